"""The command line: the figure, the benchmark's figures and the demo, as a user runs them."""

from __future__ import annotations

import json

import pytest

from tests.helpers import run_groundfx


def test_plot_ground_effect_writes_a_png(tmp_path):
    out = tmp_path / "ge.png"
    result = run_groundfx("plot", "ground-effect", "--rho", "1,2", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 10_000


def test_plot_refuses_a_bad_rho():
    result = run_groundfx("plot", "ground-effect", "--rho", "1,-2")
    assert result.returncode == 2 and "--rho" in result.stderr and "Traceback" not in result.stderr


def test_bench_sim_prints_its_figures_as_json():
    result = run_groundfx("bench", "sim", "--json", "--seconds", "1", "--repeat", "1")
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout.strip().splitlines()[-1])
    assert figures["physics_rtf"] > 0 and figures["lockstep_rtf"] > 0
    # each beside its reference, measured in the same run
    assert figures["physics_ratio"] == figures["physics_rtf"] / figures["bare_loop_rtf"]
    assert figures["lockstep_ratio"] == figures["lockstep_rtf"] / figures["pingpong_rtf"]
    # ... and against a pymavlink simulator with physics, which served every step too
    physics = figures["lockstep_rtf"] / figures["pingpong_physics_rtf"]
    assert figures["lockstep_physics_ratio"] == physics
    # 1 s at 250 Hz timed, after the first tick answered before the clocks start
    assert "251 steps" in figures["pingpong_physics_report"]
    assert len(figures["load_average"]) == 2
    assert figures["effects"] == ["ground_effect"] and figures["physics_hz"] == 1000
    assert figures["control_hz"] == 250
    assert figures["physics_altitude_drift_m"] < 1e-3  # it benchmarks a hovering drone
    # where the time goes: the CPU each end of each loop spent a step (Linux /proc)
    for key in ("lockstep_sim", "lockstep_client", "pingpong_server", "pingpong_client",
                "pingpong_physics_server", "pingpong_physics_client"):  # fmt: skip
        assert figures[f"{key}_cpu_us_per_step"] >= 0.0
    assert "autopilot disconnected; 251 steps" in figures["sim_report"]
    # the loop and its reference wake up alike: both say what became of the latency request
    assert figures["cpu_wake_latency"].startswith("CPU wake-up latency")
    assert figures["cpu_wake_latency"] in figures["pingpong_report"]


def test_demo_shows_the_ground_effect_lifting_the_drone(tmp_path):
    result = run_groundfx("demo", "--lift", "--logs", str(tmp_path))
    assert result.returncode == 0, result.stderr
    # PyBullet's build banner is not our output (simbridge/pybullet_quiet.py)
    assert "pybullet build time" not in result.stdout + result.stderr
    lines = result.stdout.splitlines()
    predicted = float(next(ln for ln in lines if "predicts" in ln).split("predicts")[1].split()[0])
    rows = [ln.split() for ln in lines if ln.strip()[:1].isdigit()]
    altitudes = [float(r[1]) for r in rows]
    assert altitudes == sorted(altitudes) and altitudes[-1] > 0.1  # it climbs out of ground effect
    assert float(rows[0][3]) == pytest.approx(predicted, rel=0.01)  # measured over MAVLink
    assert (tmp_path / "ground_effect.png").exists()


def test_fly_writes_a_flight_log_and_ends_at_its_time_limit(tmp_path):
    log = tmp_path / "hover.csv"
    result = run_groundfx(
        "fly", "mission/examples/hover.yaml", "--no-gcs", "--no-record", "--json",
        "--flight-log", str(log), "--max-flight-s", "3",
    )  # fmt: skip
    summary = json.loads(result.stdout.strip().splitlines()[-1])
    assert summary["ended"] == "mission time limit" and result.returncode == 1
    header, *rows = [ln for ln in log.read_text().splitlines() if not ln.startswith("#")]
    assert header.startswith("time_s,x_m,y_m,z_m") and len(rows) > 100  # airborne steps
    assert float(rows[-1].split(",")[0]) <= 3.0


def test_a_flight_request_crosses_to_the_autopilot_as_its_own_command_line():
    """What `fly` and `sitl` ask of the autopilot process reads back as the same request:
    repeatable options in order, a southern origin's leading minus, the tri-state online
    mode; options left at their defaults are not written at all."""
    from pathlib import Path

    from autopilot.request import FlightRequest

    request = FlightRequest(
        sim="unix:/tmp/sim.sock",
        mission=Path("mission/examples/hover.yaml"),
        auto_start=True,
        model="neural",
        rho=2.0,
        out=("udpout:127.0.0.1:14550", "tcpin:0.0.0.0:5760"),
        param=("GFX_OL_LR=0.01", "MIS_TAKEOFF_ALT=-2"),
        origin="-33.8568,151.2153,10",
        online="rls",
        online_deterministic=False,
        max_flight_s=12.5,
    )
    assert FlightRequest.parse(request.argv()) == request
    assert FlightRequest().argv() == [] and FlightRequest.parse([]) == FlightRequest()
    more = request.with_options(["--param", "GFX_POS_I=0", "--rho", "1"])
    assert more.param == (*request.param, "GFX_POS_I=0") and more.rho == 1.0


def test_bench_campaign_prints_flights_per_minute_for_one_and_two_workers():
    result = run_groundfx("bench", "campaign", "--flights", "1", "--json")
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout.strip().splitlines()[-1])
    rates = [figures[f"flights_per_min_{k}"] for k in ("1_on_1_core", "1", "2")]
    assert all(r > 0 for r in rates)
    assert figures["speedup"] == rates[2] / rates[1]
    assert figures["speedup_per_core"] == rates[2] / rates[0]


def test_bench_online_compares_the_learner_working_and_resting_within_each_flight():
    """The learner works and rests in 1 s turns: both hold control steps, samples (100 Hz)
    are taken only in the working ones, and the ratios are those of the pooled steps."""
    result = run_groundfx(
        "bench", "online", "--method", "naive", "--repeat", "1", "--hold-s", "2", "--json"
    )
    assert result.returncode in (0, 3), result.stderr  # 3: a target missed on a busy machine
    r = json.loads(result.stdout.strip().splitlines()[-1])
    assert r["steps_working"] > 900 and r["steps_resting"] > 900
    assert r["sim_s_working"] == pytest.approx(r["sim_s_resting"], abs=1.0)
    samples = sum(r["online_samples"])
    assert 0.8 * 100 * r["sim_s_working"] < samples <= 100 * r["sim_s_working"] + 2
    assert r["online_updates"][0] >= 4 and r["online_errors"] == []
    assert r["p99_ratio"] == r["controller_us_p99_working"] / r["controller_us_p99_resting"]
    assert r["rtf_ratio"] == r["rtf_working"] / r["rtf_resting"]
    met = r["meets_p99_target"] and r["meets_rtf_target"] and r["no_sample_dropped"]
    assert result.returncode == (0 if met else 3)
