"""Go-to, guided and offboard requests and the identity's defaults, as pure functions, on
real pymavlink messages."""

from __future__ import annotations

import math
import os

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mav

from autopilot.commander import guided, requests
from autopilot.commander.commander import CommanderState, Phase, command
from autopilot.commander.commander_params import CommanderParams
from autopilot.commander.mission_items import (
    NAV_WAYPOINT,
    Geofence,
    Home,
    MissionItem,
    is_home_row,
    item_at,
)
from autopilot.commander.offboard import Refused, follow, global_target, local_target
from autopilot.identity import ARDUPILOT, PX4, Identity
from autopilot.params import ParamStore
from autopilot.types import FlightMode

REST = 0.0126
ORIGIN = (59.3498, 18.0707, 28.0)
HOME = Home(*ORIGIN)
NAN = math.nan
VELOCITY_ONLY = 0b100111000111  # MAVSDK's set_velocity_ned: x, y, z, a, yaw rate ignored


def local(frame: int, mask: int, *fields: float) -> mav.MAVLink_message:
    return mav.MAVLink_set_position_target_local_ned_message(0, 1, 1, frame, mask, *fields)


def context(identity: Identity, fence: Geofence | None = None) -> guided.Context:
    """Flying at 1 m over home, the surface at z = 0."""
    fence = fence or Geofence()
    return guided.Context(
        identity, ORIGIN, (0.0, 0.0, REST), 0.0, (0.0, 0.0, 1.0), 0.0, fence, 10.0
    )


def flying(mode: FlightMode = FlightMode.HOLD) -> CommanderState:
    s, _ = requests.arm(CommanderState(), 0.0, (0.0, 0.0, REST), None, False)
    return requests.dataclasses.replace(s, phase=Phase.HOLDING, mode=mode)


def test_defaults_follow_the_identity():
    px4, ardupilot = ParamStore(None, identity="px4"), ParamStore(None, identity="ardupilot")
    for store in (px4, ardupilot):
        assert store.geofence() == Geofence()  # no fence until the user sets one
        assert store.values["NAV_DLL_ACT"] == 0  # no ground-station-loss failsafe either
    assert px4.values["MIS_TAKEOFF_ALT"] == 2.5 and px4.values["COM_DL_LOSS_T"] == 10.0
    assert px4.values["COM_OF_LOSS_T"] == 1.0 and ardupilot.values["COM_OF_LOSS_T"] == 3.0
    assert px4.values["GF_ACTION"] == 2 and ardupilot.values["GF_ACTION"] == 3


def test_item_0_is_home_when_a_station_put_home_there():
    assert is_home_row(MissionItem(NAV_WAYPOINT, frame=0, x=1, y=1, z=28.0), HOME)  # MSL
    assert is_home_row(item_at(NAV_WAYPOINT, HOME, (0.3, 0.2, 0.0)), HOME)
    assert not is_home_row(item_at(NAV_WAYPOINT, HOME, (4.0, 0.0, 1.0)), HOME)  # MAVSDK's


def test_velocity_setpoints_are_integrated_into_a_moving_position():
    target = local_target(1, VELOCITY_ONLY, (0, 0, 0, 1.0, 0.5, -0.2, 0, 0, 0, 0.0, 0), (0,) * 3, 0)
    assert target.velocity_m_s == (0.5, 1.0, 0.2)  # NED -> east, north, up
    sp, track = follow(target, None, (0.0, 0.0, 1.0), 0.0, 0.0)
    for k in range(1, 11):  # the vehicle keeps up with the setpoint
        sp, track = follow(target, track, track.position_m, 0.0, 0.1 * k)
    assert sp.position_m == pytest.approx((0.5, 1.0, 1.2))
    assert sp.velocity_m_s == (0.5, 1.0, 0.2) and sp.yaw_rad == pytest.approx(math.pi / 2)
    stuck, _ = follow(target, track, (0.0, 0.0, 1.0), 0.0, 1.1)  # never runs away
    assert abs(stuck.position_m[1]) <= 1.0


def test_acceleration_and_yaw_rate_are_integrated_and_mixed_axes_taken():
    mask = 0b010000000000 | 0b000000111011  # z by position, x y by acceleration; yaw rate
    fields = (0, 0, -1.5, 0, 0, 0, 2.0, 0, 0, 0, 0.5)
    target = local_target(1, mask, fields, (0.0, 0.0, 1.0), 0.0)
    sp, track = follow(target, None, (0.0, 0.0, 1.0), 0.0, 0.0)
    for k in range(1, 6):
        sp, track = follow(target, track, track.position_m, 0.0, 0.1 * k)
    assert sp.velocity_m_s[1] == pytest.approx(1.0)  # 2 m/s^2 north for 0.5 s
    assert sp.acceleration_m_s2 == (0.0, 2.0, 0.0) and sp.position_m[2] == 1.5
    assert sp.yaw_rad == pytest.approx(-0.25)  # 0.5 rad/s clockwise


def test_body_frame_offsets_turn_with_the_heading():
    # MAVProxy's `position 1 0 0`: 1 m forward of a vehicle heading north
    target = local_target(8, 3576, (1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0), (2.0, 3.0, 1.0), math.pi / 2)
    assert target.position_m == pytest.approx((2.0, 4.0, 1.0)) and target.position_only


@pytest.mark.parametrize(
    ("frame", "mask", "why"),
    [
        (1, 0b1000000000, "force"),  # with accelerations: as forces
        (1, 0b000111111111, "ignores position, velocity and acceleration"),
        (12, VELOCITY_ONLY, "frame 12"),
        (8, 0b110111111110, "x and y together"),
    ],
)
def test_what_cannot_be_flown_is_refused_saying_why(frame, mask, why):
    with pytest.raises(Refused, match=why):
        local_target(frame, mask, (1.0,) * 11, (0.0, 0.0, 1.0), 0.0)
    s, refused = guided.setpoint(local(frame, mask, *(1.0,) * 11), flying(), context(PX4))
    assert why in refused and s.offboard is None


def test_offboard_velocity_flies_and_ardupilot_holds_in_guided_when_it_stops():
    params = CommanderParams()
    ctx = context(ARDUPILOT)
    s = requests.dataclasses.replace(flying(FlightMode.GUIDED), hold_mode=FlightMode.GUIDED)
    message = local(1, VELOCITY_ONLY, 0, 0, 0, 1.0, 0, 0, 0, 0, 0, 0.0, 0)
    s, refused = guided.setpoint(message, s, ctx)
    assert refused is None and s.mode == FlightMode.OFFBOARD
    c = command(s, params, 10.5, (0.0, 0.0, 1.0), 1.0, REST)
    assert c.setpoint.velocity_m_s == (0.0, 1.0, 0.0)
    c = command(c.state, params, 14.0, (0.0, 3.0, 1.0), 1.0, REST)  # none for 4 s
    assert c.state.mode == FlightMode.GUIDED and c.setpoint.position_m == (0.0, 3.0, 1.0)


def test_go_to_needs_the_air_and_the_fence_and_flies_in_the_identitys_mode():
    here = ORIGIN
    message = mav.MAVLink_command_int_message(
        1, 1, 6, 192, 0, 0, -1, 1, 0, NAN, round(here[0] * 1e7), round(here[1] * 1e7) + 300, 1.5
    )
    grounded, _ = requests.arm(CommanderState(), 0.0, (0.0, 0.0, REST), None, False)
    _, verdict = guided.reposition(message, grounded, context(PX4))
    assert not verdict.accepted and "not flying" in verdict.reason
    s, verdict = guided.reposition(message, flying(FlightMode.MISSION), context(PX4))
    assert verdict.accepted and s.mode == FlightMode.HOLD
    assert s.target_m == pytest.approx((1.70, 0.0, 1.5), abs=0.01)
    s, verdict = guided.reposition(message, flying(), context(ARDUPILOT))
    assert verdict.accepted and s.mode == FlightMode.GUIDED
    fenced = context(PX4, fence=Geofence(max_radius_m=1.0))
    _, verdict = guided.reposition(message, flying(), fenced)
    assert not verdict.accepted and "geofence" in verdict.reason
    item = mav.MAVLink_mission_item_int_message(
        1, 1, 0, 6, 16, 2, 0, 0, 0, 0, 0, round(here[0] * 1e7), round(here[1] * 1e7), 1.0
    )
    _, verdict = guided.guided_item(item, flying(FlightMode.HOLD), context(ARDUPILOT))
    assert not verdict.accepted and "switch to guided" in verdict.reason
    s, verdict = guided.guided_item(item, flying(FlightMode.GUIDED), context(ARDUPILOT))
    assert verdict.accepted and s.target_m == pytest.approx((0.0, 0.0, 1.0), abs=1e-6)


def test_global_setpoints_take_latitude_longitude_and_relative_altitude():
    lat, lon = round(ORIGIN[0] * 1e7) + 90, round(ORIGIN[1] * 1e7)  # about 1 m north
    fields = (2.0, 0, 0, 0, 0, 0, 0, NAN, 0)  # 2 m above home, yaw ignored below
    mask = 0b110111111000  # position only
    target = global_target(6, mask, lat, lon, fields, ORIGIN, 0.1, (0.0, 0.0, 1.0))
    assert target.position_m == pytest.approx((0.0, 1.0, 2.1), abs=0.01) and target.position_only
    with pytest.raises(Refused, match="frame 1"):
        global_target(1, mask, lat, lon, fields, ORIGIN, 0.1, (0.0, 0.0, 1.0))
