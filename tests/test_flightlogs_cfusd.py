"""Crazyflie microSD-deck logs (both formats), written by a tiny encoder of each format in
the test and read back without a mapping; their refusals."""

from __future__ import annotations

import math
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from learner.flightlogs.flightlog import FlightLog
from learner.flightlogs.readers import read_log
from simbridge.config import ConfigError
from tests.helpers import run_groundfx
from tests.test_flightlogs import CF, G_UP, known_flight, thrust_n


def quat_compress(q_xyzw: np.ndarray) -> np.ndarray:
    """The firmware's quatcompress (quatcompress.h), for the test's own logs."""
    out = []
    for q in q_xyzw:
        largest = int(np.argmax(np.abs(q)))
        negative = q[largest] < 0
        c = largest
        for i in range(4):
            if i != largest:
                sign = int((q[i] < 0) ^ negative)
                c = (c << 10) | (sign << 9) | int(511 * abs(q[i]) / math.sqrt(0.5) + 0.5)
        out.append(c)
    return np.array(out, dtype=np.uint32)


def cf_variables(log: FlightLog, compressed: bool) -> list[tuple[str, str, np.ndarray]]:
    """The neural-swarm variables (compressed state, mm, mrad/s, world +g in az) or the
    float state estimate (m, g, deg/s gyro), with motor.f1..f4 in motor order M1..M4."""
    f = thrust_n(log)
    xyzw = log.quaternion[:, [1, 2, 3, 0]]
    if compressed:
        acc = log.acceleration_m_s2 + G_UP
        s = "stateEstimateZ."
        vars_ = [(s + a, "h", np.round(log.position_m[:, i] * 1000)) for i, a in enumerate("xyz")]
        vars_ += [
            (s + "v" + a, "h", np.round(log.velocity_m_s[:, i] * 1000)) for i, a in enumerate("xyz")
        ]
        vars_ += [(s + "a" + a, "h", np.round(acc[:, i] * 1000)) for i, a in enumerate("xyz")]
        vars_ += [(s + "quat", "I", quat_compress(xyzw))]
        vars_ += [(s + r, "h", np.round(log.body_rates_rad_s[:, i] * 1000))
                  for i, r in enumerate(("rateRoll", "ratePitch", "rateYaw"))]  # fmt: skip
    else:
        s = "stateEstimate."
        vars_ = [(s + a, "f", log.position_m[:, i]) for i, a in enumerate("xyz")]
        vars_ += [(s + "v" + a, "f", log.velocity_m_s[:, i]) for i, a in enumerate("xyz")]
        vars_ += [
            (s + "a" + a, "f", log.acceleration_m_s2[:, i] / 9.81) for i, a in enumerate("xyz")
        ]
        vars_ += [(s + "q" + a, "f", xyzw[:, i]) for i, a in enumerate("xyzw")]
        vars_ += [
            (f"gyro.{a}", "f", np.degrees(log.body_rates_rad_s[:, i])) for i, a in enumerate("xyz")
        ]
    # motor order: M1 front-right (our 3), M2 back-right (2), M3 back-left (1), M4 front-left (0)
    vars_ += [(f"motor.f{m}", "f", f[:, 4 - m]) for m in range(1, 5)]
    vars_ += [("pm.vbatMV", "H", np.full(len(log), 3700))]
    return vars_


def records(variables: list[tuple[str, str, np.ndarray]]) -> np.ndarray:
    dtype = np.dtype([(n, "<" + t) for n, t, _ in variables])
    rec = np.zeros(len(variables[0][2]), dtype)
    for name, _, values in variables:
        rec[name] = values
    return rec


def legacy_cfusd(log: FlightLog, bad_block: int | None = None) -> bytes:
    """uint8 N, 'name(T),' entries, CRC; blocks of uint8 k, k records, CRC (each CRC the
    complement of crc32, little-endian: crc32 over the bytes and it is the residue)."""
    variables = [("tick", "I", np.round((log.time_s - log.time_s[0]) * 1e6) + 9954)]
    variables += cf_variables(log, compressed=True)

    def crc(b: bytes) -> bytes:
        return struct.pack("<I", zlib.crc32(b) ^ 0xFFFFFFFF)

    header = bytes([len(variables)]) + b"".join(f"{n}({t}),".encode() for n, t, _ in variables)
    out = header + crc(header)
    rec = records(variables)
    for k, start in enumerate(range(0, len(rec), 2)):
        block = bytes([len(rec[start : start + 2])]) + rec[start : start + 2].tobytes()
        block += crc(block)
        if k == bad_block:
            block = block[:3] + bytes([block[3] ^ 0xFF]) + block[4:]
        out += block
    return out


def event_cfusd(
    log: FlightLog, version: int, events: tuple[str, ...] = ("fixedFrequency",)
) -> bytes:
    """0xBC, version, event types (id, name, variables), records (id, timestamp, payload), crc32."""
    variables = cf_variables(log, compressed=False)
    out = b"\xbc" + struct.pack("<HH", version, len(events) + 1)
    for eid, name in enumerate(events):
        out += struct.pack("<H", eid) + name.encode() + b"\x00" + struct.pack("<H", len(variables))
        out += b"".join(f"{n}({t})".encode() + b"\x00" for n, t, _ in variables)
    out += struct.pack("<H", 99) + b"estPosition\x00" + struct.pack("<H", 1) + b"x(f)\x00"
    rec = records(variables)
    stamp = struct.Struct("<HI" if version == 1 else "<HQ")
    unit = 1e3 if version == 1 else 1e6
    for k, r in enumerate(rec):
        out += stamp.pack(0, round(log.time_s[k] * unit)) + r.tobytes()
        out += stamp.pack(99, round(log.time_s[k] * unit) + 1) + struct.pack("<f", 0.5)
    return out + struct.pack("<I", zlib.crc32(out))


def test_crazyflie_legacy_microsd_log_reads_without_a_mapping(tmp_path: Path) -> None:
    log = known_flight()
    path = tmp_path / "cf50_01"
    path.write_bytes(legacy_cfusd(log))
    got = read_log(path, vehicle=CF)
    assert got.time_s - got.time_s[0] == pytest.approx(log.time_s - log.time_s[0], abs=1e-6)
    assert got.position_m == pytest.approx(log.position_m, abs=6e-4)  # mm in int16
    assert got.acceleration_m_s2 == pytest.approx(log.acceleration_m_s2, abs=6e-4)
    assert np.abs(np.sum(got.quaternion * log.quaternion, axis=1)) == pytest.approx(1.0, abs=1e-5)
    assert got.body_rates_rad_s == pytest.approx(log.body_rates_rad_s, abs=6e-4)
    assert got.rotor_speeds_rad_s == pytest.approx(log.rotor_speeds_rad_s, rel=1e-6)
    assert got.battery_v == pytest.approx(3.7)
    assert "packaged mapping crazyflie_z" in " ".join(got.meta["conversions"])


def test_crazyflie_legacy_block_with_a_bad_crc_is_left_out_and_counted(tmp_path: Path) -> None:
    log = known_flight()
    path = tmp_path / "log00"
    path.write_bytes(legacy_cfusd(log, bad_block=3))
    got = read_log(path, vehicle=CF)
    assert len(got) == len(log) - 2
    assert "microSD: 1 block with a bad CRC left out (2 records)" in got.meta["conversions"]


@pytest.mark.parametrize("version", [1, 2])
def test_crazyflie_event_microsd_log_reads_without_a_mapping(tmp_path: Path, version: int) -> None:
    log = known_flight()
    path = tmp_path / "log07"
    path.write_bytes(event_cfusd(log, version))
    got = read_log(path, vehicle=CF)
    assert len(got) == len(log)
    assert got.time_s == pytest.approx(log.time_s, abs=1e-3 if version == 1 else 1e-6)
    assert got.position_m == pytest.approx(log.position_m, abs=1e-6)
    assert got.acceleration_m_s2 == pytest.approx(log.acceleration_m_s2, abs=1e-5)
    assert got.body_rates_rad_s == pytest.approx(log.body_rates_rad_s, abs=1e-6)
    assert got.rotor_speeds_rad_s == pytest.approx(log.rotor_speeds_rad_s, rel=1e-6)


def test_refuses_an_event_log_without_a_periodic_set(tmp_path: Path) -> None:
    path = tmp_path / "log01"
    path.write_bytes(event_cfusd(known_flight(), 2, events=("onTakeoff",)))
    with pytest.raises(
        ConfigError, match=r"log01: damaged.*no 'fixedFrequency' event among onTakeoff, estPosition"
    ):
        read_log(path, vehicle=CF)


def test_refuses_a_legacy_log_without_a_tick(tmp_path: Path) -> None:
    data = legacy_cfusd(known_flight())
    path = tmp_path / "log02"
    path.write_bytes(data.replace(b"tick(I)", b"tock(I)", 1))
    with pytest.raises(ConfigError, match=r"log02: the legacy log has no 'tick' variable"):
        read_log(path, vehicle=CF)


# ---- groundfx gap convert on a Crazyflie log, through the command line


def test_gap_convert_writes_our_format_and_says_what_it_converted(tmp_path: Path) -> None:
    log = known_flight()
    src = tmp_path / "cf50_01"
    src.write_bytes(legacy_cfusd(log))
    out = tmp_path / "converted.csv"
    r = run_groundfx("gap", "convert", str(src), str(out), "--vehicle", "crazyflie2")
    assert r.returncode == 0, r.stderr
    assert "rows 300, 2.99 s, 100.0 Hz" in r.stdout
    assert "thrust: per-rotor N -> rad/s through crazyflie2's C_T 2.88e-08" in r.stdout
    assert "time: us -> s (detected" in r.stdout
    assert "warning" not in r.stdout
    back = read_log(out)
    assert back.rotor_speeds_rad_s == pytest.approx(log.rotor_speeds_rad_s, rel=1e-6)
    assert back.acceleration_m_s2 == pytest.approx(log.acceleration_m_s2, abs=6e-4)


def test_gap_convert_warns_when_the_thrust_is_not_the_vehicles_weight(tmp_path: Path) -> None:
    src = tmp_path / "cf50_01"
    src.write_bytes(legacy_cfusd(known_flight()))
    r = run_groundfx("gap", "convert", str(src), str(tmp_path / "o.csv"))  # nano, not crazyflie2
    assert r.returncode == 0, r.stderr
    assert "warning: the median vertical thrust is 0.57 x nano's weight" in r.stdout
