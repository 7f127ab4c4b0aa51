"""Navigator and commander as pure functions: a mission's life from the ground to the ground."""

from __future__ import annotations

import pytest

from autopilot.commander import CommanderParams, CommanderState, Mission, Mode, command
from autopilot.navigator import NavigatorState, Waypoint, navigate

WPS = (Waypoint((0.0, 0.0, 1.0), 0.05, 1.0), Waypoint((1.0, 0.0, 1.0), 0.05, 0.5))


def test_navigator_reaches_holds_and_moves_on():
    nav = navigate(NavigatorState(), WPS, (0.0, 0.0, 0.5), 0.0)
    assert nav.setpoint.position_m == (0.0, 0.0, 1.0) and not nav.holding
    nav = navigate(nav.state, WPS, (0.0, 0.0, 0.97), 2.0)
    assert nav.holding and nav.state.reached_at_s == 2.0
    nav = navigate(nav.state, WPS, (0.0, 0.0, 1.0), 2.9)
    assert nav.holding and nav.state.index == 0
    nav = navigate(nav.state, WPS, (0.0, 0.0, 1.0), 3.0)
    assert nav.setpoint.position_m == (1.0, 0.0, 1.0) and nav.state.index == 1
    nav = navigate(nav.state, WPS, (1.0, 0.0, 1.0), 5.0)
    nav = navigate(nav.state, WPS, (1.0, 0.0, 1.0), 5.5)
    assert nav.done


def test_a_waypoint_not_reached_in_time_is_held_anyway():
    wps = (Waypoint((0.0, 0.0, 0.03), 0.01, 2.0, timeout_s=8.0),)
    nav = navigate(NavigatorState(), wps, (0.0, 0.0, 0.15), 10.0)
    nav = navigate(nav.state, wps, (0.0, 0.0, 0.15), 17.9)
    assert not nav.holding
    nav = navigate(nav.state, wps, (0.0, 0.0, 0.15), 18.0)
    assert nav.holding


def test_commander_arms_takes_off_flies_lands_and_disarms():
    params = CommanderParams(arm_delay_s=0.1, spin_up_s=0.2, takeoff_altitude_m=1.0)
    mission = Mission(waypoints=(Waypoint((0.5, 0.0, 1.0), 0.05, 0.0),))
    rest = 0.0126
    s = CommanderState(since_s=0.0)
    c = command(s, mission, params, 0.05, (0.0, 0.0, rest), rest, rest)
    assert c.state.mode == Mode.DISARMED and not c.armed and c.setpoint is None
    c = command(c.state, mission, params, 0.1, (0.0, 0.0, rest), rest, rest)
    assert c.state.mode == Mode.ARMED and c.armed and c.setpoint is None
    c = command(c.state, mission, params, 0.31, (0.0, 0.0, rest), rest, rest)
    assert c.state.mode == Mode.TAKING_OFF and c.setpoint.position_m == pytest.approx(
        (0.0, 0.0, 1.0126)
    )
    c = command(c.state, mission, params, 5.0, (0.0, 0.0, 1.0), 1.0, rest)
    assert c.state.mode == Mode.FLYING and c.setpoint.position_m == (0.5, 0.0, 1.0)
    c = command(c.state, mission, params, 8.0, (0.5, 0.0, 1.0), 1.0, rest)
    assert c.state.mode == Mode.LANDING
    c = command(c.state, mission, params, 9.0, (0.5, 0.0, 0.95), 0.95, rest)
    assert c.setpoint.position_m[2] == pytest.approx(1.0 - 0.1 * 1.0)  # sinking at 0.1 m/s
    assert c.setpoint.velocity_m_s == (0.0, 0.0, -0.1)
    c = command(c.state, mission, params, 20.0, (0.5, 0.0, rest), rest + 0.001, rest)
    assert c.state.mode == Mode.LANDING and c.armed  # down, not yet for long enough
    c = command(c.state, mission, params, 20.1, (0.5, 0.0, rest), rest, rest)
    assert c.state.mode == Mode.LANDED and not c.armed and c.state.touchdown_s == 20.1
