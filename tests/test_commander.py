"""Commander, requests and modes as pure functions: a mission's life from the ground to the
ground, speed limits, mode numbering and idempotent requests."""

from __future__ import annotations

import pytest

from autopilot.commander import requests
from autopilot.commander.commander import (
    CommanderParams,
    CommanderState,
    Phase,
    command,
    limited_setpoint,
)
from autopilot.commander.mission_items import PlanStep
from autopilot.identity import ARDUPILOT, PX4
from autopilot.types import FlightMode

REST = 0.0126
PARAMS = CommanderParams(spin_up_s=0.2, takeoff_altitude_m=1.0, cruise_speed_m_s=0.5)
PLAN = (
    PlanStep(0, "takeoff", altitude_m=1.0),
    PlanStep(1, "waypoint", (0.5, 0.0, 1.0), hold_s=1.0),
    PlanStep(2, "speed", speed_m_s=2.0),
    PlanStep(3, "waypoint", (3.0, 0.0, 1.0)),
    PlanStep(4, "land", (3.0, 0.0, 0.0)),
)


def step(c, t, position, height=None):
    return command(
        c.state if hasattr(c, "state") else c, PARAMS, t, position, height or position[2], REST
    )


def test_a_mission_from_arming_to_disarm():
    s = requests.load_plan(CommanderState(), PLAN)
    c = step(s, 0.0, (0.0, 0.0, REST))
    assert c.state.phase == Phase.DISARMED and not c.armed and c.setpoint is None
    s, verdict = requests.arm(c.state, 0.1, (0.0, 0.0, REST), None, False)
    assert verdict.accepted
    s, verdict = requests.set_mode(s, FlightMode.MISSION, 0.1, (0.0, 0.0, REST), PARAMS)
    assert verdict.accepted
    c = step(s, 0.2, (0.0, 0.0, REST))
    assert c.state.phase == Phase.ARMED and c.armed and c.setpoint is None  # spinning up
    c = step(c, 0.31, (0.0, 0.0, REST))
    assert c.state.phase == Phase.TAKING_OFF
    assert c.setpoint.position_m == pytest.approx((0.0, 0.0, 1.0126))  # a 1 m step: in reach
    c = step(c, 4.0, (0.0, 0.0, 1.0))
    assert c.state.phase == Phase.HOLDING  # at the take-off altitude
    c = step(c, 4.004, (0.0, 0.0, 1.0))
    assert c.reached == (0,) and c.setpoint.position_m == (0.5, 0.0, 1.0)
    c = step(c, 6.0, (0.5, 0.0, 1.0))
    assert c.state.phase == Phase.HOLDING
    c = step(c, 7.0, (0.5, 0.0, 1.0))
    # waypoint 1 held, speed item 2 taken: waypoint 3 is 2.5 m away, the lead at 2 m/s is 4 m
    assert c.reached == (1, 2) and c.setpoint.position_m == pytest.approx((3.0, 0.0, 1.0))
    c = step(c, 9.0, (3.0, 0.0, 1.0))
    c = step(c, 9.004, (3.0, 0.0, 1.0))
    assert c.reached == (3,)
    c = step(c, 9.008, (3.0, 0.0, 1.0))
    c = step(c, 9.012, (3.0, 0.0, 1.0))
    assert c.state.phase == Phase.LANDING
    c = step(c, 10.012, (3.0, 0.0, 0.95))
    # sinking at the descent speed (0.5 m/s) while above MPC_LAND_ALT1 (0.5 m)
    assert c.setpoint.position_m[2] == pytest.approx(0.5, abs=3e-3)
    c = step(c, 20.0, (3.0, 0.0, REST), REST + 0.001)
    assert c.state.phase == Phase.LANDING and c.armed  # down, not yet for long enough
    c = step(c, 20.1, (3.0, 0.0, REST), REST)
    assert c.state.phase == Phase.LANDED and not c.armed and c.reached == (4,)
    assert c.state.mission_done


def test_speed_limits_clip_the_setpoint_not_the_short_moves():
    lead = 2.0  # a1 / a0 of the thesis's gains
    assert limited_setpoint((0, 0, 1), (0.5, 0, 1), lead, 0.5, 0.5, 0.5) == (0.5, 0, 1)
    far = limited_setpoint((0, 0, 1), (10.0, 0, 1), lead, 0.5, 0.5, 0.5)
    assert far == pytest.approx((1.0, 0, 1))  # steady speed 1 m * a0 / a1 = 0.5 m/s
    down = limited_setpoint((0, 0, 5), (0, 0, 0.03), lead, 0.5, 0.5, 0.25)
    assert down == pytest.approx((0, 0, 4.5))
    # the stiffer vertical loop (a1 / a0 = 12 / 36 s) leads by its own, shorter, time
    both = limited_setpoint((0, 0, 5), (10.0, 0, 0.03), 1.0, 0.5, 0.5, 0.25, 1.0 / 3.0)
    assert both == pytest.approx((0.5, 0, 5 - 0.25 / 3.0))


def test_requests_are_idempotent_and_refusals_say_why():
    s, v = requests.arm(CommanderState(), 1.0, (0, 0, REST), "sensors not ready", False)
    assert not v.accepted and "sensors not ready" in v.reason and s.phase == Phase.DISARMED
    s, v = requests.arm(s, 1.0, (0, 0, REST), "sensors not ready", True)  # forced
    assert v.accepted and s.phase == Phase.ARMED
    again, v = requests.arm(s, 1.5, (0, 0, REST), None, False)
    assert v.accepted and again == s
    _, v = requests.set_mode(s, FlightMode.MISSION, 2.0, (0, 0, REST), PARAMS)
    assert not v.accepted and "no mission" in v.reason
    _, v = requests.set_mode(s, FlightMode.LAND, 2.0, (0, 0, REST), PARAMS)
    assert not v.accepted and "not flying" in v.reason
    flying = requests.dataclasses.replace(s, phase=Phase.FLYING)
    _, v = requests.disarm(flying, 3.0, False)
    assert not v.accepted and "in the air" in v.reason
    down, v = requests.disarm(flying, 3.0, True)
    assert v.accepted and down.phase == Phase.DISARMED


@pytest.mark.parametrize("mode", list(FlightMode))
def test_mode_numbers_round_trip_under_both_identities(mode):
    px4 = PX4.custom_mode(mode)
    as_px4 = FlightMode.HOLD if mode == FlightMode.GUIDED else mode  # a reposition: AUTO.LOITER
    assert PX4.decode_mode(px4, None) == as_px4  # SET_MODE's packed form
    assert PX4.decode_mode((px4 >> 16) & 0xFF, (px4 >> 24) & 0xFF) == as_px4  # DO_SET_MODE
    # ArduCopter has no take-off or offboard mode: both are flown in Guided
    as_ardupilot = FlightMode.GUIDED if mode in (FlightMode.TAKEOFF, FlightMode.OFFBOARD) else mode
    assert ARDUPILOT.decode_mode(ARDUPILOT.custom_mode(mode), None) == as_ardupilot
    assert PX4.custom_mode(FlightMode.MISSION) == 0x04040000
    assert ARDUPILOT.custom_mode(FlightMode.RETURN) == 6


def test_do_set_mode_reads_the_sub_mode_only_under_px4():
    assert PX4.mode_from_command(4.0, 6.0) == (FlightMode.LAND, "main mode 4 sub 6")
    assert PX4.mode_from_command(4.0, float("nan")) == (None, "main mode 4 sub 0")
    assert ARDUPILOT.mode_from_command(9.0, 6.0) == (FlightMode.LAND, "custom mode 9")
    assert ARDUPILOT.mode_from_command(16.0, 0.0)[0] == FlightMode.HOLD  # PosHold: Loiter


def test_a_waypoint_never_reached_is_held_anyway_after_its_timeout():
    """A vehicle floating above a low waypoint (a ground effect stronger than the model's):
    the setpoint is the target exactly, so the timeout runs and the mission goes on."""
    params = CommanderParams(spin_up_s=0.2, waypoint_timeout_s=3.0)
    plan = (
        PlanStep(0, "takeoff", altitude_m=0.3),
        PlanStep(1, "waypoint", (-0.0171, 0.1331, 0.04)),
        PlanStep(2, "land", (-0.0171, 0.1331, 0.0)),
    )
    s = requests.load_plan(CommanderState(), plan)
    s, _ = requests.arm(s, 0.0, (0.0, 0.0, REST), None, False)
    s, _ = requests.set_mode(s, FlightMode.MISSION, 0.0, (0.0, 0.0, REST), params)
    c = command(s, params, 0.3, (0.0, 0.0, REST), REST, REST)
    c = command(c.state, params, 2.0, (0.0, 0.0, 0.3), 0.3, REST)  # took off
    t, stuck = 2.0, (-0.0173, 0.1337, 0.109)  # 7 cm above it, never within 2 cm
    while t < 6.0 and c.state.phase != Phase.LANDING:
        t += 0.004
        c = command(c.state, params, t, stuck, stuck[2], REST)
    assert c.state.phase == Phase.LANDING and t == pytest.approx(5.0, abs=0.1)


def test_a_take_off_mode_chosen_in_the_air_climbs_to_the_altitude_then_holds():
    """Not left in TAKEOFF (MAVProxy's `takeoff` while hovering stayed in AUTO.TAKEOFF)."""
    s, _ = requests.arm(CommanderState(), 0.0, (0.0, 0.0, REST), None, False)
    s, _ = requests.set_mode(s, FlightMode.TAKEOFF, 0.0, (0.0, 0.0, REST), PARAMS)
    c = step(s, 0.1, (0.0, 0.0, REST))
    c = step(c, 0.31, (0.0, 0.0, REST))
    c = step(c, 4.0, (0.0, 0.0, 1.0))
    assert c.state.mode == FlightMode.HOLD and "take-off complete: holding in hold" in c.events
    s, verdict = requests.set_mode(c.state, FlightMode.TAKEOFF, 5.0, (0.4, 0.0, 0.5), PARAMS)
    assert verdict.accepted and s.mode == FlightMode.TAKEOFF  # pulled down to 0.5 m meanwhile
    c = step(s, 5.004, (0.4, 0.0, 0.5))
    assert c.state.mode == FlightMode.TAKEOFF
    assert c.setpoint.position_m == pytest.approx((0.4, 0.0, 1.0126))  # back up, not home
    c = step(c, 9.0, (0.4, 0.0, 1.0126))
    assert c.state.mode == FlightMode.HOLD and "take-off complete: holding in hold" in c.events


def test_a_landing_descends_fast_high_up_and_at_the_landing_speed_near_the_ground():
    """PX4's MPC_LAND_ALT1/ALT2: the descent speed above 0.5 m, the landing speed below
    0.2 m, a speed falling with height between, never a jump; from 1 m down in about 4 s."""
    import numpy as np

    from autopilot.commander.landing_profile import LandingProfile

    profile = LandingProfile(fast_m_s=0.5, slow_m_s=0.1, alt1_m=0.5, alt2_m=0.2)
    dt = 1e-3
    heights = np.array([profile.height_m(1.0, t) for t in np.arange(0.0, 6.0, dt)])
    speeds = -np.diff(heights) / dt
    assert speeds[heights[1:] > 0.5].min() == pytest.approx(0.5)
    assert speeds[heights[1:] < 0.2] == pytest.approx(0.1, abs=1e-5)
    assert np.abs(np.diff(speeds)).max() < 1e-3  # continuous
    for h in (0.6, 0.35, 0.1):  # the closed form follows the speed it states
        t = np.argmin(np.abs(heights - h))
        assert speeds[t] == pytest.approx(profile.speed_m_s(heights[t]), abs=1e-3)
    assert np.argmax(heights < 0.0126) * dt == pytest.approx(4.08, abs=0.01)
    # one speed, or the two heights the wrong way round: still a descent that ends
    assert LandingProfile(0.1, 0.1, 0.5, 0.2).height_m(1.0, 2.0) == pytest.approx(0.8)
    assert LandingProfile(0.5, 0.1, 0.1, 0.2).height_m(1.0, 2.0) == pytest.approx(0.16)
