"""The navigator: a list of local waypoints into position setpoints, as a pure function.

A waypoint is reached when the vehicle is within its acceptance radius; the navigator then
holds it for `hold_s` and moves on. The thesis stops at each waypoint: desired velocity and
acceleration are zero.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from autopilot.controller import Setpoint
from simbridge.config import param
from simbridge.frames import Vec3


@dataclass(frozen=True)
class Waypoint:
    position_m: Vec3 = param(unit="m", lo=-1000.0, hi=1000.0, doc="local x east, y north, z up")
    acceptance_radius_m: float = param(0.05, unit="m", lo=0.001, hi=100.0, doc="reached within")
    hold_s: float = param(0.0, unit="s", lo=0.0, hi=3600.0, doc="time to hold once reached")
    yaw_deg: float = param(0.0, unit="deg", lo=-180.0, hi=180.0, doc="heading, from east")
    timeout_s: float | None = param(
        None,
        unit="s",
        lo=0.0,
        hi=3600.0,
        doc="not reached this long after setting out: hold it anyway (null: wait forever)",
    )


@dataclass(frozen=True)
class NavigatorState:
    index: int = 0  # the waypoint being flown to or held
    reached_at_s: float | None = None  # when it was reached (or timed out); None while flying
    left_at_s: float | None = None  # when the vehicle set out for it


@dataclass(frozen=True)
class Navigation:
    state: NavigatorState
    setpoint: Setpoint
    holding: bool  # at the waypoint, waiting out its hold time
    done: bool  # every waypoint reached and held


def navigate(
    nav: NavigatorState, waypoints: tuple[Waypoint, ...], position_m: Vec3, time_s: float
) -> Navigation:
    while True:
        wp = waypoints[nav.index]
        setpoint = Setpoint(position_m=wp.position_m, yaw_rad=math.radians(wp.yaw_deg))
        if nav.left_at_s is None:
            nav = NavigatorState(nav.index, nav.reached_at_s, time_s)
        if nav.reached_at_s is None:
            close = math.dist(position_m, wp.position_m) <= wp.acceptance_radius_m
            late = wp.timeout_s is not None and time_s - nav.left_at_s >= wp.timeout_s
            if close or late:
                nav = NavigatorState(nav.index, time_s, nav.left_at_s)
        if nav.reached_at_s is None:
            return Navigation(nav, setpoint, holding=False, done=False)
        if time_s - nav.reached_at_s < wp.hold_s:
            return Navigation(nav, setpoint, holding=True, done=False)
        if nav.index + 1 == len(waypoints):
            return Navigation(nav, setpoint, holding=True, done=True)
        nav = NavigatorState(nav.index + 1, None, time_s)
