"""A slow simulator is waited for, a gone one ends the flight at once and says so: real
processes (`groundfx sim`, `groundfx autopilot`, a pymavlink ground station), the simulator
stopped with SIGSTOP mid-hover or killed with SIGKILL."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from autopilot.commander.mission_items import Home
from learner.flightlogs.recording import SUMMARY, read_recording
from mission.fly import fly, gcs_autopilot_command
from mission.gcs_client import GroundStation
from mission.plans.formats import load_mission_file
from simbridge.config import ConfigError
from simbridge.launch import finish, start_sim
from simbridge.world import load_world
from tests.helpers import recorded_s, stop_process

WORLD_ORIGIN = load_world("default").origin
ORIGIN = Home(WORLD_ORIGIN.lat_deg, WORLD_ORIGIN.lon_deg, WORLD_ORIGIN.alt_m)
HOVER = """\
name: chaos_hover
takeoff_altitude_m: 0.5
waypoints:
  - {position_m: [0.0, 0.0, 0.5], hold_s: 6.0}
land: true
"""
STOPPED_S = 3.0  # how long the simulator is frozen: longer than a loaded machine stalls it
IN_AIR = mav.MAV_LANDED_STATE_IN_AIR
LANDING = mav.MAV_LANDED_STATE_LANDING


@contextlib.contextmanager
def flight(
    tmp_path: Path,
) -> Iterator[tuple[GroundStation, subprocess.Popen[str], subprocess.Popen[str], Path]]:
    """A simulator at twice real time and an autopilot recording to a file, reporting to a
    pymavlink ground station that has uploaded the hover mission, armed and started it."""
    mission = tmp_path / "hover.yaml"
    mission.write_text(HOVER)
    recording = tmp_path / "flight.rrd"
    station = GroundStation("udpin:127.0.0.1:0")
    sim, port = start_sim("default", speedup="2")
    gcs_port = station.conn.port.getsockname()[1]
    command = gcs_autopilot_command(port, gcs_port, "--json", f"--record={recording}")
    autopilot = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    station.vehicle_alive = lambda: autopilot.poll() is None
    try:
        station.connect(timeout_s=20.0)
        station.upload(load_mission_file(mission, ORIGIN).items)
        station.wait_armable()
        station.require(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, what="arming")
        station.require(mav.MAV_CMD_MISSION_START, 0, 0, what="mission start")
        yield station, sim, autopilot, recording
    finally:
        with contextlib.suppress(ProcessLookupError):
            sim.send_signal(signal.SIGCONT)
        try:
            stop_process(autopilot, timeout_s=30)
        finally:  # nothing this test started outlives it
            finish(sim)
            station.close()


def hovering(station: GroundStation) -> None:
    """Until the vehicle is in the air and has reached its hover waypoint."""
    p = station.progress
    station.wait_for(
        "the hover", lambda m: p.landed_state == IN_AIR and 1 in p.reached, timeout_s=60.0
    )


def test_a_simulator_stopped_mid_hover_is_waited_for_and_the_flight_lands(tmp_path):
    with flight(tmp_path) as (station, sim, autopilot, recording):
        hovering(station)
        sim.send_signal(signal.SIGSTOP)
        stopped_at = time.monotonic()
        resume_at = stopped_at + STOPPED_S
        heartbeats = []
        while time.monotonic() < resume_at:  # the station stays heard meanwhile
            m = station.receive(resume_at - time.monotonic())
            if m is not None and m.get_type() == "HEARTBEAT" and m.get_srcComponent() == 1:
                heartbeats.append(time.monotonic() - stopped_at)
        # and the vehicle is heard too: its heartbeats go on while its loop waits
        assert len(heartbeats) >= 2 and heartbeats[-1] > STOPPED_S - 1.5, heartbeats
        # it was stopped in the air: hovering, or already landing on a slow machine
        assert station.progress.landed_state in (IN_AIR, LANDING)
        sim.send_signal(signal.SIGCONT)
        p = station.progress
        station.wait_for("disarm after landing", lambda m: not p.armed, timeout_s=120.0)
        out, err = autopilot.communicate(timeout=60)
    assert autopilot.returncode == 0, err
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["ended"] == "landed" and summary["landed"]
    assert not any("lost the simulator link" in text for text in station.progress.texts)
    assert read_recording(recording).complete


def test_an_autopilot_waiting_for_a_stopped_simulator_stops_when_asked(tmp_path):
    """Ctrl-C (SIGINT) or SIGTERM is heard while a frozen simulator is waited for: the flight
    ends as stopped, not after the link's silence limit."""
    with flight(tmp_path) as (station, sim, autopilot, recording):
        hovering(station)
        sim.send_signal(signal.SIGSTOP)
        autopilot.terminate()
        out, err = autopilot.communicate(timeout=20)  # a bound, far below the link timeout
    assert autopilot.returncode == 0, err
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["ended"] == "stopped"
    assert read_recording(recording).complete


def test_a_killed_simulator_ends_the_flight_at_once_saying_why(tmp_path):
    closed = "lost the simulator link: it closed the connection"
    with flight(tmp_path) as (station, sim, autopilot, recording):
        hovering(station)
        sim.kill()
        # told to the ground station before the autopilot closes its link to it
        station.wait_for("the reason", lambda m: closed in station.progress.texts, timeout_s=20.0)
        out, err = autopilot.communicate(timeout=20)  # a bound, far below the link timeout
    assert autopilot.returncode == 3
    assert closed in err
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["ended"] == closed and not summary["landed"]
    rec = read_recording(recording)
    assert rec.complete
    assert json.loads(rec.static(SUMMARY, "TextDocument:text"))["ended"] == closed
    assert any(closed in text for _, _, text in rec.texts())
    assert len(rec.trajectory()) > 0


def test_a_simulator_that_fails_at_start_ends_fly_with_its_reason(tmp_path):
    """The autopilot, started beside it, would retry its connection; the launcher saw the
    simulator exit and says why."""
    mission = tmp_path / "hover.yaml"
    mission.write_text(HOVER)
    with pytest.raises(ConfigError, match=r"groundfx sim exited with code 2: .*--sensor-seed"):
        fly(mission, via_gcs=False, record=False, sim_options=["--sensor-seed=-1"])


def simulators_started_by_this_test() -> list[int]:
    """The `groundfx sim` processes this process started (Linux's /proc): among its children,
    and its zygote's (`simbridge/zygote.py`: a forked child takes its command as its title)."""
    found = []
    for child in _children(os.getpid()):
        for pid in (child, *_children(child)):
            with contextlib.suppress(OSError):
                argv = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").split()
                if b"sim" in argv and b"autopilot" not in argv:
                    found.append(pid)
    return found


def _children(pid: int) -> list[int]:
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def test_a_campaign_flight_whose_simulator_dies_is_flown_again_to_the_same_trajectory(tmp_path):
    """`fly` (every campaign's flight: gather, trials, replays, online evaluation) flies a lost
    link again once; lockstep makes the second flight the one an undisturbed run flies."""
    mission = tmp_path / "hover.yaml"
    mission.write_text(HOVER)
    recording = tmp_path / "first.rrd"
    killed: list[int] = []

    def kill_the_first_simulator_in_flight() -> None:
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline and recorded_s(recording) < 1.0:
            time.sleep(0.05)
        for pid in simulators_started_by_this_test()[:1]:
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    said: list[str] = []
    killer = threading.Thread(target=kill_the_first_simulator_in_flight, daemon=True)
    killer.start()
    summary = fly(mission, via_gcs=False, record=recording, speedup="2", say=said.append)
    killer.join(timeout=5)
    assert killed, "the simulator was never seen in flight"
    assert any(text.startswith("lost the simulator link") for text in said), said
    assert summary["landed"], summary
    undisturbed = fly(mission, via_gcs=False, record=False)
    assert summary["trajectory_sha256"] == undisturbed["trajectory_sha256"]
