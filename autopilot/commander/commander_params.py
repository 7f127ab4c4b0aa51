"""The commander's parameters: take-off, waypoints, speeds, landing, return and offboard
timeouts, each with its unit and range (tuned over MAVLink through autopilot/params.py)."""

from __future__ import annotations

from dataclasses import dataclass

from simbridge.config import param


@dataclass(frozen=True)
class CommanderParams:
    spin_up_s: float = param(
        0.2, unit="s", lo=0.0, hi=10.0, doc="armed on the ground before take-off"
    )
    takeoff_altitude_m: float = param(1.0, unit="m", lo=0.05, hi=100.0, doc="above home")
    takeoff_acceptance_m: float = param(
        0.05, unit="m", lo=0.001, hi=10.0, doc="take-off reached within"
    )
    acceptance_radius_m: float = param(
        0.05, unit="m", lo=0.001, hi=100.0, doc="waypoint reached within (item's 0)"
    )
    waypoint_timeout_s: float = param(
        0.0, unit="s", lo=0.0, hi=3600.0, doc="not reached this long after the setpoint got "
        "there: held anyway (0: wait forever)",
    )  # fmt: skip
    cruise_speed_m_s: float = param(0.5, unit="m/s", lo=0.01, hi=20.0, doc="horizontal speed")
    climb_speed_m_s: float = param(0.5, unit="m/s", lo=0.01, hi=10.0, doc="vertical speed up")
    descent_speed_m_s: float = param(
        0.5, unit="m/s", lo=0.01, hi=10.0, doc="vertical speed down (not landing)"
    )
    land_speed_m_s: float = param(
        0.1, unit="m/s", lo=0.01, hi=3.0, doc="descent rate of the landing setpoint near the "
        "ground",
    )  # fmt: skip
    land_blend_from_m: float = param(
        0.5, unit="m", lo=0.0, hi=100.0, doc="a landing slows from the descent speed below this "
        "height above the ground",
    )  # fmt: skip
    land_slow_below_m: float = param(
        0.2, unit="m", lo=0.0, hi=100.0, doc="... to the landing speed below this one",
    )  # fmt: skip
    return_altitude_m: float = param(
        1.0, unit="m", lo=0.0, hi=100.0, doc="lowest altitude above home to return at"
    )
    touchdown_margin_m: float = param(
        0.004, unit="m", lo=0.0, hi=0.1, doc="height above resting that counts as down"
    )
    touchdown_s: float = param(
        0.1, unit="s", lo=0.0, hi=5.0, doc="down this long: touchdown, disarm"
    )
    landing_floor_m: float = param(
        0.05, unit="m", lo=0.0, hi=1.0, doc="the landing setpoint stops this far below resting"
    )
    offboard_timeout_s: float = param(
        0.5, unit="s", lo=0.05, hi=60.0, doc="offboard setpoints older than this: hold"
    )
