"""Acceptance with MAVSDK (`mavsdk` 4.1, the native binding, asyncio API) as a real client
over loopback UDP: it flies the square mission under both identities (tests/client_vehicle.py).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass
from typing import Any

import pytest
from mavsdk.asyncio import Autopilot, ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.mission import MissionAsync, MissionItem, MissionPlan
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync
from mavsdk.asyncio.plugins.param import ParamAsync
from mavsdk.asyncio.plugins.telemetry import LandedState, TelemetryAsync
from pymavlink.dialects.v20 import ardupilotmega as mav

from autopilot.commander.mission_items import DO_CHANGE_SPEED, NAV_LAND, NAV_TAKEOFF, NAV_WAYPOINT
from autopilot.identity import identity_named
from tests.client_vehicle import (
    EXAMPLES,
    FLIGHT_WALL_S,
    LANDED_WITHIN_M,
    LANDING_ACCEPTANCE_M,
    distance_m,
    free_udp_port,
    square_items,
    vehicle,
)

__all__ = ["vehicle"]  # the fixture, used by name


# MAVSDK's autopilot type for HEARTBEAT.autopilot
MAVSDK_AUTOPILOT = {
    mav.MAV_AUTOPILOT_PX4: Autopilot.PX4,
    mav.MAV_AUTOPILOT_ARDUPILOTMEGA: Autopilot.ARDUPILOT,
}


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
    if identity_named(identity).home_is_item_0:
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
    offboard: OffboardAsync

    def destroy(self) -> None:
        """Before the Mavsdk instance goes. Left to garbage collection, a plugin can be
        destroyed in an executor thread while Mavsdk is destroyed: mavsdk 4.1 aborts."""
        plugins = (self.telemetry, self.action, self.mission, self.raw, self.param, self.offboard)
        for plugin in plugins:
            plugin.destroy()


async def with_mavsdk(
    port: int,
    identity: str,
    fly: Callable[[Client], Awaitable[dict[str, Any]]],
    acceptance_m: float | None = LANDING_ACCEPTANCE_M,
) -> dict[str, Any]:
    """Connect MAVSDK to the autopilot, wait until it is healthy, set NAV_ACC_RAD (unless
    `acceptance_m` is None: the defaults), then `fly`."""
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as sdk:
        await within("connect", 5, sdk.add_any_connection(f"udpout://127.0.0.1:{port}"))
        system = await within("discovery", 15, sdk.first_autopilot(timeout_s=10.0))
        assert system is not None, "MAVSDK found no autopilot within 10 s"
        expected = MAVSDK_AUTOPILOT[identity_named(identity).autopilot]
        assert await system.autopilot_type() == expected
        client = Client(
            TelemetryAsync(system),
            ActionAsync(system),
            MissionAsync(system),
            MissionRawAsync(system),
            ParamAsync(system),
            OffboardAsync(system),
        )
        try:
            await first(
                "health: global position, home, armable",
                15,
                client.telemetry.subscribe_health(),
                lambda h: h.is_global_position_ok and h.is_home_position_ok and h.is_armable,
            )
            if acceptance_m is not None:
                await within(
                    "set NAV_ACC_RAD", 5, client.param.set_param_float("NAV_ACC_RAD", acceptance_m)
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


async def arm_as_soon_as_healthy(port: int) -> list[Any]:
    """Connect at once, wait for health as MAVSDK's examples do (global position and home
    OK), arm at that moment: what every health value said until then."""
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as sdk:
        await within("connect", 5, sdk.add_any_connection(f"udpout://127.0.0.1:{port}"))
        system = await within("discovery", 15, sdk.first_autopilot(timeout_s=10.0))
        assert system is not None, "MAVSDK found no autopilot within 10 s"
        telemetry, action = TelemetryAsync(system), ActionAsync(system)
        try:
            _, seen = await first(
                "health: global position and home",
                15,
                telemetry.subscribe_health(),
                lambda h: h.is_global_position_ok and h.is_home_position_ok,
            )
            await within("arm", 5, action.arm())  # raises if refused
            await within("disarm", 5, action.disarm())
            return seen
        finally:
            telemetry.destroy()
            action.destroy()


def test_mavsdk_health_says_ready_only_when_arming_is_accepted(vehicle):
    """Health (position, pre-arm) is what the pre-arm checks say: a client that arms the
    moment MAVSDK reports the position healthy is never refused."""
    port = free_udp_port()
    vehicle("px4", f"udpin:127.0.0.1:{port}")
    seen = asyncio.run(arm_as_soon_as_healthy(port))
    assert seen  # and arming was accepted: arm() raises on a refusal


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


# Each API under the autopilot its users fly it with: the mission plugin under PX4, the raw
# items (which carry ArduPilot's home as item 0) under ArduPilot: MAVSDK flies a mission
# under both identities, each flight once.
@pytest.mark.parametrize("identity", ["px4"])
def test_mavsdk_uploads_the_square_takes_off_flies_it_lands_and_sees_the_disarm(vehicle, identity):
    port = free_udp_port()
    flight = vehicle(identity, f"udpin:127.0.0.1:{port}")
    t0 = time.monotonic()
    result = asyncio.run(with_mavsdk(port, identity, lambda s: fly_plugin_mission(s, identity)))
    wall = time.monotonic() - t0

    items, progress = result["items"], result["progress"]
    first_flown = 1 if identity_named(identity).home_is_item_0 else 0
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


@pytest.mark.parametrize("identity", ["ardupilot"])
def test_mavsdk_imports_square_plan_and_flies_it_as_raw_items(vehicle, identity):
    port = free_udp_port()
    flight = vehicle(identity, f"udpin:127.0.0.1:{port}")
    t0 = time.monotonic()
    result = asyncio.run(with_mavsdk(port, identity, fly_raw_plan))
    wall = time.monotonic() - t0

    items, progress = result["items"], result["progress"]
    plan = square_items()
    home_row = 1 if identity_named(identity).home_is_item_0 else 0
    assert len(items) == len(plan) + home_row
    assert [i.command for i in items[home_row:]] == [i.command for i in plan]
    assert set(range(home_row + 1, len(items) + 1)) <= set(progress), progress
    assert progress == sorted(progress), f"progress went backwards: {progress}"
    check_landing(result, items[-1].x * 1e-7, items[-1].y * 1e-7)
    summary = flight.summary()
    assert summary["landed"] and summary["landing_error_m"] < LANDED_WITHIN_M, summary
    print(f"MAVSDK raw {identity}: {wall:.1f} s wall, {summary['sim_s']:.1f} s simulated")


# --- MAVProxy -------------------------------------------------------------------------------
