"""ArduCopter 3.3's DataFlash logs, still common in public datasets (dronekit-la's test log
log171.bin, flown at CMAC): times in TimeMS, the EKF's core in EKF1, motor outputs in RCOU
Ch1..Ch4, the battery in centivolts, the motor parameters under their old names (THR_MIN,
THR_MID, MOT_THST_MAX, RC3_MIN/MAX). Written here from a known flight, the motor PWM through
ArduCopter 3.3's own output stage (AP_MotorsMulticopter::apply_thrust_curve_and_volt_scaling),
and read back to its positions, attitude and rotor speeds, as binary and as the text Mission
Planner writes (`.log`); a hexarotor's firmware, named in its start-up text, is refused."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from learner.flightlogs.flightlog import FlightLog
from learner.flightlogs.readers import read_log
from simbridge.config import ConfigError
from tests.test_flightlogs_autopilot_logs import (
    NANO,
    assert_dataflash_round_trip,
    df_formats,
    df_record,
    known_flight,
    ned_frd,
)

FORMATS_33 = {  # name: (type, format characters, columns), as ArduCopter 3.3 logs them
    "PARM": (64, "Nf", "Name,Value"),
    "MSG": (65, "Z", "Message"),
    "ATT": (66, "IccccCCCC", "TimeMS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,ErrRP,ErrYaw"),
    "IMU": (67, "IffffffIIf", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,ErrG,ErrA,Temp"),
    "EKF1": (68, "IccCffffffccc", "TimeMS,Roll,Pitch,Yaw,VN,VE,VD,PN,PE,PD,GX,GY,GZ"),
    "RCOU": (69, "Ihhhh", "TimeMS,Ch1,Ch2,Ch3,Ch4"),
    "CURR": (70, "IhhhHfh", "TimeMS,Throttle,Volt,Curr,Vcc,CurrTot,Volt2"),
}
# ArduCopter 3.3's motor parameters, none at their defaults
PARAMS_33 = {"THR_MIN": 120.0, "THR_MID": 420.0, "MOT_THST_MAX": 0.93, "MOT_THST_EXPO": 0.7,
             "RC3_MIN": 1050.0, "RC3_MAX": 1920.0, "FRAME": 1.0}  # fmt: skip


def pwm_33(rotors_rad_s: np.ndarray, p: dict[str, float]) -> np.ndarray:
    """The PWM ArduCopter 3.3 sends for these rotor speeds (thrust through nano's C_T): the
    throttle (0..1) at which its linearised thrust gives them, THR_MID's hovering, mapped
    onto RC3_MIN..RC3_MAX (calc_throttle_radio_output), then its thrust curve between
    out_min = RC3_MIN + THR_MIN of the span and RC3_MAX (apply_thrust_curve_and_volt_scaling,
    no voltage scaling: lift_max 1)."""
    weight_share = NANO.thrust_coefficient_n_s2 * rotors_rad_s**2 / (NANO.weight_n / 4)
    s, hover = p["THR_MIN"] / 1000.0, p["THR_MID"] / 1000.0
    throttle = s + (hover - s) * weight_share  # thrust linear in the throttle above THR_MIN
    lo, hi = p["RC3_MIN"], p["RC3_MAX"]
    pwm_in = lo + throttle * (hi - lo)
    out_min = lo + s * (hi - lo)
    ratio = (pwm_in - out_min) / (hi - out_min)
    e = p.get("MOT_THST_EXPO", 0.0)  # ArduCopter 3.2 and before: no curve
    if e > 0.0:
        ratio = ((e - 1.0) + np.sqrt((1.0 - e) ** 2 + 4.0 * e * ratio)) / (2.0 * e)
    return ratio * p.get("MOT_THST_MAX", 1.0) * (hi - out_min) + out_min


def write_dataflash_33(
    path: Path, log: FlightLog, frame_text: str = "Frame: QUAD", params: dict | None = None
) -> Path:
    params = PARAMS_33 if params is None else params

    def rec(name: str, *values: object) -> bytes:
        return df_record(name, *values, formats=FORMATS_33)

    out = bytearray(df_formats(FORMATS_33))
    out += rec("MSG", "APM:Copter V3.3.3 (acf2e10c)") + rec("MSG", frame_text)
    for name, value in params.items():
        out += rec("PARM", name, value)
    a = ned_frd(log)
    pwm = pwm_33(log.rotor_speeds_rad_s, params)[:, [3, 1, 0, 2]]  # ours to quad X's
    for k, t in enumerate(log.time_s):
        ms = round(t * 1000)
        roll, pitch, yaw = np.degrees(a["euler"][k])
        out += rec("ATT", ms, 0.0, roll, 0.0, pitch, 0.0, yaw % 360.0, 0.0, 0.0)
        out += rec("IMU", ms, *a["rates"][k], *a["specific_force"][k], 0, 0, 25.0)
        out += rec("EKF1", ms, roll, pitch, yaw % 360.0, *a["vel"][k], *a["pos"][k], 0, 0, 0)
        out += rec("RCOU", ms, *(round(x) for x in pwm[k]))
        out += rec("CURR", ms, 400, 1654, 1200, 5000, 100.0, 0)  # 16.54 V in centivolts
    path.write_bytes(bytes(out))
    return path


def test_an_arducopter_33_log_reads_back_to_its_flight(tmp_path: Path) -> None:
    log = known_flight()
    back = read_log(write_dataflash_33(tmp_path / "log171.bin", log))
    assert_dataflash_round_trip(back, log)
    assert back.battery_v == pytest.approx(np.full(len(back), 16.54))
    assert back.time_s[-1] - back.time_s[0] == pytest.approx(log.time_s[-1] - log.time_s[0],
                                                             abs=0.03)  # fmt: skip
    assert back.meta["autopilot"] == "APM:Copter V3.3.3 (acf2e10c)"
    assert back.meta["sources"]["position"] == "EKF1.PN,PE,PD C=0"
    notes = "\n".join(back.meta["conversions"])
    assert "ArduCopter 3.3's motor parameters: THR_MIN 120, THR_MID 420" in notes
    assert "not in the log" not in notes


def test_an_arducopter_32_log_reads_its_output_linear_in_the_throttle(tmp_path: Path) -> None:
    """Before 3.3 there was no MOT_THST_EXPO or MOT_THST_MAX: the motors' PWM was the throttle
    mapped linearly onto RC3_MIN..RC3_MAX (read as such, not through 3.3's default curve)."""
    log = known_flight()
    params = {k: v for k, v in PARAMS_33.items() if k not in ("MOT_THST_EXPO", "MOT_THST_MAX")}
    back = read_log(write_dataflash_33(tmp_path / "old.bin", log, params=params))
    at = np.column_stack([np.interp(back.time_s, log.time_s, c) for c in log.rotor_speeds_rad_s.T])
    np.testing.assert_allclose(back.rotor_speeds_rad_s, at, rtol=3e-3)
    notes = "\n".join(back.meta["conversions"])
    assert "ArduCopter 3.2 or older's motor parameters" in notes
    assert "not in the log" not in notes


def as_text(binary: Path, text: Path) -> Path:
    """The log as Mission Planner writes it as text: 'NAME, v1, v2, ...' lines."""
    from pymavlink import DFReader

    reader = DFReader.DFReader_binary(str(binary))
    lines = []
    while (m := reader.recv_msg()) is not None:
        if m.get_type() == "FMT":
            lines.append(f"FMT, {m.Type}, {m.Length}, {m.Name}, {m.Format}, {m.Columns}")
        else:
            lines.append(", ".join([m.get_type(), *(str(getattr(m, c)) for c in m.fmt.columns)]))
    text.write_text("\n".join(lines) + "\n")
    return text


def test_a_dataflash_log_as_text_reads_as_the_binary_one(tmp_path: Path) -> None:
    binary = write_dataflash_33(tmp_path / "log171.bin", known_flight(3.0))
    from_text = read_log(as_text(binary, tmp_path / "log171.log"))  # sniffed: FMT first
    from_binary = read_log(binary)
    np.testing.assert_array_equal(from_text.time_s, from_binary.time_s)
    np.testing.assert_allclose(from_text.position_m, from_binary.position_m, atol=1e-6)
    np.testing.assert_allclose(from_text.quaternion, from_binary.quaternion, atol=1e-6)
    np.testing.assert_allclose(from_text.rotor_speeds_rad_s, from_binary.rotor_speeds_rad_s,
                               rtol=1e-6)  # fmt: skip


def test_an_arducopter_33_hexarotor_is_refused(tmp_path: Path) -> None:
    path = write_dataflash_33(tmp_path / "hexa.bin", known_flight(2.0), frame_text="Frame: HEXA")
    with pytest.raises(ConfigError, match=re.escape("a hexarotor (its start-up text: 'Frame: "
                                                    "HEXA'); the diagnosis models")):  # fmt: skip
        read_log(path)


def test_thr_mid_at_or_below_thr_min_is_refused(tmp_path: Path) -> None:
    params = {**PARAMS_33, "THR_MID": 100.0}
    path = write_dataflash_33(tmp_path / "low.bin", known_flight(2.0), params=params)
    with pytest.raises(ConfigError, match=r"THR_MID 100 at or below THR_MIN 120: .*THR_MID "
                       r"must lie in 120\.\.1000"):  # fmt: skip
        read_log(path)
