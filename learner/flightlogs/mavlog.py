"""ArduPilot DataFlash logs (`.bin`, or as text: Mission Planner's `.log`) and MAVLink
telemetry logs (`.tlog`) into a `FlightLog` through pymavlink.

DataFlash: ATT (degrees, NED/FRD Euler Z-Y-X), IMU (first instance: gyro, body FRD specific
force), XKF1/NKF1/EKF1 (core 0: PN PE PD VN VE VD), else POS (latitude, longitude, altitude
about the first fix; velocity differentiated), ESC RPM (instances 0..3) where logged, else
RCOU (C1.., Ch1.. or Chan1.. by the log's age) through ArduCopter's thrust curve, BAT (else
CURR) Volt, RFND Dist, PARM for the parameters. Times are TimeUS, or TimeMS in the logs of
ArduCopter 3.3 and before (GPS: T).

Telemetry: ATTITUDE_QUATERNION else ATTITUDE, LOCAL_POSITION_NED (else GLOBAL_POSITION_INT
about the first fix, relative altitude), HIGHRES_IMU else SCALED_IMU
else (ArduPilot) RAW_IMU, ESC_TELEMETRY_1_TO_4 or ESC_STATUS rpm, else SERVO_OUTPUT_RAW (port
0) through the autopilot's thrust curve, SYS_STATUS else BATTERY_STATUS, DISTANCE_SENSOR
(downward), PARAM_VALUE; the autopilot (PX4 or ArduPilot) and vehicle type from the
vehicle's HEARTBEAT. Times are the vehicle's boot time where a message carries it, else the
log's receive time shifted by the median offset between the two.

ArduCopter's thrust curve, either generation's parameters: `learner.flightlogs.arducopter`.
"""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from learner.flightlogs.actuators import ActuatorModel
from learner.flightlogs.arducopter import (
    arducopter_thrust,
    ardupilot_type,
    frame_class,
    motor_outputs,
    winged_warning,
)
from learner.flightlogs.flightlog import FlightLog
from learner.flightlogs.resample import QUAD_X_TO_OURS, AutopilotLog, Stream, stream, to_flightlog
from learner.flightlogs.ulog import motor_channels, px4_pwm_thrust
from simbridge.config import ConfigError
from simbridge.frames import geodetic_to_local, quat_from_euler
from simbridge.vehicle import GRAVITY_M_S2, Vehicle

# MAV_TYPE
QUADROTOR = 2
OTHER_MULTIROTORS = {3: "coaxial helicopter", 4: "helicopter", 13: "hexarotor", 14: "octorotor",
                     15: "tricopter"}  # fmt: skip
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

    from learner.flightlogs.readers import is_dataflash_text

    with path.open("rb") as f:
        text = is_dataflash_text(f.read(64))
    try:
        conn = (DFReader.DFReader_text if text else DFReader.DFReader_binary)(str(path))
    except Exception as err:
        raise ConfigError(f"{path}: not a readable ArduPilot DataFlash log ({err})") from None
    by: dict[str, list[tuple[float, Any]]] = defaultdict(list)
    texts = []
    params: dict[str, float] = {}
    for m in _messages(conn, path, "ArduPilot DataFlash log"):
        t = m.get_type()
        if t == "PARM":
            params[m.Name] = float(m.Value)
        elif t == "MSG":
            texts.append(str(m.Message))
        elif t != "FMT" and (boot_s := _dataflash_boot_s(m)) is not None:
            by[t].append((boot_s, m))
    found = [f"{k} ({len(v)})" for k, v in sorted(by.items())] + [f"PARM ({len(params)})"]
    looked = {
        "position": "XKF1, NKF1, EKF1 or POS",
        "attitude": "ATT",
        "actuator outputs": "ESC RPM (instances 0..3) or RCOU C1..C4 (Ch1.., Chan1..)",
    }
    log = AutopilotLog(path, "ArduPilot DataFlash log", found, looked)
    log.meta["autopilot"] = next(
        (x for x in texts if x.startswith(("Ardu", "APM:Copter"))), "ArduPilot"
    )
    ardupilot_type(log, params, texts)

    def series(name: str, fields: list[str], scale: float = 1.0, **match: int) -> Stream | None:
        rows = [(t, m) for t, m in by.get(name, [])
                if all(_matches(m, k, v) for k, v in match.items())]  # fmt: skip
        src = f"{name}.{','.join(fields)}" + "".join(f" {k}={v}" for k, v in match.items())
        return stream([t for t, _ in rows], [[getattr(m, f) * scale for f in fields]
                                             for _, m in rows], src)  # fmt: skip

    att = series("ATT", ["Roll", "Pitch", "Yaw"], math.pi / 180.0)
    if att is not None:
        q = np.array([quat_from_euler(*r) for r in att.values])
        log.attitude_ned_frd = Stream(att.t_s, q, "ATT.Roll,Pitch,Yaw (deg)")
    log.rates_frd_rad_s = series("IMU", ["GyrX", "GyrY", "GyrZ"], I=0)
    log.acceleration = series("IMU", ["AccX", "AccY", "AccZ"], I=0)
    log.acceleration_frame = "frd_specific_force"
    # the EKF's core 0: XKF1 (EKF3), NKF1 (EKF2), EKF1 (ArduCopter 3.3's EKF, one core)
    for ekf in ("XKF1", "NKF1", "EKF1"):
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
        channels = motor_outputs(log, params)
        first = by["RCOU"][0][1] if by.get("RCOU") else None
        # the outputs' names: C1.. (ArduCopter 3.4 on), Ch1.. (3.3), Chan1.. (before)
        names = next(
            ([f"{p}{c + 1}" for c in channels] for p in ("C", "Ch", "Chan")
             if all(hasattr(first, f"{p}{c + 1}") for c in channels)),
            None,
        )  # fmt: skip
        rcou = series("RCOU", names) if names else None
        log.actuators, log.actuator_model, log.actuator_note = arducopter_thrust(
            log, _ours(rcou), params
        )
    log.battery_v = series("BAT", ["Volt"], Instance=0) or _volts(by, series)
    log.range_m = series("RFND", ["Dist"], Instance=0)
    return log


# A field's other names across ArduPilot's versions (BAT's Instance became Inst in 4.1)
FIELD_ALIASES = {"Instance": ("Instance", "Inst")}


def _matches(m: Any, field: str, value: int) -> bool:
    """The message's `field` (or its alias) equals `value`; a message without it matches
    (one instance, one core)."""
    for name in FIELD_ALIASES.get(field, (field,)):
        if hasattr(m, name):
            return getattr(m, name) == value
    return True


def _dataflash_boot_s(m: Any) -> float | None:
    """A DataFlash message's time since boot: TimeUS (ArduPilot 3.4 on), else TimeMS (before;
    GPS's TimeMS is then its week's time, and T the boot time)."""
    if hasattr(m, "TimeUS"):
        return m.TimeUS * 1e-6
    if m.get_type() == "GPS":
        return m.T * 1e-3 if hasattr(m, "T") else None
    return m.TimeMS * 1e-3 if hasattr(m, "TimeMS") else None


def _volts(by: dict[str, list[tuple[float, Any]]], series: Any) -> Stream | None:
    """CURR's Volt: volts in a float field, centivolts in an integer one (ArduCopter 3.3)."""
    rows = by.get("CURR")
    if not rows or not hasattr(rows[0][1], "Volt"):
        return None
    m = rows[0][1]
    kind = m.fmt.format[m.fmt.columns.index("Volt")]
    return series("CURR", ["Volt"], 0.01 if kind in "bBhHiI" else 1.0)


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
        "position": "LOCAL_POSITION_NED or GLOBAL_POSITION_INT",
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
    fix = series("GLOBAL_POSITION_INT", ["lat", "lon", "relative_alt"], 1.0)
    if log.position_ned_m is None and fix is not None:  # streamed without a local frame
        lat0, lon0 = fix.values[0, 0] * 1e-7, fix.values[0, 1] * 1e-7
        en = np.array([geodetic_to_local(lat0, lon0, la * 1e-7, lo * 1e-7)
                       for la, lo, _ in fix.values])  # fmt: skip
        ned = np.column_stack([en[:, 1], en[:, 0], -fix.values[:, 2] * 1e-3])
        log.position_ned_m = Stream(
            fix.t_s, ned, "GLOBAL_POSITION_INT.lat,lon about the first fix,relative_alt"
        )
        log.velocity_ned_m_s = series("GLOBAL_POSITION_INT", ["vx", "vy", "vz"], 0.01)
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
        channels = (motor_channels(params) or [0, 1, 2, 3]) if px4 else motor_outputs(log, params)
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
            log.actuators, log.actuator_model, log.actuator_note = arducopter_thrust(
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


def _mav_type(log: AutopilotLog, mav_type: int, params: dict[str, float], px4: bool) -> None:
    log.meta["mav_type"] = mav_type
    if not px4:
        frame_class(log, params)
    if mav_type in OTHER_MULTIROTORS:
        raise ConfigError(
            f"{log.path}: a {OTHER_MULTIROTORS[mav_type]} (HEARTBEAT type {mav_type}); the "
            f"diagnosis models a quadrotor's four rotors: not converted"
        )
    if mav_type != QUADROTOR:
        kind = "fixed-wing" if mav_type == 1 else f"MAV_TYPE {mav_type}"
        log.meta["warning_vehicle"] = kind
        log.notes.append(winged_warning(kind, "PX4" if px4 else "ArduPilot"))
