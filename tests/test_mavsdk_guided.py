"""What a new MAVSDK user does in the first hour, with MAVSDK 4.1 over loopback
UDP against `groundfx autopilot` at its default parameters: an 8 m square through the mission
plugin under both identities, every corner checked on the recording the autopilot wrote;
goto_location and offboard velocity under both (under ArduCopter both are flown in Guided)."""

from __future__ import annotations

import asyncio
import functools
import math
import time
from typing import Any

import pytest
from mavsdk.asyncio.plugins.mission import MissionItem, MissionPlan
from mavsdk.asyncio.plugins.offboard import VelocityNedYaw
from mavsdk.asyncio.plugins.telemetry import FlightMode

from autopilot.commander.mission_items import Home
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
from tests.test_mavsdk import (
    Client,
    after,
    eventually,
    first,
    follow_to_the_ground,
    is_flying,
    is_on_ground,
    with_mavsdk,
    within,
)

__all__ = ["vehicle"]  # the fixture, used by name

ORIGIN = origin_home()  # the vehicle starts at the origin
ACCEPTANCE_M = SQUARE_ACCEPTANCE_M  # MAVSDK's own default would be 1 m
ALTITUDE_M = 1.0
SPEED_M_S = SQUARE_SPEED_M_S
FAST = SQUARE_SPEEDUP


async def home_of(client: Client) -> Home:
    home, _ = await first(
        "home", 5, client.telemetry.subscribe_home(), lambda h: math.isfinite(h.latitude_deg)
    )
    return Home(home.latitude_deg, home.longitude_deg, home.absolute_altitude_m)


async def take_off(client: Client) -> float:
    """action.takeoff() at the defaults (PX4: MIS_TAKEOFF_ALT 2.5 m; ArduPilot: MAVSDK's own
    2 m as param 7); returns the altitude it climbed to."""
    altitude = await within("take-off altitude", 5, client.action.get_takeoff_altitude())
    await within("arm", 5, client.action.arm())
    await within("take off", 5, client.action.takeoff())
    await first(
        f"climb to {altitude:g} m",
        30,
        client.telemetry.subscribe_position(),
        lambda p: p.relative_altitude_m > altitude - 0.05,
    )
    return altitude


async def fly_8m_square(client: Client) -> dict[str, Any]:
    """The mission plugin as its example uses it: waypoints, the last one landing; no home
    row, under either identity."""
    home = await home_of(client)
    items = []
    corners = square_8m(home, ALTITUDE_M)
    for k, (east, north, up) in enumerate(corners):
        lat, lon = local_to_geodetic(home.lat_deg, home.lon_deg, east, north)
        last = k == len(corners) - 1
        items.append(
            MissionItem(
                latitude_deg=lat,
                longitude_deg=lon,
                relative_altitude_m=up,
                speed_m_s=SPEED_M_S,
                is_fly_through=False,
                acceptance_radius_m=ACCEPTANCE_M,
                yaw_deg=math.nan,
                vehicle_action=MissionItem.VehicleAction.LAND if last else None,
            )
        )
    t0 = time.monotonic()
    await within(
        "set RTL after mission", 10, client.mission.set_return_to_launch_after_mission(False)
    )
    await within("mission upload", 10, client.mission.upload_mission(MissionPlan(items)))
    upload_s = time.monotonic() - t0
    await take_off(client)
    result = await follow_to_the_ground(
        client,
        len(items),
        client.mission.subscribe_mission_progress(),
        client.mission.start_mission(),
    )
    await eventually("mission finished", 5, client.mission.is_mission_finished)
    return dict(result, home=home, corners=corners, upload_s=upload_s)


# under PX4, the autopilot MAVSDK is made for; MAVProxy flies it under ArduCopter
@pytest.mark.parametrize("identity", ["px4"])
def test_mavsdk_flies_the_8_m_square_at_default_parameters_every_corner(
    vehicle, identity, tmp_path
):
    port = free_udp_port()
    recording = tmp_path / "square.rrd"
    flight = vehicle(identity, f"udpin:127.0.0.1:{port}", "--record", str(recording), speedup=FAST)
    t0 = time.monotonic()
    result = asyncio.run(with_mavsdk(port, identity, fly_8m_square, acceptance_m=None))
    wall = time.monotonic() - t0
    summary = flight.summary()
    assert summary["landed"], summary
    progress = result["progress"]
    assert set(range(len(result["corners"]) + 1)) <= set([0, *progress]), progress
    approach = closest_approach_m(recording, ORIGIN, result["home"], result["corners"])
    assert max(approach) < ACCEPTANCE_M, f"closest to each corner: {approach}"
    upload_ms = 1e3 * result["upload_s"]
    print(
        f"MAVSDK 8 m square {identity}: upload {upload_ms:.0f} ms, {wall:.1f} s wall, "
        f"{summary['sim_s']:.1f} s simulated, corners within {[round(a, 3) for a in approach]} m"
    )


# MAVSDK's name for the mode a go-to is flown in: PX4's AUTO.LOITER; ArduCopter's Guided,
# which MAVSDK calls offboard
GOTO_MODE = {"px4": FlightMode.HOLD, "ardupilot": FlightMode.OFFBOARD}


async def goto_and_offboard(client: Client, identity: str) -> dict[str, Any]:
    """Take off, goto_location 2 m east, then offboard at 0.5 m/s north started with velocity
    setpoints, stop, land."""
    telemetry, action = client.telemetry, client.action
    home = await home_of(client)
    altitude = await take_off(client)
    lat, lon = local_to_geodetic(home.lat_deg, home.lon_deg, 2.0, 0.0)
    t0 = time.monotonic()
    await within(
        "goto_location", 5, action.goto_location(lat, lon, home.alt_m + altitude, math.nan)
    )
    goto_ack_s = time.monotonic() - t0

    def off(p: Any, east: float, north: float) -> float:
        e, n = geodetic_to_local(home.lat_deg, home.lon_deg, p.latitude_deg, p.longitude_deg)
        return math.hypot(e - east, n - north)

    await first(
        "at the go-to target", 30, telemetry.subscribe_position(), lambda p: off(p, 2.0, 0.0) < 0.1
    )
    goto_s = time.monotonic() - t0
    mode = await within("flight mode", 5, telemetry.flight_mode())
    assert mode == GOTO_MODE[identity]
    offboard = client.offboard
    # started with a velocity setpoint, as MAVSDK's offboard_velocity_ned example does
    north = VelocityNedYaw(0.5, 0.0, 0.0, 0.0)
    await within("velocity setpoint", 5, offboard.set_velocity_ned(north))
    await within("offboard start", 5, offboard.start())
    await first(
        "1 m north in offboard",
        30,
        telemetry.subscribe_position(),
        lambda p: off(p, 2.0, 1.0) < 0.15,
    )
    assert await within("flight mode", 5, telemetry.flight_mode()) == FlightMode.OFFBOARD
    await within("stop", 5, offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 0.0)))
    await within("offboard stop", 5, offboard.stop())
    landed = asyncio.create_task(
        first(
            "landed",
            FLIGHT_WALL_S,
            telemetry.subscribe_landed_state(),
            after(is_flying, is_on_ground),
        )
    )
    await asyncio.sleep(0)
    await within("land", 5, action.land())
    await landed
    return {"goto_ack_s": goto_ack_s, "goto_s": goto_s}


@pytest.mark.parametrize("identity", ["px4"])  # the acceptance: under PX4 (ArduCopter: MAVProxy)
def test_mavsdk_goto_location_and_offboard_velocity(vehicle, identity):
    port = free_udp_port()
    # four times real time: MAVSDK streams setpoints at 20 Hz of the wall clock, 0.2 s
    # simulated apart, well inside PX4's COM_OF_LOSS_T (1 s)
    flight = vehicle(identity, f"udpin:127.0.0.1:{port}", speedup="4")
    fly = functools.partial(goto_and_offboard, identity=identity)
    result = asyncio.run(with_mavsdk(port, identity, fly, acceptance_m=None))
    summary = flight.summary()
    assert summary["landed"], summary
    acked, there = result["goto_ack_s"], result["goto_s"]
    print(f"MAVSDK goto {identity}: acked in {1e3 * acked:.0f} ms, there in {there:.1f} s wall")
