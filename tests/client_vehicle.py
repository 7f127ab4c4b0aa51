"""The vehicle the real ground-station clients fly (tests/test_mavsdk.py, test_mavproxy.py):
`groundfx sim` and `groundfx autopilot` as processes over loopback UDP.

Each client flies the square mission (mission/examples/square.*: take off to 1 m, four
waypoints at 0.5 then 1 m/s, land at home) under the PX4 and the ArduCopter identity. Every
wait is bounded and says what it waited for. Ports are ephemeral, never 14540/14550, which a
user's ground station may hold.
"""

from __future__ import annotations

import json
import math
import os
import socket
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from autopilot.commander.mission_items import Home
from autopilot.identity import IDENTITIES as BY_NAME
from mission.plans.formats import load_mission_file
from simbridge.frames import geodetic_to_local
from simbridge.launch import start_sim
from simbridge.world import load_world
from tests.helpers import REPO, stop_process

os.environ.setdefault("MAVLINK20", "1")


EXAMPLES = REPO / "mission" / "examples"
IDENTITIES = tuple(BY_NAME)  # as `--identity` names them
# Ten times real time: a flight takes 5-7 s wall. As fast as it can (10-25 times here) both
# clients fly it too, in 3-6 s, but the simulator and the autopilot then take both cores,
# from the client and from whatever else runs.
SPEEDUP = "10"
LANDING_ACCEPTANCE_M = 0.02  # NAV_ACC_RAD, set by each client: where the descent begins
LANDED_WITHIN_M = 0.03
FLIGHT_WALL_S = 60.0  # the square takes about 40 s simulated: 4 s wall at speedup 10
# The 8 m squares of the first-hour tests: each corner's acceptance radius, the mission's own
# speed (DO_CHANGE_SPEED, to keep it short: 55 s simulated), the speed-up they fly at
SQUARE_ACCEPTANCE_M = 0.3
SQUARE_SPEED_M_S = 1.0
SQUARE_SPEEDUP = "20"


def origin_home() -> Home:
    """The default world's origin, where the vehicle starts: home."""
    o = load_world("default").origin
    return Home(o.lat_deg, o.lon_deg, o.alt_m)


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class Vehicle:
    sim: subprocess.Popen[str]
    autopilot: subprocess.Popen[str]

    def summary(self, timeout_s: float = 20.0) -> dict[str, Any]:
        """The autopilot's JSON summary: it ends by itself once it has landed and settled."""
        try:
            out, err = self.autopilot.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.autopilot.kill()
            out, err = self.autopilot.communicate()
            pytest.fail(f"the autopilot did not end within {timeout_s} s of the landing: {err}")
        lines = out.strip().splitlines()
        assert self.autopilot.returncode == 0 and lines, f"autopilot failed: {err.strip()}"
        return json.loads(lines[-1])


@pytest.fixture
def vehicle() -> Iterator[Callable[..., Vehicle]]:
    """Start `groundfx sim` and `groundfx autopilot --identity ID --out URL [OPTIONS]`; both
    are ended (terminated, then killed if need be) at teardown. It records only where
    `--record PATH` is among the options."""
    started: list[subprocess.Popen[str]] = []

    def start(identity: str, out_url: str, *options: str, speedup: str = SPEEDUP) -> Vehicle:
        sim, port = start_sim("default", speedup=speedup)
        started.append(sim)
        command = [
            sys.executable, "-m", "mission.cli", "autopilot",
            "--sim", f"tcp:127.0.0.1:{port}", "--identity", identity, "--params-file", "none",
            "--out", out_url, "--exit-after-landing", "--json",
            *(() if "--record" in options else ("--no-record",)), *options,
        ]  # fmt: skip
        autopilot = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO
        )
        started.append(autopilot)
        return Vehicle(sim, autopilot)

    yield start
    for proc in reversed(started):  # the autopilot first: the simulator then ends cleanly
        stop_process(proc)


def square_items() -> tuple[Any, ...]:
    return load_mission_file(EXAMPLES / "square.plan").items


def square_8m(home: Home, altitude_m: float) -> list[tuple[float, float, float]]:
    """The issue's 8 m square (east, north, up of home; relative altitude): its far corner is
    11.3 m from home, beyond the 10 m fence the vehicle had by default. It starts away from
    home, so that under ArduPilot MAVSDK's first waypoint, sent as item 0, is not a home row."""
    return [
        (8.0, 0.0, altitude_m),
        (8.0, 8.0, altitude_m),
        (0.0, 8.0, altitude_m),
        (0.0, 0.0, altitude_m),
    ]


def closest_approach_m(recording: Path, origin: Home, home: Home, corners: list) -> list[float]:
    """How close the flown trajectory (the recording the autopilot wrote) came to each corner
    (east, north, up of `home`), in metres, 3-D."""
    from learner.flightlogs.recording import read_recording

    xyz = read_recording(recording).trajectory()[:, 1:4]
    home_east, home_north = geodetic_to_local(
        origin.lat_deg, origin.lon_deg, home.lat_deg, home.lon_deg
    )
    ground = home.alt_m - origin.alt_m
    out = []
    for east, north, up in corners:
        corner = np.array([home_east + east, home_north + north, ground + up])
        out.append(float(np.min(np.linalg.norm(xyz - corner, axis=1))))
    return out


def distance_m(lat: float, lon: float, to_lat: float, to_lon: float) -> float:
    east, north = geodetic_to_local(to_lat, to_lon, lat, lon)
    return math.hypot(east, north)


# --- MAVSDK ---------------------------------------------------------------------------------
