"""What a new MAVProxy user does in the first hour, with MAVProxy 1.8.75 over
loopback UDP against `groundfx autopilot` at its default parameters: an 8 m square from a WPL
file under both identities, every corner checked on the recording the autopilot wrote; guided
flight under ArduCopter (`mode GUIDED`, `takeoff`, `guided LAT LON ALT` both ways, `position`).
"""

from __future__ import annotations

import math
import re
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mav

from autopilot.commander.mission_items import DO_CHANGE_SPEED, NAV_LAND, NAV_TAKEOFF, NAV_WAYPOINT
from autopilot.identity import identity_named
from simbridge.frames import geodetic_to_local, local_to_geodetic
from tests.client_vehicle import (
    FLIGHT_WALL_S,
    SQUARE_ACCEPTANCE_M,
    SQUARE_SPEED_M_S,
    SQUARE_SPEEDUP,
    closest_approach_m,
    free_udp_port,
    origin_home,
    square_8m,
    vehicle,
)
from tests.test_mavproxy import MavProxy

__all__ = ["vehicle"]  # the fixture, used by name

HOME = origin_home()  # the vehicle starts at the origin
ACCEPTANCE_M = SQUARE_ACCEPTANCE_M  # MAVSDK's own default would be 1 m
SPEED_M_S = SQUARE_SPEED_M_S
FAST = SQUARE_SPEEDUP


class Watcher:
    """What MAVProxy forwards on its `--out`: the latest of each message, and every text."""

    def __init__(self) -> None:
        self.link = mavutil.mavlink_connection("udpin:127.0.0.1:0")
        self.port = self.link.port.getsockname()[1]
        self.latest: dict[str, Any] = {}
        self.texts: list[str] = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.stop.is_set():
            m = self.link.recv_match(blocking=True, timeout=0.2)
            if m is None or m.get_srcSystem() != 1:
                continue
            self.latest[m.get_type()] = m
            if m.get_type() == "STATUSTEXT":
                self.texts.append(m.text)

    def wait(self, what: str, ok: Any, timeout_s: float = 30.0) -> None:
        end = time.monotonic() + timeout_s
        while not ok():
            if time.monotonic() > end:
                raise AssertionError(f"not {what} within {timeout_s:g} s; texts {self.texts[-8:]}")
            time.sleep(0.05)

    def offset_m(self) -> tuple[float, float, float]:
        """East, north, up of home."""
        p = self.latest.get("GLOBAL_POSITION_INT")
        if p is None:
            return (math.inf, math.inf, math.inf)
        east, north = geodetic_to_local(HOME.lat_deg, HOME.lon_deg, p.lat * 1e-7, p.lon * 1e-7)
        return (east, north, p.relative_alt * 1e-3)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=5)
        self.link.close()


def write_wpl(path: Path, corners: list[tuple[float, float, float]]) -> int:
    """Home, take-off to the corners' altitude, a speed, the corners, land at home: a
    `QGC WPL 110` file as MAVProxy's `wp save` writes it. Returns the number of rows."""
    relative, msl, mission = (
        mav.MAV_FRAME_GLOBAL_RELATIVE_ALT,
        mav.MAV_FRAME_GLOBAL,
        mav.MAV_FRAME_MISSION,
    )
    rows = [(msl, NAV_WAYPOINT, 0.0, HOME.lat_deg, HOME.lon_deg, HOME.alt_m)]  # row 0: home
    rows.append((relative, NAV_TAKEOFF, 0.0, 0.0, 0.0, corners[0][2]))
    rows.append((mission, DO_CHANGE_SPEED, SPEED_M_S, 0.0, 0.0, 0.0))  # p2: the speed
    for east, north, up in corners:
        lat, lon = local_to_geodetic(HOME.lat_deg, HOME.lon_deg, east, north)
        rows.append((relative, NAV_WAYPOINT, ACCEPTANCE_M, lat, lon, up))
    rows.append((relative, NAV_LAND, 0.0, HOME.lat_deg, HOME.lon_deg, 0.0))
    lines = ["QGC WPL 110"]
    for k, (frame, command, radius, lat, lon, alt) in enumerate(rows):
        speed = (
            command == DO_CHANGE_SPEED
        )  # p1 1: ground speed, p2 the speed, p3 -1: throttle unchanged
        fields = (
            k,
            int(k == 0),
            frame,
            command,
            int(speed),
            radius,
            -1 if speed else 0,
            0,
            f"{lat:.8f}",
            f"{lon:.8f}",
            alt,
            1,
        )
        lines.append("\t".join(str(f) for f in fields))
    path.write_text("\n".join(lines) + "\n")
    return len(rows)


def started(identity: str, vehicle: Any, tmp_path: Path, *options: str) -> tuple:
    master = free_udp_port()
    watcher = Watcher()
    flight = vehicle(identity, f"udpout:127.0.0.1:{master}", *options, speedup=FAST)
    mavproxy = MavProxy(master, watcher.port, tmp_path)
    mavproxy.expect(lambda s: s.startswith("Detected vehicle 1:1"), "vehicle detected")
    mavproxy.expect(lambda s: re.fullmatch(r"Received \d+ parameters", s), "parameters")
    return flight, mavproxy, watcher


# under ArduCopter, the autopilot MAVProxy is made for; MAVSDK flies it under PX4
@pytest.mark.parametrize("identity", ["ardupilot"])
def test_mavproxy_flies_the_8_m_square_at_default_parameters_every_corner(
    vehicle, identity, tmp_path
):
    corners = square_8m(HOME, 1.0)
    rows = write_wpl(tmp_path / "square8.waypoints", corners)
    recording = tmp_path / "square8.rrd"
    flight, mavproxy, watcher = started(identity, vehicle, tmp_path, "--record", str(recording))
    t0 = time.monotonic()
    try:
        mavproxy.send(f"wp load {tmp_path / 'square8.waypoints'}")
        mavproxy.expect(lambda s: s == f"Sent all {rows} waypoints", "mission sent")
        mavproxy.expect(lambda s: s == "Got MISSION_ACK: TYPE_MISSION: ACCEPTED", "mission ack")
        upload_s = time.monotonic() - t0
        mavproxy.send("arm throttle")
        mavproxy.expect(lambda s: s == "ARMED", "arming")
        if identity_named(identity).autopilot == mav.MAV_AUTOPILOT_ARDUPILOTMEGA:
            mavproxy.send("mode AUTO")
        else:
            mavproxy.send("long DO_SET_MODE 1 4 4")
        mavproxy.expect(lambda s: s == "DISARMED", "disarm after landing", FLIGHT_WALL_S)
        wall = time.monotonic() - t0
        summary = flight.summary()
    finally:
        mavproxy.close()
        watcher.close()
    assert summary["landed"], summary
    approach = closest_approach_m(recording, HOME, HOME, corners)
    assert max(approach) < ACCEPTANCE_M, f"closest to each corner: {approach}"
    print(
        f"MAVProxy 8 m square {identity}: upload {1e3 * upload_s:.0f} ms, {wall:.1f} s wall, "
        f"{summary['sim_s']:.1f} s simulated, corners within {[round(a, 3) for a in approach]} m"
    )


def test_mavproxy_guided_under_arducopter(vehicle, tmp_path):
    flight, mavproxy, watcher = started("ardupilot", vehicle, tmp_path)
    guided = mavutil.mavlink.COPTER_MODE_GUIDED

    def mode() -> int:
        heartbeat = watcher.latest.get("HEARTBEAT")
        return -1 if heartbeat is None else heartbeat.custom_mode

    def near(east: float, north: float, up: float, within_m: float = 0.1) -> bool:
        e, n, u = watcher.offset_m()
        return math.dist((e, n, u), (east, north, up)) < within_m

    try:
        mavproxy.send("arm throttle")
        mavproxy.expect(lambda s: s == "ARMED", "arming")
        mavproxy.send("mode GUIDED")
        watcher.wait("GUIDED on the ground", lambda: mode() == guided)
        mavproxy.send("takeoff 1")
        watcher.wait("take-off done", lambda: any("take-off complete" in t for t in watcher.texts))
        assert mode() == guided, "a guided take-off stays in GUIDED, as ArduCopter"
        watcher.wait("at 1 m", lambda: near(0.0, 0.0, 1.0))
        lat, lon = local_to_geodetic(HOME.lat_deg, HOME.lon_deg, 1.5, 0.0)
        mavproxy.send(f"guided {lat:.8f} {lon:.8f} 1")  # DO_REPOSITION
        watcher.wait("at the guided target", lambda: near(1.5, 0.0, 1.0))
        mavproxy.send("mode LOITER")
        watcher.wait("LOITER", lambda: mode() == mavutil.mavlink.COPTER_MODE_LOITER)
        mavproxy.send("mode GUIDED")  # while hovering: the heartbeat says so
        watcher.wait("GUIDED while hovering", lambda: mode() == guided)
        mavproxy.send("set guided_use_reposition 0")  # the guided MISSION_ITEM, current = 2
        lat, lon = local_to_geodetic(HOME.lat_deg, HOME.lon_deg, 1.5, 1.0)
        mavproxy.send(f"guided {lat:.8f} {lon:.8f} 1.2")
        watcher.wait("at the guided item", lambda: near(1.5, 1.0, 1.2))
        before = watcher.offset_m()
        mavproxy.send("position 0.8 0 0")  # 0.8 m forward (body frame), once

        def there() -> bool:
            p = watcher.latest["GLOBAL_POSITION_INT"]
            moved = math.dist(watcher.offset_m(), before)
            return abs(moved - 0.8) < 0.05 and math.hypot(p.vx, p.vy) < 5  # cm/s: stopped

        watcher.wait("0.8 m forward and stopped there", there)
        assert mode() == guided
        mavproxy.send("mode LAND")
        mavproxy.expect(lambda s: s == "DISARMED", "disarm after landing", FLIGHT_WALL_S)
        summary = flight.summary()
    finally:
        mavproxy.close()
        watcher.close()
    assert summary["landed"], summary
