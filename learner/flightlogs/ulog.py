"""PX4 ULog (`.ulg`) into a `FlightLog` through pyulog.

Read by topic (the first instance of each): vehicle_local_position (position, velocity NED;
ax, ay, az NED kinematic where logged), vehicle_attitude (q, body FRD to NED), body rates from
vehicle_angular_velocity, else vehicle_attitude's rollspeed.. (older PX4), else
sensor_combined's gyro; acceleration from vehicle_local_position, else vehicle_acceleration,
else sensor_combined (both body FRD specific force); the rotors from esc_status rpm where it
reports spinning rotors, else actuator_motors (normalised thrust), else actuator_outputs (PWM);
battery_status; distance_sensor (downward). Times are the samples' (`timestamp_sample` where
logged, else `timestamp`), in seconds since boot.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from learner.flightlogs.actuators import ActuatorModel
from learner.flightlogs.flightlog import FlightLog
from learner.flightlogs.resample import QUAD_X_TO_OURS, AutopilotLog, Stream, stream, to_flightlog
from simbridge.config import ConfigError
from simbridge.vehicle import Vehicle

TOPICS = [
    "vehicle_local_position", "vehicle_attitude", "vehicle_angular_velocity",
    "vehicle_acceleration", "sensor_combined", "esc_status", "actuator_motors",
    "actuator_outputs", "battery_status", "distance_sensor", "vehicle_status",
]  # fmt: skip
LOOKED_FOR = {
    "position": "vehicle_local_position x, y, z",
    "attitude": "vehicle_attitude q[0..3]",
    "actuator outputs": "esc_status esc[0..3].esc_rpm, actuator_motors control[0..3], "
    "actuator_outputs output[0..3]",
}
ESC_SPINNING_RPM = 500.0  # below this throughout, esc_status is not a spinning rotor's
# PX4's MAV_TYPE: multirotors with other than four rotors, and the fixed-wing kinds
OTHER_MULTIROTORS = {3: "coaxial helicopter", 4: "helicopter", 13: "hexarotor", 14: "octorotor",
                     15: "tricopter"}  # fmt: skip
WINGED = {1: "fixed-wing", 19: "VTOL tailsitter duo", 20: "VTOL tailsitter quad",
          21: "VTOL tiltrotor", 22: "VTOL (fixed rotors)", 23: "VTOL"}  # fmt: skip
PX4_MOTOR_FUNCTION = 101  # PWM_MAIN_FUNCn: 101 = Motor 1, 102 = Motor 2, ...


def read_ulog(path: Path, mapping: Any = None, vehicle: Vehicle | str | None = None) -> FlightLog:
    """A PX4 ULog as a FlightLog; `vehicle` (default nano) turns throttle into rotor speeds."""
    if mapping is not None and not mapping.is_default:
        raise ConfigError(f"{path}: a PX4 ULog is read by topic; a column mapping does not apply")
    return to_flightlog(decode_ulog(Path(path)), vehicle)


def decode_ulog(path: Path) -> AutopilotLog:
    """The topics of a ULog as streams in PX4's frames."""
    try:
        from pyulog import ULog
    except ImportError:
        raise ConfigError(f"{path}: reading PX4 ULog needs pyulog (pip install pyulog)") from None
    if not path.is_file():
        raise ConfigError(f"{path}: no such flight log")
    try:
        ulog = ULog(str(path), TOPICS)
    except Exception as err:  # pyulog raises bare exceptions on a damaged or foreign file
        raise ConfigError(f"{path}: not a readable PX4 ULog ({err})") from None
    topics: dict[str, dict[str, np.ndarray]] = {}
    for d in sorted(ulog.data_list, key=lambda d: d.multi_id):
        topics.setdefault(d.name, d.data)
    params = dict(ulog.initial_parameters)
    found = [f"{n} ({len(topics[n]['timestamp'])} samples)" for n in TOPICS if n in topics]
    log = AutopilotLog(path, "PX4 ULog", found or ["none of the topics read"], LOOKED_FOR)
    log.meta["autopilot"] = "PX4 " + str(ulog.msg_info_dict.get("ver_sw_release", "")).strip()
    _vehicle_type(log, params, topics)
    _state(log, topics)
    _actuators(log, topics, params)
    bat = topics.get("battery_status")
    if bat is not None:
        v = np.where(bat["voltage_v"] > 0.0, bat["voltage_v"], np.nan)  # 0: no battery
        log.battery_v = stream(_time(bat), v, "battery_status.voltage_v")
    dist = topics.get("distance_sensor")
    if dist is not None:
        n = len(dist["timestamp"])
        down = dist["orientation"] == 25 if "orientation" in dist else np.ones(n, bool)
        log.range_m = stream(
            _time(dist)[down], dist["current_distance"][down], "distance_sensor.current_distance"
        )
    return log


def _time(d: dict[str, np.ndarray]) -> np.ndarray:
    t = d.get("timestamp_sample", d["timestamp"]).astype(float)
    return t * 1e-6


def _cols(d: dict[str, np.ndarray], names: list[str]) -> np.ndarray:
    return np.column_stack([d[n].astype(float) for n in names])


def _vehicle_type(log: AutopilotLog, params: dict, topics: dict) -> None:
    mav_type = int(params.get("MAV_TYPE", 2))
    status = topics.get("vehicle_status", {})
    vtol = "is_vtol" in status and bool(np.any(status["is_vtol"]))
    log.meta["mav_type"] = mav_type
    if mav_type in OTHER_MULTIROTORS:
        raise ConfigError(
            f"{log.path}: a {OTHER_MULTIROTORS[mav_type]} (MAV_TYPE {mav_type}); the diagnosis "
            f"models a quadrotor's four rotors: not converted"
        )
    if mav_type in WINGED or vtol:
        kind = WINGED.get(mav_type, "VTOL")
        log.meta["warning_vehicle"] = kind
        log.notes.append(
            f"warning: a {kind} log (MAV_TYPE {mav_type}), not a quadrotor's: its four motors "
            f"are read as a quad X's rotors; wing and control-surface forces are not modelled"
        )


def _state(log: AutopilotLog, topics: dict) -> None:
    lpos = topics.get("vehicle_local_position")
    if lpos is not None:
        t = _time(lpos)
        log.position_ned_m = stream(t, _cols(lpos, ["x", "y", "z"]), "vehicle_local_position.xyz")
        log.velocity_ned_m_s = stream(
            t, _cols(lpos, ["vx", "vy", "vz"]), "vehicle_local_position.vx,vy,vz"
        )
        if all(k in lpos for k in ("ax", "ay", "az")):
            acc = _cols(lpos, ["ax", "ay", "az"])
            if np.any(acc != 0.0):  # older PX4 has the fields but leaves them zero
                log.acceleration = stream(t, acc, "vehicle_local_position.ax,ay,az")
    att = topics.get("vehicle_attitude")
    if att is not None:
        q = _cols(att, [f"q[{i}]" for i in range(4)])
        log.attitude_ned_frd = stream(_time(att), q, "vehicle_attitude.q")
    angv, sc = topics.get("vehicle_angular_velocity"), topics.get("sensor_combined")
    if angv is not None:
        xyz = _cols(angv, [f"xyz[{i}]" for i in range(3)])
        log.rates_frd_rad_s = stream(_time(angv), xyz, "vehicle_angular_velocity.xyz")
    elif att is not None and "rollspeed" in att:
        rates = _cols(att, ["rollspeed", "pitchspeed", "yawspeed"])
        log.rates_frd_rad_s = stream(_time(att), rates, "vehicle_attitude.rollspeed..yawspeed")
    elif sc is not None:
        gyro = _cols(sc, [f"gyro_rad[{i}]" for i in range(3)])
        log.rates_frd_rad_s = stream(_time(sc), gyro, "sensor_combined.gyro_rad")
    if log.acceleration is None:
        vacc = topics.get("vehicle_acceleration")
        if vacc is not None:
            xyz = _cols(vacc, [f"xyz[{i}]" for i in range(3)])
            log.acceleration = stream(_time(vacc), xyz, "vehicle_acceleration.xyz")
        elif sc is not None:
            acc = _cols(sc, [f"accelerometer_m_s2[{i}]" for i in range(3)])
            log.acceleration = stream(_time(sc), acc, "sensor_combined.accelerometer_m_s2")
        log.acceleration_frame = "frd_specific_force"  # both: the accelerometer, body FRD


def _hover(log: AutopilotLog, params: dict) -> float:
    hover = params.get("MPC_THR_HOVER")
    if hover is None or not 0.0 < float(hover) <= 1.0:
        log.notes.append("warning: MPC_THR_HOVER not in the log: PX4's default 0.5 assumed")
        return 0.5
    return float(hover)


def _actuators(log: AutopilotLog, topics: dict, params: dict) -> None:
    esc = topics.get("esc_status")
    if esc is not None and all(f"esc[{i}].esc_rpm" in esc for i in range(4)):
        rpm = np.abs(_cols(esc, [f"esc[{i}].esc_rpm" for i in range(4)]))
        if np.nanmax(rpm) > ESC_SPINNING_RPM:
            log.actuators = _ours(stream(_time(esc), rpm, "esc_status.esc[0..3].esc_rpm"))
            log.actuator_model = ActuatorModel("rotor_speed", "rpm")
            log.actuator_note = "ESC rpm (esc i = motor i + 1, quad X order)"
            return
        log.notes.append(
            f"esc_status: rpm never above {ESC_SPINNING_RPM:g} (a simulator's or an absent "
            f"telemetry): not used"
        )
    hover = _hover(log, params)
    motors = topics.get("actuator_motors")
    if motors is not None:
        # NaN marks a stopped motor (disarmed): no thrust
        u = np.nan_to_num(_cols(motors, [f"control[{i}]" for i in range(4)]), nan=0.0)
        log.actuators = _ours(stream(_time(motors), u, "actuator_motors.control[0..3]"))
        log.actuator_model = ActuatorModel("throttle", hover_throttle=hover)
        log.actuator_note = (
            f"actuator_motors normalised thrust u, per rotor weight/4 x u / MPC_THR_HOVER {hover:g}"
        )
        return
    outputs = topics.get("actuator_outputs")
    if outputs is None:
        return
    channels = motor_channels(params)
    if channels is None:
        if log.meta.get("mav_type") == 1:  # a plane's outputs 1..4 drive its surfaces
            raise ConfigError(
                f"{log.path}: a fixed-wing log (MAV_TYPE 1) without four motors "
                f"(no esc_status, actuator_motors, or PWM_MAIN_FUNCn = 101..104): not converted"
            )
        channels = [0, 1, 2, 3]
    pwm = stream(_time(outputs), _cols(outputs, [f"output[{c}]" for c in channels]),
                 f"actuator_outputs.output{channels}")  # fmt: skip
    log.actuators, note = px4_pwm_thrust(_ours(pwm), params)
    log.actuator_note = f"actuator_outputs {note}"
    log.actuator_model = ActuatorModel("throttle", hover_throttle=hover)


def px4_pwm_thrust(pwm: Stream | None, params: dict) -> tuple[Stream | None, str]:
    """PWM into PX4's thrust fraction: u = (pwm - min) / (max - min) clipped to 0..1, fraction
    THR_MDL_FAC u^2 + (1 - THR_MDL_FAC) u; per rotor thrust is then weight/4 x fraction /
    MPC_THR_HOVER (the hover thrust in the same units)."""
    lo, hi, which = _pwm_range(params)
    fac = float(params.get("THR_MDL_FAC", 0.0))
    hover = float(params.get("MPC_THR_HOVER", 0.5))
    note = (
        f"PWM, u = (pwm - {lo:g}) / ({hi:g} - {lo:g}) ({which}), clipped to 0..1; thrust "
        f"fraction = {fac:g} u^2 + {1 - fac:g} u (THR_MDL_FAC); per rotor weight/4 x "
        f"fraction / MPC_THR_HOVER {hover:g}"
    )
    if pwm is None:
        return None, note
    u = np.clip((pwm.values - lo) / (hi - lo), 0.0, 1.0)
    return Stream(pwm.t_s, fac * u * u + (1.0 - fac) * u, pwm.source), note


def motor_channels(params: dict) -> list[int] | None:
    """The outputs (zero-based) of motors 1..4 by PWM_MAIN_FUNCn (PX4 1.13+), else None (a
    mixer file's: a multicopter's and a standard VTOL's motors are on MAIN 1..4)."""
    prefix = "PWM_MAIN_FUNC"
    funcs = {
        int(v): int(k.removeprefix(prefix)) - 1
        for k, v in params.items()
        if k.startswith(prefix) and k.removeprefix(prefix).isdigit()
    }
    motors = [funcs.get(PX4_MOTOR_FUNCTION + i) for i in range(4)]
    return None if None in motors else [int(c) for c in motors if c is not None]


def _pwm_range(params: dict) -> tuple[float, float, str]:
    for lo, hi in (("PWM_MAIN_MIN", "PWM_MAIN_MAX"), ("PWM_MIN", "PWM_MAX"),
                   ("PWM_MAIN_MIN1", "PWM_MAIN_MAX1")):  # fmt: skip
        if lo in params and hi in params and float(params[hi]) > float(params[lo]):
            return float(params[lo]), float(params[hi]), f"{lo}/{hi}"
    return 1000.0, 2000.0, "PWM range not in the log: 1000-2000 us assumed"


def _ours(s: Stream | None) -> Stream | None:
    """Quad X motors 1..4 (columns) into our rotor order."""
    return None if s is None else Stream(s.t_s, s.values[:, QUAD_X_TO_OURS], s.source)
