"""Logs the tests write themselves from known flights (a PX4 ULog, Crazyflie microSD logs,
Parquet), read back and taken end to end through `groundfx gap diagnose` (the sample ULog
fixture is a vehicle on the ground: nothing in it to diagnose)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from learner.flightlogs.flightlog import FlightLog, write_log
from learner.flightlogs.readers import read_log
from tests.helpers import groundfx_in_process
from tests.test_flightlogs_autopilot_logs import NANO, assert_round_trip, known_flight, ned_frd
from tests.test_flightlogs_cfusd import known_flight as crazyflie_flight
from tests.test_flightlogs_cfusd import legacy_cfusd
from tests.ulog_writer import write_ulog

HOVER_THROTTLE = 0.42


def px4_ulog(path: Path, log: FlightLog) -> Path:
    """The flight as PX4 logs it: NED position and velocity, FRD attitude and rates, the
    accelerometer's specific force, and actuator_motors' normalised thrust per rotor."""
    a = ned_frd(log)
    t_us = np.round(log.time_s * 1e6)[:, None]
    thrust_n = NANO.thrust_coefficient_n_s2 * log.rotor_speeds_rad_s**2
    throttle = HOVER_THROTTLE * thrust_n / (NANO.weight_n / 4)  # PX4: u / MPC_THR_HOVER
    stamp = ("uint64_t", "timestamp")
    topics = {
        "vehicle_local_position": (
            [stamp, *[("float", c) for c in ("x", "y", "z", "vx", "vy", "vz")]],
            np.hstack([t_us, a["pos"], a["vel"]]),
        ),
        "vehicle_attitude": ([stamp, ("float[4]", "q")], np.hstack([t_us, a["q"]])),
        "vehicle_angular_velocity": ([stamp, ("float[3]", "xyz")], np.hstack([t_us, a["rates"]])),
        "sensor_combined": (
            [stamp, ("float[3]", "accelerometer_m_s2")],
            np.hstack([t_us, a["specific_force"]]),
        ),
        # equal rotors in the known flight: PX4's motor order needs no mapping here
        "actuator_motors": ([stamp, ("float[4]", "control")], np.hstack([t_us, throttle])),
    }
    return write_ulog(path, topics, {"MPC_THR_HOVER": HOVER_THROTTLE, "MAV_TYPE": 2.0})


def test_a_written_ulog_reads_back_to_the_flight(tmp_path: Path) -> None:
    log = known_flight(6.0)
    back = read_log(px4_ulog(tmp_path / "flight.ulg", log), vehicle=NANO)
    assert_round_trip(back, log, rotor_rel=1e-5)
    assert back.meta["sources"]["actuators"] == "actuator_motors.control[0..3]"
    assert "MPC_THR_HOVER 0.42" in "\n".join(back.meta["conversions"])


def diagnose(tmp_path: Path, logs: list[Path], *options: str) -> dict:
    out = tmp_path / "diagnosis"
    # the formats' reading is under test here, not the search: a few candidates (the
    # command in this process: tests/test_flightlogs_autopilot_logs.py runs it as one)
    r = groundfx_in_process("gap", "diagnose", *map(str, logs), "--no-replay", "--folds", "2",
                            "--out", str(out), "--candidates",
                            "thrust_mass,rotor_drag,ground_effect", *options)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    gap = json.loads((out / "gap.json").read_text())
    assert gap["fitting_flights"] == [p.stem for p in logs]
    assert gap["left_out"]["summary"] == "left out: nothing"  # airborne throughout
    assert gap["closed_loop"] == {"status": "skipped", "why": "not asked for (--no-replay)"}
    assert "| rotor_drag |" in (out / "report.md").read_text()
    return gap


def test_px4_ulogs_go_through_a_diagnosis(tmp_path: Path) -> None:
    logs = [px4_ulog(tmp_path / f"flight{k}.ulg", known_flight(10.0, phase=k)) for k in (0, 1)]
    gap = diagnose(tmp_path, logs, "--world", "default")
    assert gap["vehicle"] == "nano"
    # the known flight is the nano vehicle's own physics: what is left is the discretisation
    assert gap["gap"]["force_rms_n"]["before"] < 0.02 * NANO.weight_n


def test_crazyflie_microsd_logs_go_through_a_diagnosis(tmp_path: Path) -> None:
    logs = []
    for k in range(2):
        path = tmp_path / f"cf50_0{k + 1}"
        path.write_bytes(legacy_cfusd(crazyflie_flight(n=600 + 100 * k)))
        logs.append(path)
    gap = diagnose(tmp_path, logs, "--world", "crazyflie_lab", "--vehicle", "crazyflie2")
    assert gap["vehicle"] == "crazyflie2"


def test_parquet_logs_go_through_a_diagnosis(tmp_path: Path) -> None:
    logs = [write_log(known_flight(10.0, phase=k), tmp_path / f"flight{k}.parquet") for k in (0, 1)]
    back = read_log(logs[0])
    assert_round_trip(back, known_flight(10.0, phase=0), rotor_rel=1e-9)
    gap = diagnose(tmp_path, logs, "--world", "default")
    assert gap["gap"]["force_rms_n"]["before"] < 0.02 * NANO.weight_n
