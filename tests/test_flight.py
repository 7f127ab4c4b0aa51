"""Flights: `groundfx sim` and `groundfx autopilot` as processes, in lockstep over MAVLink."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from mission.fly import autopilot_command, fly
from simbridge.launch import finish, start_sim
from tests.helpers import REPO, recorded_s, run_groundfx, wait_for

EXAMPLES = REPO / "mission" / "examples"


def autopilot(port: int, mission: str, *extra: str) -> subprocess.Popen[str]:
    """An autopilot process; with `--record PATH` among `extra` a test can wait until it flies
    (`recorded_s`), else it does not record."""
    record = () if "--record" in extra else ("--no-record",)
    return subprocess.Popen(
        autopilot_command(port, EXAMPLES / mission, *record, *extra),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def test_hover_at_one_metre_holds_within_a_centimetre(tmp_path):
    summary = fly(EXAMPLES / "hover.yaml", trajectory=tmp_path / "t.npz", record=False)
    assert summary["landed"]
    log = np.load(tmp_path / "t.npz")["log"]
    t, x, y, z, mode = log[:, 0], log[:, 1], log[:, 2], log[:, 3], log[:, 9]
    holding = np.flatnonzero(mode == 4)
    settled = holding[t[holding] >= t[holding[0]] + 3.0]  # after 3 s of the 10 s hold
    assert settled.size > 1000
    assert np.max(np.abs(z[settled] - 1.0)) < 0.01
    assert np.max(np.hypot(x[settled], y[settled])) < 0.01
    # the landing: fast high up, at MPC_LAND_SPEED (0.1 m/s) over the last 10 cm
    landing = np.flatnonzero(mode == 5)
    assert t[landing[-1]] - t[landing[0]] < 5.0
    near = landing[log[landing, 8] < 0.1]
    assert np.max(-log[near, 6]) < 0.13 and summary["touchdown_speed_m_s"] < 0.13


def test_holding_3_cm_over_rho_2_ground_analytic_holds_within_5_mm_and_lands_softly():
    # the reproducible path (ground-station flights: test_gcs.py); `none` against analytic
    # and neural on the same ground: tests/test_learner.py's closed-loop trials
    analytic = fly(
        EXAMPLES / "low_hover.yaml", world="rho2", model="analytic", via_gcs=False, record=False
    )
    assert analytic["landed"] and analytic["rho"] == 2.0
    # on its estimator and realistic sensors (1 mm motion capture): a 0.2 mm height error
    # is 5 mN of ground effect there, so the largest error is about twice the RMS
    assert analytic["hold_z_rms_error_m"] < 0.005 and analytic["hold_z_max_error_m"] < 0.012
    assert analytic["bounce_m"] < 0.001 and analytic["touchdown_speed_m_s"] < 0.2
    assert analytic["landing_error_m"] < 0.02


def test_landing_on_a_box_measures_the_ground_effect_to_the_box(tmp_path):
    summary = fly(
        EXAMPLES / "land_on_box.yaml",
        world="obstacles",
        trajectory=tmp_path / "t.npz",
        record=False,
    )
    assert summary["landed"] and summary["landing_error_m"] < 0.02
    assert summary["hold_z_rms_error_m"] < 0.005  # 3 cm above the box top
    log = np.load(tmp_path / "t.npz")["log"]
    assert log[-1, 3] == pytest.approx(0.1 + 0.0126, abs=0.002)  # resting on the box
    assert log[-1, 8] == pytest.approx(0.0126, abs=0.001)  # its height is measured to the box


def test_the_same_mission_twice_flies_the_same_trajectory():
    # without a ground station: arming at a fixed simulated time makes runs reproducible
    first = fly(EXAMPLES / "demo.yaml", world="rho2", via_gcs=False, record=False)
    second = fly(EXAMPLES / "demo.yaml", world="rho2", via_gcs=False, record=False)
    assert first["landed"] and first["steps"] == second["steps"]
    assert first["trajectory_sha256"] == second["trajectory_sha256"]


def test_fly_json_reports_the_figures():
    result = run_groundfx("fly", str(EXAMPLES / "low_hover.yaml"), "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout.strip().splitlines()[-1])
    for key in (
        "landing_error_m",
        "touchdown_speed_m_s",
        "sim_s",
        "wall_s",
        "rtf",
        "hold_z_rms_error_m",
        "ge_z_hold_rms_error_n",
        "ge_z_hold_true_n",
        "controller_us_p50",
    ):
        assert isinstance(summary[key], float), key
    # a figure, not a speed target (the benchmark commands measure speed): > 0 on any machine;
    # the flight lasted at least the mission's two holds (1 s and 6 s)
    assert summary["sim_s"] > 7 and summary["rtf"] > 0
    # the flight on one page beside its recording: the five answers, as the figures say
    png = Path(summary["report"])
    assert png.is_file() and png.stat().st_size > 20_000 and png.read_bytes()[:4] == b"\x89PNG"
    page = json.loads(png.with_name(png.name.replace(".png", ".json")).read_text())
    answers = page["answers"]
    assert list(answers) == ["landing", "hold", "model", "learner", "rotors"]
    assert answers["landing"]["landed"] and "landed" in answers["landing"]["text"]
    assert answers["hold"]["rms_mm"] == pytest.approx(summary["hold_z_rms_error_m"] * 1e3)
    assert " mN " in answers["model"]["text"]
    # the page's model error over the hold, from the recording, is the summary's
    assert answers["model"]["hold_rms_mn"] == pytest.approx(
        summary["ge_z_hold_rms_error_n"] * 1e3, rel=0.1
    )
    learner = answers["learner"]
    assert learner["method"] is None and "no online learning" in learner["text"]
    assert len(answers["rotors"]["rms_difference_rad_s"]) == 4
    # and for any recording, on demand: the same answers
    again = run_groundfx("review", summary["recording"], "--report")
    assert again.returncode == 0 and str(png) in again.stdout
    assert json.loads(png.with_name(png.name.replace(".png", ".json")).read_text()) == page
    # what is not a recording is refused with the reason
    from mission.cli.review import write_flight_report
    from simbridge.config import ConfigError

    with pytest.raises(ConfigError, match="not a rerun recording"):
        write_flight_report(png)


def test_fly_gives_the_autopilot_the_worlds_vehicle(tmp_path):
    """A world naming another vehicle flies it on both sides: the autopilot once took the nano
    for a Crazyflie's world and never finished a mission (mass, C_T and rotor speeds its
    own); its flight log named the nano."""
    import yaml

    from learner.flightlogs.readers import read_log

    world = tmp_path / "cf.yaml"
    world.write_text(
        yaml.safe_dump({"vehicle": "crazyflie2", "effects": [{"name": "ground_effect"}]})
    )
    summary = fly(EXAMPLES / "low_hover.yaml", world=str(world), via_gcs=False, record=False,
                  flight_log=tmp_path / "flight.csv")  # fmt: skip
    assert summary["landed"] and summary["landing_error_m"] < 0.02
    assert summary["hold_z_rms_error_m"] < 0.005
    log = read_log(tmp_path / "flight.csv")
    assert log.meta["vehicle"] == "crazyflie2"


def test_a_heavy_vehicle_with_slow_motors_flies_fast_legs_and_lands(tmp_path):
    """The 2.7 kg quadrotor with a 60 ms motor lag on 3 m/s diagonal legs: the attitude loop
    asks for more than the rotors give, and the mixer must give up yaw before roll and
    pitch. Clipping each rotor alone, it tumbled on its first leg and lay on the ground
    until the mission's time ran out."""
    import yaml

    world = tmp_path / "heavy.yaml"
    world.write_text(yaml.safe_dump({
        "vehicle": "quad_2_7kg",
        "effects": [{"name": "ground_effect"}, {"name": "motor_lag", "time_constant_s": 0.06}],
    }))  # fmt: skip
    mission = tmp_path / "legs.yaml"
    leg = {"acceptance_radius_m": 0.6, "hold_s": 0.0, "speed_m_s": 3.0}
    mission.write_text(yaml.safe_dump({
        "takeoff_altitude_m": 0.3,
        "land": True,
        "waypoints": [
            {**leg, "position_m": [1.86, 1.87, 0.64]},
            {**leg, "position_m": [-2.12, -0.91, 0.48]},
            {"position_m": [0.0, 0.0, 0.5], "acceptance_radius_m": 0.15},
        ],
    }))  # fmt: skip
    summary = fly(mission, world=str(world), via_gcs=False, record=False, max_flight_s=40.0)
    assert summary["landed"] and summary["landing_error_m"] < 0.05


def test_a_heavy_vehicle_caught_on_the_ground_by_a_corner_settles_and_lands(tmp_path):
    """The 2.7 kg quadrotor in a 2 m/s wind with its thrust axis leaning 1.8 deg flies a
    mission made for the nano (the gap bench's aggressive one, before its heights followed
    the vehicle), whose last hold (4 cm) lies below its resting height (10 cm): dragged on
    the ground, it tips onto a corner. The mixer raised the collective
    to keep the bottom rotor above zero for the levelling moment, and the vehicle hovered
    pinned, 10 deg tilted, 15 cm above its landing setpoint until the mission's time ran
    out; with the collective never raised (PX4's airmode off) it settles and lands."""
    import yaml

    from mission.campaigns.gap_flights import bench_mission

    world = tmp_path / "caught.yaml"
    world.write_text(yaml.safe_dump({
        "vehicle": "quad_2_7kg",
        "effects": [
            {"name": "ground_effect"}, {"name": "rotor_drag"},
            {"name": "thrust_tilt", "lean_deg": [-1.5, 1.0]},
            {"name": "wind", "mean_m_s": [2.0, 0.0, 0.0]},
        ],
    }))  # fmt: skip
    mission = tmp_path / "aggressive.yaml"
    mission.write_text(yaml.safe_dump(bench_mission("aggressive", 1)))
    params = ("MPC_Z_V_AUTO_UP=1.0", "MPC_Z_V_AUTO_DN=1.0")
    summary = fly(mission, world=str(world), via_gcs=False, record=False, max_flight_s=40.0,
                  autopilot_options=[a for p in params for a in ("--param", p)],
                  sim_options=["--ideal-sensors"])  # fmt: skip
    assert summary["landed"], summary["ended"]


def test_a_killed_simulator_ends_the_autopilot_within_a_second_with_its_log(tmp_path):
    sim, port = start_sim("default", speedup="1")
    trajectory = tmp_path / "t.npz"
    rrd = tmp_path / "flight.rrd"
    ap = autopilot(port, "hover.yaml", "--trajectory", str(trajectory), "--record", str(rrd))
    wait_for(lambda: recorded_s(rrd) >= 1.5, "flying for 1.5 s", ap)
    sim.send_signal(signal.SIGKILL)
    t0 = time.monotonic()
    _, err = ap.communicate(timeout=10)
    # it notices at once, not after the link's 10 s timeout (the margin is for a busy machine)
    assert time.monotonic() - t0 < 5.0
    sim.communicate()
    assert ap.returncode == 3 and "lost the simulator link" in err
    log = np.load(trajectory)["log"]
    assert log[-1, 0] > 1.5 and np.max(log[:, 3]) > 0.1  # it flew until the kill


def test_a_killed_autopilot_ends_the_simulator_cleanly(tmp_path):
    sim, port = start_sim("default", speedup="1")
    rrd = tmp_path / "flight.rrd"
    ap = autopilot(port, "hover.yaml", "--record", str(rrd))
    wait_for(lambda: recorded_s(rrd) > 0.5, "flying", ap)
    ap.send_signal(signal.SIGKILL)
    ap.communicate()
    line = finish(sim)
    assert sim.returncode == 0 and "autopilot disconnected" in line


def test_with_wait_the_simulator_takes_the_next_autopilot_in_a_fresh_world(tmp_path):
    sim, port = start_sim("default", speedup="max", extra=["--wait"])
    try:
        rrd = tmp_path / "first.rrd"
        first = autopilot(port, "hover.yaml", "--record", str(rrd))
        wait_for(lambda: first.poll() is not None or recorded_s(rrd) > 0.0, "connected")
        first.send_signal(signal.SIGKILL)  # in flight, or (on a fast machine) already landed
        first.communicate()
        second = autopilot(port, "low_hover.yaml", "--json")
        out, err = second.communicate(timeout=120)
        assert second.returncode == 0, err
        assert json.loads(out.strip().splitlines()[-1])["landed"]
    finally:
        sim.send_signal(signal.SIGTERM)
        out, _ = sim.communicate(timeout=10)
    ends = [ln for ln in out.splitlines() if "autopilot disconnected" in ln]
    assert len(ends) == 2 and sim.returncode == 0


class GarbageProxy:
    """A TCP relay between autopilot and simulator that slips garbage into the sensor stream."""

    def __init__(self, sim_port: int) -> None:
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port = self.listener.getsockname()[1]
        self.sim_port = sim_port
        self.injected = 0
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        client, _ = self.listener.accept()
        upstream = socket.create_connection(("127.0.0.1", self.sim_port))
        for s in (client, upstream):
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        threading.Thread(target=self._pipe, args=(client, upstream, False), daemon=True).start()
        self._pipe(upstream, client, True)

    def _pipe(self, src: socket.socket, dst: socket.socket, dirty: bool) -> None:
        chunks = 0
        try:
            while data := src.recv(65536):
                chunks += 1
                if dirty and chunks % 50 == 0:
                    dst.sendall(b"\x00\x13 line noise \xfd\x05\x00")  # noise, then a broken frame
                    self.injected += 1
                dst.sendall(data)
        except OSError:
            pass
        finally:
            dst.close()


def test_garbage_on_the_link_is_counted_and_the_flight_goes_on():
    sim, port = start_sim("default", speedup="max")
    proxy = GarbageProxy(port)
    ap = autopilot(proxy.port, "low_hover.yaml", "--json")
    out, err = ap.communicate(timeout=120)
    finish(sim)
    assert ap.returncode == 0, err
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["landed"] and proxy.injected > 50
    assert summary["malformed"] >= proxy.injected


def test_bench_sitl_prints_its_figures():
    result = run_groundfx("bench", "sitl", "--json", "--repeat", "1")
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout.strip().splitlines()[-1])
    # figures, not speed targets: a busy machine may run the lockstep slower than real time
    assert figures["rtf"] > 0 and 0 < figures["controller_us_p50"] <= figures["controller_us_p99"]
    assert figures["rtf_recording_off"] > 0 and figures["rtf_recording_on"] > 0
    assert figures["recording_bytes"] > 100_000


def test_a_bad_mission_is_refused_with_a_message(tmp_path: Path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("waypoints:\n  - {position_m: [0, 0], hold_s: 1}\n")
    result = run_groundfx("fly", str(bad))
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "waypoints[0].position_m: expected a list of 3 values" in result.stderr
