"""ArduPilot DataFlash logs (`.bin`) and MAVLink telemetry logs (`.tlog`) into a `FlightLog`
through pymavlink.

DataFlash: ATT (degrees, NED/FRD Euler Z-Y-X), IMU (first instance: gyro, body FRD specific
force), XKF1/NKF1 (core 0: PN PE PD VN VE VD), else POS (latitude, longitude, altitude about
the first fix; velocity differentiated), ESC RPM (instances 0..3) where logged, else RCOU
through ArduCopter's thrust curve, BAT (else CURR) Volt, RFND Dist, PARM for the parameters.
Times are TimeUS.

Telemetry: ATTITUDE_QUATERNION else ATTITUDE, LOCAL_POSITION_NED, HIGHRES_IMU else SCALED_IMU
else (ArduPilot) RAW_IMU, ESC_TELEMETRY_1_TO_4 or ESC_STATUS rpm, else SERVO_OUTPUT_RAW (port
0) through the autopilot's thrust curve, SYS_STATUS else BATTERY_STATUS, DISTANCE_SENSOR
(downward), PARAM_VALUE; the autopilot (PX4 or ArduPilot) and vehicle type from the
vehicle's HEARTBEAT. Times are the vehicle's boot time where a message carries it, else the
log's receive time shifted by the median offset between the two.

ArduCopter's thrust curve (AP_MotorsMulticopter): a = (pwm - MOT_PWM_MIN) / (MOT_PWM_MAX -
MOT_PWM_MIN), r = (a - MOT_SPIN_MIN) / (MOT_SPIN_MAX - MOT_SPIN_MIN) clipped to 0..1, thrust
fraction = (1 - MOT_THST_EXPO) r + MOT_THST_EXPO r^2 (the inverse of its linearisation; the
battery voltage scaling is left out, lift_max = 1), per rotor thrust = weight/4 x fraction /
MOT_THST_HOVER (the learnt hover thrust, in the same units).
"""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from learner.flightlogs.actuators import ActuatorModel
from learner.flightlogs.flightlog import FlightLog
from learner.flightlogs.resample import QUAD_X_TO_OURS, AutopilotLog, Stream, stream, to_flightlog
from learner.flightlogs.ulog import motor_channels, px4_pwm_thrust
from simbridge.config import ConfigError
from simbridge.frames import geodetic_to_local, quat_from_euler
from simbridge.vehicle import GRAVITY_M_S2, Vehicle

# ArduCopter's defaults, used where the log has no PARM for them (and said so in the meta)
AC_DEFAULTS = {"MOT_PWM_MIN": 1000.0, "MOT_PWM_MAX": 2000.0, "MOT_SPIN_MIN": 0.15,
               "MOT_SPIN_MAX": 0.95, "MOT_THST_EXPO": 0.65, "MOT_THST_HOVER": 0.35}  # fmt: skip
AP_MOTOR_FUNCTION = 33  # SERVOn_FUNCTION: 33 = Motor 1, 34 = Motor 2, ...
# MAV_TYPE
QUADROTOR = 2
OTHER_MULTIROTORS = {3: "coaxial helicopter", 4: "helicopter", 13: "hexarotor", 14: "octorotor",
                     15: "tricopter"}  # fmt: skip
AP_FRAME_CLASSES = {2: "hexarotor", 3: "octorotor", 4: "octaquad", 5: "Y6", 6: "helicopter",
                    7: "tricopter", 8: "single copter", 9: "coax copter"}  # fmt: skip
MAV_AUTOPILOT_PX4, MAV_AUTOPILOT_INVALID = 12, 8
MG_TO_M_S2 = GRAVITY_M_S2 / 1000.0
DOWNWARD = 25  # MAV_SENSOR_ROTATION_PITCH_270


def read_dataflash(
    path: Path, mapping: Any = None, vehicle: Vehicle | str | None = None
) -> FlightLog:
    """An ArduPilot DataFlash log as a FlightLog."""
    _no_mapping(path, mapping, "an ArduPilot DataFlash log")
    return to_flightlog(decode_dataflash(Path(path)), vehicle)


def read_tlog(path: Path, mapping: Any = None, vehicle: Vehicle | str | None = None) -> FlightLog:
    """A MAVLink telemetry log as a FlightLog."""
    _no_mapping(path, mapping, "a MAVLink telemetry log")
    return to_flightlog(decode_tlog(Path(path)), vehicle)


def _no_mapping(path: Path, mapping: Any, what: str) -> None:
    if mapping is not None and not mapping.is_default:
        raise ConfigError(f"{path}: {what} is read by message; a column mapping does not apply")
    if not Path(path).is_file():
        raise ConfigError(f"{path}: no such flight log")


def _messages(conn: Any, path: Path, kind: str) -> list[Any]:
    out = []
    try:
        while (m := conn.recv_match(blocking=False)) is not None:
            if m.get_type() != "BAD_DATA":
                out.append(m)
    except Exception as err:  # pymavlink raises bare exceptions on damaged files
        raise ConfigError(f"{path}: not a readable {kind} ({err})") from None
    return out


def decode_dataflash(path: Path) -> AutopilotLog:
    """A DataFlash log's messages as streams in ArduPilot's frames."""
    from pymavlink import DFReader

    try:
        conn = DFReader.DFReader_binary(str(path))
    except Exception as err:
        raise ConfigError(f"{path}: not a readable ArduPilot DataFlash log ({err})") from None
    by: dict[str, list[Any]] = defaultdict(list)
    texts = []
    params: dict[str, float] = {}
    for m in _messages(conn, path, "ArduPilot DataFlash log"):
        t = m.get_type()
        if t == "PARM":
            params[m.Name] = float(m.Value)
        elif t == "MSG":
            texts.append(str(m.Message))
        elif t != "FMT" and hasattr(m, "TimeUS"):
            by[t].append(m)
    found = [f"{k} ({len(v)})" for k, v in sorted(by.items())] + [f"PARM ({len(params)})"]
    looked = {"position": "XKF1, NKF1 or POS", "attitude": "ATT",
              "actuator outputs": "ESC RPM (instances 0..3) or RCOU C1..C4"}  # fmt: skip
    log = AutopilotLog(path, "ArduPilot DataFlash log", found, looked)
    log.meta["autopilot"] = next((x for x in texts if x.startswith("Ardu")), "ArduPilot")
    _ardupilot_type(log, params, " ".join(texts))

    def series(name: str, fields: list[str], scale: float = 1.0, **match: int) -> Stream | None:
        rows = [m for m in by.get(name, []) if all(getattr(m, k, v) == v for k, v in match.items())]
        t = [m.TimeUS * 1e-6 for m in rows]
        src = f"{name}.{','.join(fields)}" + "".join(f" {k}={v}" for k, v in match.items())
        return stream(t, [[getattr(m, f) * scale for f in fields] for m in rows], src)

    att = series("ATT", ["Roll", "Pitch", "Yaw"], math.pi / 180.0)
    if att is not None:
        q = np.array([quat_from_euler(*r) for r in att.values])
        log.attitude_ned_frd = Stream(att.t_s, q, "ATT.Roll,Pitch,Yaw (deg)")
    log.rates_frd_rad_s = series("IMU", ["GyrX", "GyrY", "GyrZ"], I=0)
    log.acceleration = series("IMU", ["AccX", "AccY", "AccZ"], I=0)
    log.acceleration_frame = "frd_specific_force"
    for ekf in ("XKF1", "NKF1"):
        log.position_ned_m = series(ekf, ["PN", "PE", "PD"], C=0)
        log.velocity_ned_m_s = series(ekf, ["VN", "VE", "VD"], C=0)
        if log.position_ned_m is not None:
            break
    pos = series("POS", ["Lat", "Lng", "Alt"])
    if log.position_ned_m is None and pos is not None:
        lat0, lon0, alt0 = pos.values[0]
        en = np.array([geodetic_to_local(lat0, lon0, la, lo) for la, lo, _ in pos.values])
        ned = np.column_stack([en[:, 1], en[:, 0], alt0 - pos.values[:, 2]])
        log.position_ned_m = Stream(pos.t_s, ned, "POS.Lat,Lng,Alt about the first fix")
    esc = [series("ESC", ["RPM"], Instance=i) for i in range(4)]
    if all(e is not None for e in esc):
        log.actuators = _ours(_joined(esc, "ESC.RPM Instance=0..3"))
        log.actuator_model = ActuatorModel("rotor_speed", "rpm")
        log.actuator_note = "ESC rpm (instance i = motor i + 1, quad X order)"
    else:
        channels = _ap_motor_channels(log, params)
        rcou = series("RCOU", [f"C{c + 1}" for c in channels])
        log.actuators, log.actuator_model, log.actuator_note = _arducopter_thrust(
            log, _ours(rcou), params
        )
    log.battery_v = series("BAT", ["Volt"], Instance=0) or series("CURR", ["Volt"])
    log.range_m = series("RFND", ["Dist"], Instance=0)
    return log


def decode_tlog(path: Path) -> AutopilotLog:
    """A telemetry log's messages as streams in MAVLink's frames."""
    from pymavlink import mavutil

    try:
        conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    except Exception as err:
        raise ConfigError(f"{path}: not a readable MAVLink telemetry log ({err})") from None
    msgs = _messages(conn, path, "MAVLink telemetry log")
    beats = [
        m for m in msgs if m.get_type() == "HEARTBEAT" and m.autopilot != MAV_AUTOPILOT_INVALID
    ]
    vehicle_sys = beats[0].get_srcSystem() if beats else None
    by: dict[str, list[Any]] = defaultdict(list)
    params: dict[str, float] = {}
    for m in msgs:
        if vehicle_sys is not None and m.get_srcSystem() != vehicle_sys:
            continue  # a ground station's own messages
        if m.get_type() == "PARAM_VALUE":
            params[str(m.param_id)] = float(m.param_value)
        else:
            by[m.get_type()].append(m)
    found = [f"{k} ({len(v)})" for k, v in sorted(by.items())] + [f"PARAM_VALUE ({len(params)})"]
    looked = {
        "position": "LOCAL_POSITION_NED",
        "attitude": "ATTITUDE_QUATERNION or ATTITUDE",
        "actuator outputs": "ESC_TELEMETRY_1_TO_4, ESC_STATUS or SERVO_OUTPUT_RAW",
    }
    log = AutopilotLog(path, "MAVLink telemetry log", found, looked)
    px4 = bool(beats) and beats[0].autopilot == MAV_AUTOPILOT_PX4
    log.meta["autopilot"] = "PX4" if px4 else "ArduPilot"
    mav_type = beats[0].type if beats else QUADROTOR
    _mav_type(log, mav_type, params, px4)
    clock = _Clock(msgs)

    def series(name: str, fields: list[str], scale: float = 1.0, **match: int) -> Stream | None:
        rows = [m for m in by.get(name, []) if all(getattr(m, k) == v for k, v in match.items())]
        vals = [[_field(m, f) * scale for f in fields] for m in rows]
        return stream([clock.boot_s(m) for m in rows], vals, f"{name}.{','.join(fields)}")

    quat = series("ATTITUDE_QUATERNION", ["q1", "q2", "q3", "q4"])
    att = series("ATTITUDE", ["roll", "pitch", "yaw"])
    if quat is not None:
        log.attitude_ned_frd = quat
    elif att is not None:
        q = np.array([quat_from_euler(*r) for r in att.values])
        log.attitude_ned_frd = Stream(att.t_s, q, att.source)
    log.rates_frd_rad_s = series("ATTITUDE", ["rollspeed", "pitchspeed", "yawspeed"])
    log.position_ned_m = series("LOCAL_POSITION_NED", ["x", "y", "z"])
    log.velocity_ned_m_s = series("LOCAL_POSITION_NED", ["vx", "vy", "vz"])
    acc = ["xacc", "yacc", "zacc"]
    log.acceleration = series("HIGHRES_IMU", acc) or series("SCALED_IMU", acc, MG_TO_M_S2)
    if log.acceleration is None and not px4:  # ArduPilot's RAW_IMU carries milli-g too
        log.acceleration = series("RAW_IMU", acc, MG_TO_M_S2)
    log.acceleration_frame = "frd_specific_force"
    rpm = series("ESC_TELEMETRY_1_TO_4", [f"rpm[{i}]" for i in range(4)]) or series(
        "ESC_STATUS", [f"rpm[{i}]" for i in range(4)], index=0
    )
    if rpm is not None and np.max(np.abs(rpm.values)) > 0:
        log.actuators = _ours(Stream(rpm.t_s, np.abs(rpm.values), rpm.source))
        log.actuator_model = ActuatorModel("rotor_speed", "rpm")
        log.actuator_note = "ESC rpm (ESC i = motor i + 1, quad X order)"
    else:
        channels = (
            (motor_channels(params) or [0, 1, 2, 3]) if px4 else _ap_motor_channels(log, params)
        )
        servo = _ours(series("SERVO_OUTPUT_RAW", [f"servo{c + 1}_raw" for c in channels], port=0))
        if px4:
            log.actuators, note = px4_pwm_thrust(servo, params)
            if "MPC_THR_HOVER" not in params:
                log.notes.append("warning: MPC_THR_HOVER not in the log: PX4's default 0.5 assumed")
            log.actuator_model = ActuatorModel(
                "throttle", hover_throttle=params.get("MPC_THR_HOVER", 0.5)
            )
            log.actuator_note = f"SERVO_OUTPUT_RAW {note}"
        else:
            log.actuators, log.actuator_model, log.actuator_note = _arducopter_thrust(
                log, servo, params
            )
    sys_v = series("SYS_STATUS", ["voltage_battery"], 1e-3)
    if sys_v is not None and np.all(sys_v.values > 0):
        log.battery_v = sys_v
    else:
        log.battery_v = _battery_status(by.get("BATTERY_STATUS", []), clock)
    down = [m for m in by.get("DISTANCE_SENSOR", []) if m.orientation == DOWNWARD]
    log.range_m = stream([clock.boot_s(m) for m in down], [m.current_distance * 0.01 for m in down],
                         "DISTANCE_SENSOR.current_distance")  # fmt: skip
    return log


class _Clock:
    """The vehicle's boot time of a message: its own time_boot_ms / time_usec where it carries
    one (time_usec beyond a year is UNIX time, not boot time), else the log's receive time
    less the median offset seen between the two."""

    def __init__(self, msgs: list[Any]) -> None:
        offsets = [m._timestamp - b for m in msgs if (b := self._own(m)) is not None]
        self.offset_s = float(np.median(offsets)) if offsets else 0.0

    @staticmethod
    def _own(m: Any) -> float | None:
        if hasattr(m, "time_boot_ms"):
            return m.time_boot_ms * 1e-3
        usec = getattr(m, "time_usec", None)
        return usec * 1e-6 if usec is not None and 0 < usec < 3.2e13 else None

    def boot_s(self, m: Any) -> float:
        own = self._own(m)
        return own if own is not None else m._timestamp - self.offset_s


def _field(m: Any, name: str) -> float:
    if name.endswith("]"):  # an array field's element: rpm[2]
        base, idx = name[:-1].split("[")
        return float(getattr(m, base)[int(idx)])
    return float(getattr(m, name))


def _battery_status(rows: list[Any], clock: _Clock) -> Stream | None:
    # cell voltages in mV, UINT16_MAX where none; their sum is the pack's voltage
    volts = [sum(v for v in m.voltages if v != 65535) * 1e-3 for m in rows]
    return stream([clock.boot_s(m) for m in rows], volts, "BATTERY_STATUS.voltages")


def _joined(parts: list[Stream | None], source: str) -> Stream | None:
    """Per-instance streams (separate stamps) on the first one's times."""
    if any(p is None for p in parts):
        return None
    first = parts[0]
    assert first is not None
    cols = [np.interp(first.t_s, p.t_s, p.values[:, 0]) for p in parts if p is not None]
    return Stream(first.t_s, np.abs(np.column_stack(cols)), source)


def _ours(s: Stream | None) -> Stream | None:
    return None if s is None else Stream(s.t_s, s.values[:, QUAD_X_TO_OURS], s.source)


def _ap_motor_channels(log: AutopilotLog, params: dict[str, float]) -> list[int]:
    """The outputs of motors 1..4 by SERVOn_FUNCTION 33..36; ArduCopter's default 1..4 for a
    copter whose log has none; a plane without them has no four motors."""
    funcs = {
        int(v): int(k[5:-9]) - 1
        for k, v in params.items()
        if k.startswith("SERVO") and k.endswith("_FUNCTION") and k[5:-9].isdigit()
    }
    motors = [funcs.get(AP_MOTOR_FUNCTION + i) for i in range(4)]
    if None not in motors:
        return [int(c) for c in motors if c is not None]
    if "warning_vehicle" in log.meta:
        found = ", ".join(f"motor {f - 32} on SERVO{c + 1}" for f, c in sorted(funcs.items())
                          if 33 <= f <= 40)  # fmt: skip
        raise ConfigError(
            f"{log.path}: a {log.meta['warning_vehicle']} log without four motor outputs "
            f"(SERVOn_FUNCTION 33..36 for motors 1..4; found: {found or 'none'}): not converted"
        )
    return [0, 1, 2, 3]


def _arducopter_thrust(
    log: AutopilotLog, pwm: Stream | None, params: dict[str, float]
) -> tuple[Stream | None, ActuatorModel, str]:
    p = {k: params.get(k, d) for k, d in AC_DEFAULTS.items()}
    if p["MOT_PWM_MAX"] <= p["MOT_PWM_MIN"]:  # 0, 0: ArduCopter takes the throttle channel's
        p["MOT_PWM_MIN"] = params.get("RC3_MIN", 1000.0)
        p["MOT_PWM_MAX"] = params.get("RC3_MAX", 2000.0)
    assumed = sorted(k for k in AC_DEFAULTS if k not in params)
    if assumed:
        log.notes.append(f"warning: not in the log, ArduCopter's defaults assumed: {assumed}")
    expo, hover = p["MOT_THST_EXPO"], p["MOT_THST_HOVER"]
    note = (
        f"RCOU/SERVO_OUTPUT_RAW PWM through ArduCopter's thrust curve: a = (pwm - "
        f"{p['MOT_PWM_MIN']:g}) / ({p['MOT_PWM_MAX']:g} - {p['MOT_PWM_MIN']:g}), r = (a - "
        f"{p['MOT_SPIN_MIN']:g}) / ({p['MOT_SPIN_MAX']:g} - {p['MOT_SPIN_MIN']:g}) in 0..1, "
        f"fraction = {1 - expo:g} r + {expo:g} r^2 (MOT_THST_EXPO; no voltage scaling), per "
        f"rotor weight/4 x fraction / MOT_THST_HOVER {hover:g}"
    )
    model = ActuatorModel("throttle", hover_throttle=hover)
    if pwm is None:
        return None, model, note
    a = (pwm.values - p["MOT_PWM_MIN"]) / (p["MOT_PWM_MAX"] - p["MOT_PWM_MIN"])
    r = np.clip((a - p["MOT_SPIN_MIN"]) / (p["MOT_SPIN_MAX"] - p["MOT_SPIN_MIN"]), 0.0, 1.0)
    return Stream(pwm.t_s, (1.0 - expo) * r + expo * r * r, pwm.source), model, note


def _ap_frame_class(log: AutopilotLog, params: dict[str, float]) -> None:
    for key in ("FRAME_CLASS", "Q_FRAME_CLASS"):  # a copter's, a quadplane's lift motors
        frame_class = int(params.get(key, 1))
        if frame_class in AP_FRAME_CLASSES:
            raise ConfigError(
                f"{log.path}: a {AP_FRAME_CLASSES[frame_class]} ({key} {frame_class}); the "
                f"diagnosis models a quadrotor's four rotors: not converted"
            )


def _ardupilot_type(log: AutopilotLog, params: dict[str, float], text: str) -> None:
    _ap_frame_class(log, params)
    if "ArduPlane" in text or "Q_ENABLE" in params:
        kind = "VTOL (quadplane)" if params.get("Q_ENABLE", 0) else "fixed-wing"
        log.meta["warning_vehicle"] = kind
        log.notes.append(_winged_warning(kind, "ArduPlane"))
    elif int(params.get("FRAME_TYPE", 1)) != 1:
        log.notes.append(
            f"warning: FRAME_TYPE {int(params['FRAME_TYPE'])} is not X: motors read in X order"
        )


def _mav_type(log: AutopilotLog, mav_type: int, params: dict[str, float], px4: bool) -> None:
    log.meta["mav_type"] = mav_type
    if not px4:
        _ap_frame_class(log, params)
    if mav_type in OTHER_MULTIROTORS:
        raise ConfigError(
            f"{log.path}: a {OTHER_MULTIROTORS[mav_type]} (HEARTBEAT type {mav_type}); the "
            f"diagnosis models a quadrotor's four rotors: not converted"
        )
    if mav_type != QUADROTOR:
        kind = "fixed-wing" if mav_type == 1 else f"MAV_TYPE {mav_type}"
        log.meta["warning_vehicle"] = kind
        log.notes.append(_winged_warning(kind, "PX4" if px4 else "ArduPilot"))


def _winged_warning(kind: str, autopilot: str) -> str:
    return (
        f"warning: a {kind} {autopilot} log, not a quadrotor's: its four motors are read as a "
        f"quad X's rotors; wing and control-surface forces are not modelled"
    )
