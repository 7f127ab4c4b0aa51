"""A new flight-log format is one registration: a toy format this test invents (its writer,
its reader, its content test) is read by `read_log` and `groundfx gap convert` through
`readers.register` alone, by its suffix and by its content."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from learner.flightlogs import readers
from learner.flightlogs.flightlog import FlightLog
from learner.flightlogs.readers import LogFormat, read_log, register
from mission.cli.main import build_parser, main
from simbridge.config import ConfigError

MAGIC = "TOYLOG,1"  # the first line; its comma would make a CSV of it for the loose CSV test
FIELDS = 18  # time, position, velocity, quaternion (w, x, y, z), rates, rotor speeds


def hover_flight(n: int = 200, rate_hz: float = 100.0) -> FlightLog:
    """A nano quadrotor bobbing about 0.3 m, turning slowly."""
    t = np.arange(n) / rate_hz
    w = 2 * math.pi * 0.5
    pos = np.column_stack([0.01 * np.sin(w * t), np.zeros(n), 0.3 + 0.02 * np.sin(w * t)])
    vel = np.column_stack([0.01 * w * np.cos(w * t), np.zeros(n), 0.02 * w * np.cos(w * t)])
    yaw = 0.1 * t
    quat = np.column_stack([np.cos(yaw / 2), np.zeros(n), np.zeros(n), np.sin(yaw / 2)])
    rates = np.column_stack([np.zeros(n), np.zeros(n), np.full(n, 0.1)])
    rotors = 76.0 + np.sin(w * t[:, None] + np.arange(4))
    return FlightLog("toy", t, pos, vel, quat, rates, rotors)


def write_toy(log: FlightLog, path: Path) -> Path:
    rows = np.column_stack(
        [log.time_s, log.position_m, log.velocity_m_s, log.quaternion, log.body_rates_rad_s,
         log.rotor_speeds_rad_s]
    )  # fmt: skip
    lines = [MAGIC] + [",".join(repr(float(v)) for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def read_toy(path: Path, mapping: object, vehicle: object) -> FlightLog:
    lines = path.read_text().splitlines()
    if lines[0] != MAGIC:
        raise ConfigError(f"{path}: not a toy log")
    a = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]]).reshape(-1, FIELDS)
    return FlightLog(path.stem, a[:, 0], a[:, 1:4], a[:, 4:7], a[:, 7:11], a[:, 11:14], a[:, 14:])


def is_toy(head: bytes) -> bool:
    return head.startswith(MAGIC.encode())


@pytest.fixture
def formats(monkeypatch: pytest.MonkeyPatch) -> None:
    """The registered formats as they are, restored after the test."""
    monkeypatch.setattr(readers, "FORMATS", list(readers.FORMATS))


def same_flight(a: FlightLog, b: FlightLog) -> bool:
    fields = ("time_s", "position_m", "velocity_m_s", "quaternion", "rotor_speeds_rad_s")
    return all(np.allclose(getattr(a, f), getattr(b, f), rtol=1e-8, atol=1e-9) for f in fields)


def test_a_registered_format_is_read_by_suffix_and_by_content(tmp_path: Path, formats) -> None:
    flight = hover_flight()
    toy = write_toy(flight, tmp_path / "flight.toy")
    unnamed = write_toy(flight, tmp_path / "log07")  # as a microSD card names its files
    with pytest.raises(ConfigError, match=r"flight\.toy: "):  # the CSV reader refuses it
        read_log(toy)

    register(LogFormat("toy log", read_toy, (".toy",), is_toy))

    assert same_flight(read_log(toy), flight)
    assert same_flight(read_log(unnamed), flight)  # before the looser CSV test claims it
    with pytest.raises(ValueError, match=r"\.toy is already toy log's"):
        register(LogFormat("another toy", read_toy, (".toy",)))


def test_gap_convert_reads_a_registered_format_and_names_it_in_its_help(
    tmp_path: Path, formats, capsys: pytest.CaptureFixture[str]
) -> None:
    flight = hover_flight()
    toy = write_toy(flight, tmp_path / "flight.toy")
    out = tmp_path / "ours.csv"
    assert main(["gap", "convert", str(toy), str(out)]) == 2  # not a format yet
    assert "flight.toy: " in capsys.readouterr().err

    register(LogFormat("toy log", read_toy, (".toy",), is_toy))

    assert main(["gap", "convert", str(toy), str(out)]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    assert same_flight(read_log(out), flight)
    with pytest.raises(SystemExit):
        build_parser().parse_args(["gap", "convert", "--help"])
    assert "toy log (.toy or by content)" in " ".join(capsys.readouterr().out.split())
