"""Acceptance with the real ground-station clients, as processes over loopback UDP.

MAVSDK (`mavsdk` 4.1, the native binding, asyncio API) and MAVProxy 1.8.75 (headless, fed
commands on standard input) each fly the square mission (mission/examples/square.*: take off
to 1 m, four waypoints at 0.5 then 1 m/s, land at home) on `groundfx sim` and `groundfx
autopilot`, under the PX4 and the ArduCopter identity. Every wait is bounded and says what it
waited for. Ports are ephemeral, never 14540/14550, which a user's ground station may hold.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import os
import queue
import re
import socket
import subprocess
import sys
import threading
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

os.environ.setdefault("MAVLINK20", "1")
from mavsdk.asyncio import Autopilot, ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.mission import MissionAsync, MissionItem, MissionPlan
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
from mavsdk.asyncio.plugins.param import ParamAsync
from mavsdk.asyncio.plugins.telemetry import LandedState, TelemetryAsync
from pymavlink import mavutil

from autopilot.mission_items import DO_CHANGE_SPEED, NAV_LAND, NAV_TAKEOFF, NAV_WAYPOINT
from mission.formats import load_mission_file
from simbridge.frames import geodetic_to_local
from simbridge.launch import start_sim
from tests.helpers import REPO

EXAMPLES = REPO / "mission" / "examples"
IDENTITIES = ("px4", "ardupilot")
# Ten times real time: a flight takes 5-7 s wall. As fast as it can (10-25 times here) both
# clients fly it too, in 3-6 s, but the simulator and the autopilot then take both cores,
# from the client and from whatever else runs.
SPEEDUP = "10"
LANDING_ACCEPTANCE_M = 0.02  # NAV_ACC_RAD, set by each client: where the descent begins
LANDED_WITHIN_M = 0.03
FLIGHT_WALL_S = 60.0  # the square takes about 40 s simulated: 4 s wall at speedup 10


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
def vehicle() -> Iterator[Callable[[str, str], Vehicle]]:
    """Start `groundfx sim` and `groundfx autopilot --identity ID --out URL`; both are ended
    (terminated, then killed if need be) at teardown."""
    started: list[subprocess.Popen[str]] = []

    def start(identity: str, out_url: str) -> Vehicle:
        sim, port = start_sim("default", speedup=SPEEDUP)
        started.append(sim)
        command = [
            sys.executable, "-m", "mission.cli", "autopilot",
            "--sim", f"tcp:127.0.0.1:{port}", "--identity", identity, "--params-file", "none",
            "--out", out_url, "--exit-after-landing", "--json",
        ]  # fmt: skip
        autopilot = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO
        )
        started.append(autopilot)
        return Vehicle(sim, autopilot)

    yield start
    for proc in reversed(started):  # the autopilot first: the simulator then ends cleanly
        if proc.poll() is None:
            proc.terminate()
        try:
            proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()


def square_items() -> tuple[Any, ...]:
    return load_mission_file(EXAMPLES / "square.plan").items


def distance_m(lat: float, lon: float, to_lat: float, to_lon: float) -> float:
    east, north = geodetic_to_local(to_lat, to_lon, lat, lon)
    return math.hypot(east, north)


# --- MAVSDK ---------------------------------------------------------------------------------


async def within(what: str, timeout_s: float, awaitable: Any) -> Any:
    try:
        return await asyncio.wait_for(awaitable, timeout_s)
    except TimeoutError:
        raise AssertionError(f"MAVSDK: {what}: nothing within {timeout_s:g} s") from None


async def eventually(what: str, timeout_s: float, ask: Callable[[], Awaitable[bool]]) -> None:
    """Ask until true. MAVSDK hands a callback over before it has taken in every message
    that came with it: its mission progress can reach the end while is_mission_finished()
    still says no (about one run in fifteen on a loaded machine)."""
    end = time.monotonic() + timeout_s
    while not await within(what, timeout_s, ask()):
        if time.monotonic() > end:
            raise AssertionError(f"MAVSDK: {what}: still not so after {timeout_s:g} s")
        await asyncio.sleep(0.05)


async def first(
    what: str, timeout_s: float, stream: AsyncIterator[Any], ok: Callable[[Any], bool]
) -> tuple[Any, list[Any]]:
    """The first value of a MAVSDK subscription that is `ok`, and every value seen."""
    seen: list[Any] = []

    async def scan() -> Any:
        async with contextlib.aclosing(stream) as values:
            async for value in values:
                seen.append(value)
                if ok(value):
                    return value
        raise AssertionError(f"MAVSDK: {what}: the subscription ended")

    try:
        return await asyncio.wait_for(scan(), timeout_s), seen
    except TimeoutError:
        raise AssertionError(
            f"MAVSDK: {what}: not within {timeout_s:g} s; last seen {seen[-3:]}"
        ) from None


def mavsdk_square(home_lat: float, home_lon: float, identity: str) -> list[MissionItem]:
    """square.plan as MAVSDK mission items: its four waypoints and a landing item (MAVSDK
    puts a waypoint before the NAV_LAND). A MAVSDK item's speed is the speed after it, a
    DO_CHANGE_SPEED behind its waypoint; in the plan the change comes before the waypoint
    it is for. Under the ArduCopter identity item 0 is home, which MAVSDK's mission plugin
    does not add: the station puts it there."""
    places, speeds, speed = [], [], None
    for item in square_items():
        if item.command == DO_CHANGE_SPEED:
            speed = item.param2
        elif item.command in (NAV_WAYPOINT, NAV_LAND):
            places.append(item)
            speeds.append(speed)  # the speed flown to it
    items = []
    if identity == "ardupilot":
        items.append(
            MissionItem(
                latitude_deg=home_lat,
                longitude_deg=home_lon,
                relative_altitude_m=0.0,
                speed_m_s=speeds[0],
                is_fly_through=True,
                yaw_deg=math.nan,
            )
        )
    for i, item in enumerate(places):
        land = item.command == NAV_LAND
        items.append(
            MissionItem(
                latitude_deg=item.x * 1e-7,
                longitude_deg=item.y * 1e-7,
                relative_altitude_m=places[i - 1].z if land else item.z,
                speed_m_s=speeds[min(i + 1, len(places) - 1)],
                is_fly_through=False,
                acceptance_radius_m=LANDING_ACCEPTANCE_M if land else item.param2,
                yaw_deg=math.nan,
                vehicle_action=MissionItem.VehicleAction.LAND if land else None,
            )
        )
    return items


@dataclass
class Client:
    """One MAVSDK connection's plugins, one instance each."""

    telemetry: TelemetryAsync
    action: ActionAsync
    mission: MissionAsync
    raw: MissionRawAsync
    param: ParamAsync

    def destroy(self) -> None:
        """Before the Mavsdk instance goes. Left to garbage collection, a plugin can be
        destroyed in an executor thread while Mavsdk is destroyed: mavsdk 4.1 aborts."""
        for plugin in (self.telemetry, self.action, self.mission, self.raw, self.param):
            plugin.destroy()


async def with_mavsdk(
    port: int, identity: str, fly: Callable[[Client], Awaitable[dict[str, Any]]]
) -> dict[str, Any]:
    """Connect MAVSDK to the autopilot, wait until it is healthy, set NAV_ACC_RAD, then
    `fly`."""
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as sdk:
        await within("connect", 5, sdk.add_any_connection(f"udpout://127.0.0.1:{port}"))
        system = await within("discovery", 15, sdk.first_autopilot(timeout_s=10.0))
        assert system is not None, "MAVSDK found no autopilot within 10 s"
        expected = Autopilot.PX4 if identity == "px4" else Autopilot.ARDUPILOT
        assert await system.autopilot_type() == expected
        client = Client(
            TelemetryAsync(system),
            ActionAsync(system),
            MissionAsync(system),
            MissionRawAsync(system),
            ParamAsync(system),
        )
        try:
            await first(
                "health: global position, home, armable",
                15,
                client.telemetry.subscribe_health(),
                lambda h: h.is_global_position_ok and h.is_home_position_ok and h.is_armable,
            )
            await within(
                "set NAV_ACC_RAD",
                5,
                client.param.set_param_float("NAV_ACC_RAD", LANDING_ACCEPTANCE_M),
            )
            return await fly(client)
        finally:
            client.destroy()


def after(before: Callable[[Any], bool], then: Callable[[Any], bool]) -> Callable[[Any], bool]:
    """A test true of the first value that is `then` after one that was `before`."""
    seen = []

    def ok(value: Any) -> bool:
        if before(value):
            seen.append(value)
        return bool(seen) and then(value)

    return ok


def is_flying(state: LandedState) -> bool:
    return state in (LandedState.TAKING_OFF, LandedState.IN_AIR, LandedState.LANDING)


def is_on_ground(state: LandedState) -> bool:
    return state == LandedState.ON_GROUND


async def follow_to_the_ground(
    client: Client, total: int, progress_stream: AsyncIterator[Any], start: Awaitable[None]
) -> dict[str, Any]:
    """Start the mission and follow it to its end, the landing and the disarm."""
    telemetry = client.telemetry
    # Subscribed before the start: the autopilot ends soon after the landing, and a
    # subscription only hears what comes after it.
    following, landing, disarming = (
        asyncio.create_task(first(what, FLIGHT_WALL_S, stream, ok))
        for what, stream, ok in (
            (
                "mission progress to the end",
                progress_stream,
                lambda p: p.total == total and p.current == p.total,
            ),
            ("landed", telemetry.subscribe_landed_state(), after(is_flying, is_on_ground)),
            ("disarmed", telemetry.subscribe_armed(), after(bool, lambda armed: not armed)),
        )
    )
    try:
        await asyncio.sleep(0)  # the tasks subscribe before the mission starts
        await within("start the mission", 5, start)
        _, progress = await following
        _, landed_states = await landing
        await disarming
    finally:  # on a failure, stop watching before the plugins go
        for task in (following, landing, disarming):
            task.cancel()
        await asyncio.gather(following, landing, disarming, return_exceptions=True)
    assert LandedState.IN_AIR in landed_states, landed_states
    assert landed_states[-1] == LandedState.ON_GROUND
    return {
        "progress": [p.current for p in progress if p.total == total],
        "position": await within("position", 5, telemetry.position()),
    }


def check_landing(result: dict[str, Any], lat_deg: float, lon_deg: float) -> None:
    position = result["position"]
    assert position.relative_altitude_m == pytest.approx(0.0, abs=0.02)
    error = distance_m(position.latitude_deg, position.longitude_deg, lat_deg, lon_deg)
    assert error < LANDED_WITHIN_M, f"landed {error * 100:.1f} cm from the landing point"


async def fly_plugin_mission(client: Client, identity: str) -> dict[str, Any]:
    """The mission plugin: upload, download, arm, take off (an action), fly, land."""
    telemetry, action, mission = client.telemetry, client.action, client.mission
    home, _ = await first(
        "home position", 5, telemetry.subscribe_home(), lambda h: math.isfinite(h.latitude_deg)
    )
    items = mavsdk_square(home.latitude_deg, home.longitude_deg, identity)
    await within("mission upload", 10, mission.set_return_to_launch_after_mission(False))
    await within("mission upload", 10, mission.upload_mission(MissionPlan(items)))
    downloaded = await within("mission download", 10, mission.download_mission())

    def places(items: list[MissionItem]) -> list[tuple[int, int, int]]:
        return [
            (round(i.latitude_deg * 1e7), round(i.longitude_deg * 1e7), i.vehicle_action)
            for i in items
        ]

    assert places(downloaded.mission_items) == places(items)

    takeoff = next(i for i in square_items() if i.command == NAV_TAKEOFF)
    await within("set the take-off altitude", 5, action.set_takeoff_altitude(takeoff.z))
    await within("arm", 5, action.arm())
    await within("take off", 5, action.takeoff())
    await first(
        f"climb to {takeoff.z:g} m",
        30,
        telemetry.subscribe_position(),
        lambda p: p.relative_altitude_m > takeoff.z - 0.05,
    )
    result = await follow_to_the_ground(
        client, len(items), mission.subscribe_mission_progress(), mission.start_mission()
    )
    await eventually("mission finished", 5, mission.is_mission_finished)
    return dict(result, items=items)


@pytest.mark.parametrize("identity", IDENTITIES)
def test_mavsdk_uploads_the_square_takes_off_flies_it_lands_and_sees_the_disarm(vehicle, identity):
    port = free_udp_port()
    flight = vehicle(identity, f"udpin:127.0.0.1:{port}")
    t0 = time.monotonic()
    result = asyncio.run(with_mavsdk(port, identity, lambda s: fly_plugin_mission(s, identity)))
    wall = time.monotonic() - t0

    items, progress = result["items"], result["progress"]
    first_flown = 1 if identity == "ardupilot" else 0  # ArduCopter's item 0 is home
    assert set(range(first_flown, len(items) + 1)) <= set(progress), progress
    assert progress == sorted(progress), f"progress went backwards: {progress}"
    check_landing(result, items[-1].latitude_deg, items[-1].longitude_deg)
    summary = flight.summary()
    assert summary["landed"] and summary["landing_error_m"] < LANDED_WITHIN_M, summary
    print(f"MAVSDK mission {identity}: {wall:.1f} s wall, {summary['sim_s']:.1f} s simulated")


def raw_fields(item: Any) -> tuple[Any, ...]:
    """A raw item's content, NaN made comparable."""
    values = (item.command, item.frame, item.param1, item.param2, item.param3, item.param4)
    return (*(-999.0 if v != v else v for v in values), item.x, item.y, item.z)


async def fly_raw_plan(client: Client) -> dict[str, Any]:
    """mission_raw: MAVSDK's own import of square.plan (it adds the plan's home as item 0
    for ArduPilot), upload, download bit for bit, arm, start: the take-off is an item."""
    raw, action = client.raw, client.action
    imported = await within(
        "import square.plan", 5, raw.import_qgroundcontrol_mission(str(EXAMPLES / "square.plan"))
    )
    items = imported.mission_items
    await within("mission upload", 10, raw.upload_mission(items))
    downloaded = await within("mission download", 10, raw.download_mission())
    assert [raw_fields(i) for i in downloaded] == [raw_fields(i) for i in items]
    await within("arm", 5, action.arm())
    result = await follow_to_the_ground(
        client, len(items), raw.subscribe_mission_progress(), raw.start_mission()
    )
    await eventually("mission finished", 5, raw.is_mission_finished)
    return dict(result, items=items)


@pytest.mark.parametrize("identity", IDENTITIES)
def test_mavsdk_imports_square_plan_and_flies_it_as_raw_items(vehicle, identity):
    port = free_udp_port()
    flight = vehicle(identity, f"udpin:127.0.0.1:{port}")
    t0 = time.monotonic()
    result = asyncio.run(with_mavsdk(port, identity, fly_raw_plan))
    wall = time.monotonic() - t0

    items, progress = result["items"], result["progress"]
    plan = square_items()
    home_row = 1 if identity == "ardupilot" else 0
    assert len(items) == len(plan) + home_row
    assert [i.command for i in items[home_row:]] == [i.command for i in plan]
    assert set(range(home_row + 1, len(items) + 1)) <= set(progress), progress
    assert progress == sorted(progress), f"progress went backwards: {progress}"
    check_landing(result, items[-1].x * 1e-7, items[-1].y * 1e-7)
    summary = flight.summary()
    assert summary["landed"] and summary["landing_error_m"] < LANDED_WITHIN_M, summary
    print(f"MAVSDK raw {identity}: {wall:.1f} s wall, {summary['sim_s']:.1f} s simulated")


# --- MAVProxy -------------------------------------------------------------------------------


class MavProxy:
    """MAVProxy 1.8.75 as a process, its console on a pipe: commands in, lines out."""

    def __init__(self, master_port: int, forward_port: int, workdir: Path) -> None:
        command = [
            sys.executable, str(Path(sys.executable).parent / "mavproxy.py"),
            "--master", f"udpin:127.0.0.1:{master_port}",
            "--out", f"udpout:127.0.0.1:{forward_port}", "--no-state",
        ]  # fmt: skip
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        self.proc = subprocess.Popen(
            command,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env=env,
            cwd=workdir,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.transcript: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.rstrip())

    def send(self, command: str) -> None:
        assert self.proc.stdin is not None
        self.transcript.append(f">>> {command}")
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()

    def expect(
        self, ok: Callable[[str], bool], what: str, timeout_s: float = 15.0, fail: bool = True
    ) -> str | None:
        """The first new console line that is `ok` (MAVProxy prefixes some with a prompt);
        None after `timeout_s` if not `fail`."""
        end = time.monotonic() + timeout_s
        while (left := end - time.monotonic()) > 0:
            try:
                line = self.lines.get(timeout=min(left, 0.2))
            except queue.Empty:
                if self.proc.poll() is not None:
                    break
                continue
            self.transcript.append(line)
            if ok(line.split("> ")[-1].strip()):
                return line
        if not fail:
            return None
        tail = "\n".join(self.transcript[-25:])
        raise AssertionError(f"MAVProxy: no {what} within {timeout_s:g} s; console:\n{tail}")

    def ask_until(
        self, command: str, ok: Callable[[str], bool], what: str, timeout_s: float = 10.0
    ) -> str:
        """Send `command` every half second until a line answering it is `ok`."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            self.send(command)
            line = self.expect(ok, what, 0.5, fail=False)
            if line is not None:
                return line
        tail = "\n".join(self.transcript[-25:])
        raise AssertionError(f"MAVProxy: no {what} within {timeout_s:g} s; console:\n{tail}")

    def close(self) -> None:
        """End of input ends MAVProxy's console and MAVProxy."""
        with contextlib.suppress(OSError):
            assert self.proc.stdin is not None
            self.proc.stdin.close()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


class Listener:
    """What MAVProxy forwards on its `--out`: the items reached, as MAVProxy saw them."""

    def __init__(self) -> None:
        self.link = mavutil.mavlink_connection("udpin:127.0.0.1:0")
        self.port = self.link.port.getsockname()[1]
        self.reached: list[int] = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.stop.is_set():
            m = self.link.recv_match(type="MISSION_ITEM_REACHED", blocking=True, timeout=0.2)
            if m is not None:
                self.reached.append(m.seq)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=5)
        self.link.close()


@pytest.mark.parametrize("identity", IDENTITIES)
def test_mavproxy_loads_the_wpl_file_arms_starts_it_and_sees_every_item_reached(
    vehicle, identity, tmp_path
):
    master_port = free_udp_port()
    listener = Listener()
    flight = vehicle(identity, f"udpout:127.0.0.1:{master_port}")
    mavproxy = MavProxy(master_port, listener.port, tmp_path)
    t0 = time.monotonic()
    try:
        mavproxy.expect(lambda s: s.startswith("Detected vehicle 1:1"), "vehicle detected")
        mavproxy.expect(lambda s: re.fullmatch(r"Received \d+ parameters", s), "parameters")
        mavproxy.send(f"param set NAV_ACC_RAD {LANDING_ACCEPTANCE_M}")
        mavproxy.ask_until(  # the set is queued: its PARAM_VALUE reply updates the cache
            "param show NAV_ACC_RAD",
            lambda s: (
                s.split()[:1] == ["NAV_ACC_RAD"]
                and float(s.split()[1]) == pytest.approx(LANDING_ACCEPTANCE_M)
            ),
            f"NAV_ACC_RAD {LANDING_ACCEPTANCE_M} from the vehicle",
        )
        mavproxy.send(f"wp load {EXAMPLES / 'square.waypoints'}")
        mavproxy.expect(lambda s: s == "Sent all 9 waypoints", "mission sent")
        mavproxy.expect(lambda s: s == "Got MISSION_ACK: TYPE_MISSION: ACCEPTED", "mission ack")
        mavproxy.send("arm throttle")
        mavproxy.expect(lambda s: s == "ARMED", "arming")
        if identity == "ardupilot":
            mavproxy.send("mode AUTO")
            mavproxy.expect(lambda s: s == "Mode AUTO", "AUTO mode")
        else:  # `mode AUTO` means nothing under PX4: AUTO.MISSION by number
            mavproxy.send("long DO_SET_MODE 1 4 4")
            mavproxy.expect(
                lambda s: s == "Got COMMAND_ACK: DO_SET_MODE: ACCEPTED", "mission mode ack"
            )
        mavproxy.expect(lambda s: s == "DISARMED", "disarm after landing", FLIGHT_WALL_S)
        wall = time.monotonic() - t0
        summary = flight.summary()
    finally:
        mavproxy.close()
        listener.close()
    # MAVProxy uploads the file's row 0, home, as item 0: ArduCopter keeps it as home; PX4
    # flies it, and it is reached on the ground, where the vehicle stands.
    expected = list(range(1 if identity == "ardupilot" else 0, 9))
    assert listener.reached == expected, "\n".join(mavproxy.transcript[-40:])
    assert summary["landed"] and summary["landing_error_m"] < LANDED_WITHIN_M, summary
    assert summary["mission_items"] == 9
    print(f"MAVProxy {identity}: {wall:.1f} s wall, {summary['sim_s']:.1f} s simulated")
