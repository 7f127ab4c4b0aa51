"""Autopilot logs read directly: a PX4 ULog fixture end to end; MAVLink telemetry logs and
ArduPilot DataFlash logs that the tests write themselves (real MAVLink packets with tlog
timestamps; FMT records and messages as DFReader parses them) from a known flight, read back
to its positions, attitude and rotor speeds; one test per refusal; a written log through
`groundfx gap diagnose`."""

from __future__ import annotations

import math
import re
import struct
from pathlib import Path

import numpy as np
import pytest

from learner.flightlogs.flightlog import FlightLog
from learner.flightlogs.readers import read_log
from learner.flightlogs.tables import ColumnMapping
from simbridge.config import ConfigError
from simbridge.frames import (
    enu_to_ned,
    euler_from_quat,
    flu_to_frd,
    local_to_geodetic,
    quat_conjugate,
    quat_enu_flu_to_ned_frd,
    quat_from_euler,
    quat_multiply,
    quat_to_matrices,
)
from simbridge.vehicle import GRAVITY_M_S2, load_vehicle
from tests.helpers import run_groundfx

ULOG = Path(__file__).parent / "data/ulog/sample_appended_multiple.ulg"
NANO = load_vehicle("nano")
# ArduCopter's thrust-curve parameters, none at their defaults
AC_PARAMS = {"MOT_PWM_MIN": 1100.0, "MOT_PWM_MAX": 1900.0, "MOT_SPIN_MIN": 0.12,
             "MOT_SPIN_MAX": 0.95, "MOT_THST_EXPO": 0.55, "MOT_THST_HOVER": 0.3}  # fmt: skip
G_UP = np.array([0.0, 0.0, GRAVITY_M_S2])
BOOT_EPOCH_S = 1.7e9  # the tlog's receive clock at the vehicle's boot
LAT0_DEG, LON0_DEG = -35.3632, 149.1652  # CMAC, where ArduPilot flies its tests


def known_flight(seconds: float = 8.0, rate_hz: float = 50.0, phase: float = 0.0) -> FlightLog:
    """A flight the nano vehicle could fly: its attitude tilts the thrust along the
    acceleration, its four equal rotor speeds carry m |a + g|, its rates follow the attitude."""
    t = 2.0 + np.arange(int(seconds * rate_hz)) / rate_hz
    w = 2 * math.pi * 0.25
    s = w * t + phase
    pos = np.column_stack([0.3 * np.sin(s), 0.2 * np.sin(2 * s), 0.6 + 0.1 * np.sin(s)])
    vel = np.column_stack([0.3 * w * np.cos(s), 0.4 * w * np.cos(2 * s), 0.1 * w * np.cos(s)])
    acc = np.column_stack([-0.3 * w * w * np.sin(s), -0.8 * w * w * np.sin(2 * s),
                           -0.1 * w * w * np.sin(s)])  # fmt: skip
    yaw = 0.4 * np.sin(s) + 0.5
    force = NANO.mass_kg * (acc + G_UP)
    quats = []
    for f, psi in zip(force / np.linalg.norm(force, axis=1, keepdims=True), yaw, strict=True):
        fx = math.cos(psi) * f[0] + math.sin(psi) * f[1]  # the thrust axis in the yaw frame
        fy = -math.sin(psi) * f[0] + math.cos(psi) * f[1]
        quats.append(quat_from_euler(math.asin(-fy), math.atan2(fx, f[2]), psi))
    q = np.array(quats)
    dq = np.gradient(q, t, axis=0)
    rates = np.array(
        [2 * np.array(quat_multiply(quat_conjugate(a), b)[1:]) for a, b in zip(q, dq, strict=True)]
    )
    rotors = np.sqrt(np.linalg.norm(force, axis=1) / (4 * NANO.thrust_coefficient_n_s2))
    return FlightLog("known", t, pos, vel, q, rates, np.repeat(rotors[:, None], 4, 1), acc)


def ned_frd(log: FlightLog) -> dict[str, np.ndarray]:
    """The flight as an autopilot logs it: NED, FRD, Euler angles, specific force."""
    q_ned = np.array([quat_enu_flu_to_ned_frd(tuple(q)) for q in log.quaternion])
    rot = quat_to_matrices(log.quaternion)
    f_body = np.einsum("nji,nj->ni", rot, log.acceleration_m_s2 + G_UP)
    return {
        "pos": np.array([enu_to_ned(tuple(p)) for p in log.position_m]),
        "vel": np.array([enu_to_ned(tuple(v)) for v in log.velocity_m_s]),
        "q": q_ned,
        "euler": np.array([euler_from_quat(tuple(q)) for q in q_ned]),
        "rates": np.array([flu_to_frd(tuple(w)) for w in log.body_rates_rad_s]),
        "specific_force": np.array([flu_to_frd(tuple(f)) for f in f_body]),
    }


def arducopter_pwm(rotors_rad_s: np.ndarray, p: dict[str, float]) -> np.ndarray:
    """ArduCopter's PWM for these rotor speeds (thrust through nano's C_T): its thrust curve."""
    fraction = NANO.thrust_coefficient_n_s2 * rotors_rad_s**2 / (NANO.weight_n / 4)
    fraction = fraction * p["MOT_THST_HOVER"]
    e = p["MOT_THST_EXPO"]
    r = (-(1 - e) + np.sqrt((1 - e) ** 2 + 4 * e * fraction)) / (2 * e)
    a = p["MOT_SPIN_MIN"] + r * (p["MOT_SPIN_MAX"] - p["MOT_SPIN_MIN"])
    return p["MOT_PWM_MIN"] + a * (p["MOT_PWM_MAX"] - p["MOT_PWM_MIN"])


def assert_round_trip(back: FlightLog, log: FlightLog, rotor_rel: float, gap: int = 0) -> None:
    def at(a: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(back.time_s, log.time_s, c) for c in a.T])

    assert len(back) >= len(log) - 2 - gap
    np.testing.assert_allclose(back.position_m, at(log.position_m), atol=1e-4)
    np.testing.assert_allclose(back.velocity_m_s, at(log.velocity_m_s), atol=1e-4)
    dots = np.abs(np.sum(back.quaternion * at(log.quaternion), axis=1))
    assert dots.min() > 1 - 1e-5
    np.testing.assert_allclose(back.body_rates_rad_s, at(log.body_rates_rad_s), atol=2e-3)
    np.testing.assert_allclose(back.rotor_speeds_rad_s, at(log.rotor_speeds_rad_s), rtol=rotor_rel)
    np.testing.assert_allclose(back.acceleration_m_s2, at(log.acceleration_m_s2), atol=1e-3)


# ---- MAVLink telemetry logs, written with pymavlink ---------------------------------------


class _Sink:
    def __init__(self) -> None:
        self.data = bytearray()

    def write(self, b: bytes) -> None:
        self.data += b


def write_tlog(
    path: Path,
    log: FlightLog,
    *,
    mav_type: int = 2,
    params: dict[str, float] | None = None,
    esc: bool = False,
    servo: bool = True,
    position: bool | str = True,
    motor_outputs: tuple[int, ...] = (1, 2, 3, 4),
    hole_s: tuple[float, float] | None = None,
) -> Path:
    """A telemetry log of `log` as ArduPilot streams it: each packet after its 8-byte
    big-endian receive time in microseconds."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    sink = _Sink()
    mav = mavlink.MAVLink(sink, srcSystem=1, srcComponent=1)

    def send(t_s: float, msg: object) -> None:
        sink.write(struct.pack(">Q", round((BOOT_EPOCH_S + t_s + 0.003) * 1e6)))  # 3 ms link
        mav.send(msg)

    a = ned_frd(log)
    t0 = log.time_s[0] - 0.1
    send(t0, mav.heartbeat_encode(mav_type, 3, 0, 0, 4))  # MAV_AUTOPILOT_ARDUPILOTMEGA
    all_params = {**AC_PARAMS, **(params or {})}
    for i, (name, value) in enumerate(all_params.items()):
        send(t0, mav.param_value_encode(name.encode(), value, 9, len(all_params), i))
    pwm = arducopter_pwm(log.rotor_speeds_rad_s, all_params)[:, [3, 1, 0, 2]]  # ours -> 1..4
    for k, t in enumerate(log.time_s):
        ms = round(t * 1000)
        if hole_s and hole_s[0] < t < hole_s[1]:
            continue
        send(t, mav.attitude_encode(ms, *a["euler"][k], *a["rates"][k]))
        if position == "global":  # degE7 about an origin, mm, cm/s
            n, e, d = a["pos"][k]
            lat, lon = local_to_geodetic(LAT0_DEG, LON0_DEG, e, n)
            vn, ve, vd = (round(100 * v) for v in a["vel"][k])
            send(t, mav.global_position_int_encode(ms, round(lat * 1e7), round(lon * 1e7),
                                                   round(1e3 * (584.0 - d)), round(-1e3 * d),
                                                   vn, ve, vd, 0))  # fmt: skip
        elif position:
            send(t, mav.local_position_ned_encode(ms, *a["pos"][k], *a["vel"][k]))
        f, g = a["specific_force"][k], a["rates"][k]
        send(t, mav.highres_imu_encode(round(t * 1e6), *f, *g, 0, 0, 0, 0, 0, 0, 0, 0x3F))
        if servo:
            out = [0] * 16
            for ch, value in zip(motor_outputs, pwm[k], strict=True):
                out[ch - 1] = round(value)
            send(t, mav.servo_output_raw_encode(round(t * 1e6) % 2**32, 0, *out))
        if esc:
            rpm = [round(n * 60 / (2 * math.pi)) for n in log.rotor_speeds_rad_s[k, [3, 1, 0, 2]]]
            send(t, mav.esc_telemetry_1_to_4_encode([0] * 4, [0] * 4, [0] * 4, [0] * 4, rpm,
                                                    [0] * 4))  # fmt: skip
        send(t, mav.sys_status_encode(0, 0, 0, 0, 3900, 0, 50, 0, 0, 0, 0, 0, 0))
    path.write_bytes(bytes(sink.data))
    return path


def test_tlog_round_trip_through_arducopters_thrust_curve(tmp_path: Path) -> None:
    log = known_flight()
    back = read_log(write_tlog(tmp_path / "flight.tlog", log))
    # PWM is whole microseconds: 1 us of 800 is ~0.3% of the thrust fraction near hover
    assert_round_trip(back, log, rotor_rel=3e-3)
    assert back.battery_v == pytest.approx(np.full(len(back), 3.9))
    notes = "\n".join(back.meta["conversions"])
    assert "ArduCopter's thrust curve" in notes and "MOT_THST_HOVER 0.3" in notes
    assert "timeline: uniform 50.0 Hz" in notes and "0 rows dropped" in notes
    assert back.meta["sources"]["acceleration"] == "HIGHRES_IMU.xacc,yacc,zacc"


def test_tlog_without_a_local_frame_reads_the_global_position(tmp_path: Path) -> None:
    """A vehicle that streams GLOBAL_POSITION_INT and no LOCAL_POSITION_NED (ArduPlane 3.8's
    default streams, ArduCopter before its EKF origin is set): the position about the first
    fix and the height above home, to the message's resolution (degE7 is 11 mm, velocity
    cm/s)."""
    log = known_flight()
    back = read_log(write_tlog(tmp_path / "global.tlog", log, position="global"))

    def at(a: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(back.time_s, log.time_s, c) for c in a.T])

    start = np.array([*log.position_m[0, :2], 0.0])  # horizontally; up: above home
    np.testing.assert_allclose(back.position_m, at(log.position_m) - start, atol=0.015)
    np.testing.assert_allclose(back.velocity_m_s, at(log.velocity_m_s), atol=0.006)
    np.testing.assert_allclose(back.rotor_speeds_rad_s, at(log.rotor_speeds_rad_s), rtol=3e-3)
    assert back.meta["sources"]["position"].startswith("GLOBAL_POSITION_INT.lat,lon about")


def test_tlog_esc_rpm_preferred_to_the_outputs(tmp_path: Path) -> None:
    log = known_flight()
    back = read_log(write_tlog(tmp_path / "esc.tlog", log, esc=True))
    assert back.meta["sources"]["actuators"].startswith("ESC_TELEMETRY_1_TO_4.rpm")
    assert_round_trip(back, log, rotor_rel=2e-3)  # whole rpm


def test_tlog_logging_gap_rows_are_dropped_and_counted(tmp_path: Path) -> None:
    log = known_flight()
    back = read_log(write_tlog(tmp_path / "gap.tlog", log, hole_s=(4.0, 5.0)))
    dropped = back.meta["rows_dropped_at_gaps"]
    assert 45 <= dropped <= 52  # one second at 50 Hz, give or take the edges
    assert not np.any((back.time_s > 4.02) & (back.time_s < 4.98))
    assert f"{dropped} rows dropped at logging gaps" in "\n".join(back.meta["conversions"])
    assert_round_trip(back, log, rotor_rel=3e-3, gap=dropped)


def test_vtol_log_with_four_motors_is_converted_with_a_warning(tmp_path: Path) -> None:
    log = known_flight()
    funcs = {f"SERVO{ch}_FUNCTION": 33.0 + i for i, ch in enumerate((5, 6, 7, 8))}
    path = write_tlog(tmp_path / "vtol.tlog", log, mav_type=22, params=funcs,
                      motor_outputs=(5, 6, 7, 8))  # fmt: skip
    back = read_log(path)
    assert_round_trip(back, log, rotor_rel=3e-3)
    assert any("warning: a MAV_TYPE 22 ArduPilot log, not a quadrotor's" in c
               for c in back.meta["conversions"])  # fmt: skip


# ---- ArduPilot DataFlash logs, written by a minimal writer ---------------------------------

DF_FORMATS = {  # name: (type, format characters, columns), as ArduCopter 4 logs them
    "PARM": (64, "QNf", "TimeUS,Name,Value"),
    "MSG": (65, "QZ", "TimeUS,Message"),
    "ATT": (66, "QccccCC", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw"),
    "IMU": (67, "QBffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ"),
    "XKF1": (68, "QBffffff", "TimeUS,C,VN,VE,VD,PN,PE,PD"),
    "RCOU": (69, "QHHHHHHHH", "TimeUS,C1,C2,C3,C4,C5,C6,C7,C8"),
    "BAT": (70, "QBf", "TimeUS,Inst,Volt"),  # Instance before 4.1
}


def df_record(name: str, *values: object, formats: dict = DF_FORMATS) -> bytes:
    """One record of message `name` as `formats` lays it out."""
    from pymavlink.DFReader import FORMAT_TO_STRUCT

    kind, chars, _ = formats[name]
    packed = []
    for c, v in zip(chars, values, strict=True):
        scale = FORMAT_TO_STRUCT[c][1]
        if isinstance(v, str):
            v = v.encode()
        packed.append(round(v / scale) if scale else v)
    body = struct.pack("<" + "".join(FORMAT_TO_STRUCT[c][0] for c in chars), *packed)
    return bytes([0xA3, 0x95, kind]) + body


def df_formats(formats: dict) -> bytes:
    """The FMT records (type 128, 89 bytes) that declare `formats`."""
    from pymavlink.DFReader import FORMAT_TO_STRUCT

    out = b""
    for name, (kind, chars, cols) in formats.items():
        length = 3 + struct.calcsize("<" + "".join(FORMAT_TO_STRUCT[c][0] for c in chars))
        out += bytes([0xA3, 0x95, 0x80]) + struct.pack(
            "<BB4s16s64s", kind, length, name.encode(), chars.encode(), cols.encode()
        )
    return out


def write_dataflash(
    path: Path, log: FlightLog, *, attitude: bool = True, vehicle_text: str = "ArduCopter V4.5.7"
) -> Path:
    """A DataFlash log of `log`: an FMT record per message type (type 128, 89 bytes), then
    PARM, MSG and the messages at TimeUS."""
    out = bytearray(df_formats(DF_FORMATS))
    t0 = round((log.time_s[0] - 0.1) * 1e6)
    out += df_record("MSG", t0, vehicle_text)
    for name, value in AC_PARAMS.items():
        out += df_record("PARM", t0, name, value)
    a = ned_frd(log)
    pwm = arducopter_pwm(log.rotor_speeds_rad_s, AC_PARAMS)[:, [3, 1, 0, 2]]
    for k, t in enumerate(log.time_s):
        us = round(t * 1e6)
        roll, pitch, yaw = np.degrees(a["euler"][k])
        if attitude:
            out += df_record("ATT", us, 0.0, roll, 0.0, pitch, 0.0, yaw % 360.0)
        out += df_record("IMU", us, 0, *a["rates"][k], *a["specific_force"][k])
        out += df_record("XKF1", us, 0, *a["vel"][k], *a["pos"][k])
        out += df_record("RCOU", us, *(round(p) for p in pwm[k]), 0, 0, 0, 0)
        out += df_record("BAT", us, 1, 5.0) + df_record("BAT", us, 0, 11.1)  # two batteries
    path.write_bytes(bytes(out))
    return path


def assert_dataflash_round_trip(back: FlightLog, log: FlightLog) -> None:
    """A DataFlash log of `log` read back: ATT in centidegrees (0.005 degrees is 9e-5 rad),
    PWM in whole microseconds (0.3% of the thrust), the rest in floats."""

    def at(a: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(back.time_s, log.time_s, c) for c in a.T])

    dots = np.abs(np.sum(back.quaternion * at(log.quaternion), axis=1))
    assert dots.min() > 1 - 1e-8
    np.testing.assert_allclose(back.position_m, at(log.position_m), atol=1e-4)
    np.testing.assert_allclose(back.velocity_m_s, at(log.velocity_m_s), atol=1e-4)
    np.testing.assert_allclose(back.rotor_speeds_rad_s, at(log.rotor_speeds_rad_s), rtol=3e-3)
    np.testing.assert_allclose(back.acceleration_m_s2, at(log.acceleration_m_s2), atol=2e-3)
    np.testing.assert_allclose(back.body_rates_rad_s, at(log.body_rates_rad_s), atol=1e-5)


def test_dataflash_round_trip(tmp_path: Path) -> None:
    log = known_flight()
    back = read_log(write_dataflash(tmp_path / "00000001.BIN", log))
    assert_dataflash_round_trip(back, log)
    assert back.battery_v == pytest.approx(np.full(len(back), 11.1))
    assert back.meta["autopilot"] == "ArduCopter V4.5.7"
    assert back.meta["sources"]["position"] == "XKF1.PN,PE,PD C=0"


# ---- the PX4 ULog fixture -------------------------------------------------------------------


def test_ulog_fixture_end_to_end() -> None:
    back = read_log(ULOG)
    assert 290 <= len(back) <= 300  # 9.5 s on vehicle_attitude's 31.3 Hz
    assert back.time_s[-1] - back.time_s[0] == pytest.approx(9.5, abs=0.1)
    np.testing.assert_allclose(np.linalg.norm(back.quaternion, axis=1), 1.0, atol=1e-12)
    assert np.all(back.rotor_speeds_rad_s == 0.0)  # disarmed: PWM 900 below PWM_MIN 1075
    assert np.all((back.position_m[:, 2] > 0.1) & (back.position_m[:, 2] < 0.6))  # ENU: up
    # on the ground: the accelerometer less gravity is about zero
    assert np.abs(np.median(back.acceleration_m_s2, axis=0)).max() < 0.3
    assert back.meta["sources"] == {
        "position": "vehicle_local_position.xyz",
        "velocity": "vehicle_local_position.vx,vy,vz",
        "attitude": "vehicle_attitude.q",
        "rates": "vehicle_attitude.rollspeed..yawspeed",
        "acceleration": "sensor_combined.accelerometer_m_s2",
        "actuators": "actuator_outputs.output[0, 1, 2, 3]",
    }
    notes = "\n".join(back.meta["conversions"])
    assert "(PWM_MIN/PWM_MAX)" in notes and "MPC_THR_HOVER 0.5" in notes


# ---- one test per refusal -------------------------------------------------------------------


def test_refuses_a_log_without_position(tmp_path: Path) -> None:
    path = write_tlog(tmp_path / "nopos.tlog", known_flight(2.0), position=False)
    message = "nopos.tlog: this MAVLink telemetry log has no position (looked for "
    with pytest.raises(ConfigError, match=re.escape(
        message + "LOCAL_POSITION_NED or GLOBAL_POSITION_INT); the log has: ATT"
    )):  # fmt: skip
        read_log(path)


def test_refuses_a_log_without_attitude(tmp_path: Path) -> None:
    path = write_dataflash(tmp_path / "noatt.bin", known_flight(2.0), attitude=False)
    with pytest.raises(ConfigError, match=r"noatt.bin: this ArduPilot DataFlash log has no "
                       r"attitude \(looked for ATT\); the log has: BAT \(200\), IMU"):  # fmt: skip
        read_log(path)


def test_refuses_a_log_without_actuator_outputs(tmp_path: Path) -> None:
    path = write_tlog(tmp_path / "noout.tlog", known_flight(2.0), servo=False)
    message = "noout.tlog: this MAVLink telemetry log has no actuator outputs (looked for ESC_"
    with pytest.raises(ConfigError, match=re.escape(message)):
        read_log(path)


def test_refuses_a_hexarotor(tmp_path: Path) -> None:
    path = write_tlog(tmp_path / "hexa.tlog", known_flight(2.0), mav_type=13)
    with pytest.raises(ConfigError, match=r"a hexarotor \(HEARTBEAT type 13\); the diagnosis "
                       "models a quadrotor's four rotors: not converted"):  # fmt: skip
        read_log(path)


def test_refuses_a_plane_without_four_motors(tmp_path: Path) -> None:
    path = write_dataflash(tmp_path / "plane.bin", known_flight(2.0), vehicle_text="ArduPlane V4.5")
    message = "plane.bin: a fixed-wing log without four motor outputs (SERVOn_FUNCTION 33..36 "
    with pytest.raises(ConfigError, match=re.escape(message + "for motors 1..4; found: none)")):
        read_log(path)


def test_refuses_a_damaged_ulog(tmp_path: Path) -> None:
    path = tmp_path / "bad.ulg"
    path.write_bytes(b"not a ulog at all" * 10)
    with pytest.raises(ConfigError, match=r"bad.ulg: not a readable PX4 ULog \("):
        read_log(path)


def test_refuses_a_column_mapping_for_an_autopilot_log(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="a PX4 ULog is read by topic; a column mapping"):
        read_log(ULOG, ColumnMapping(names={"x_m": "pos_x"}))


def test_refuses_a_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nothing\.tlog: no such flight log"):
        read_log(tmp_path / "nothing.tlog")


# ---- through the command line ---------------------------------------------------------------


def test_gap_diagnose_reads_written_autopilot_logs(tmp_path: Path) -> None:
    a = write_tlog(tmp_path / "a.tlog", known_flight(10.0))
    b = write_dataflash(tmp_path / "b.bin", known_flight(10.0, phase=1.0))
    out = tmp_path / "out"
    r = run_groundfx("gap", "diagnose", str(a), str(b), "--world", "default", "--no-replay",
                     "--out", str(out), "--folds", "2", "--candidates",
                     "thrust_mass,rotor_drag,ground_effect", timeout=300)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    assert (out / "report.md").is_file() and (out / "gap.json").is_file()


def test_a_real_px4_log_that_never_flew_is_refused_with_what_was_left_out(
    tmp_path: Path,
) -> None:
    """pyulog's sample: 9.5 s disarmed (PWM 900) on a bench 0.2-0.5 m above its local frame's
    zero. Its rows once stopped the run as 'implausible for a flying vehicle' (a full
    weight of residual); all in contact, a sibling sample ended in an IndexError."""
    r = run_groundfx("gap", "diagnose", str(ULOG), "--world", "default", "--no-replay",
                     "--out", str(tmp_path / "out"), timeout=300)  # fmt: skip
    assert r.returncode == 2 and "Traceback" not in r.stderr
    message = r.stderr.strip().splitlines()[-1]
    assert "only 0 of" in message and "rows are airborne and usable" in message
    assert re.search(r"\d+ rows standing with the rotors stopped", message)
