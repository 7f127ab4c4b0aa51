"""The land detector, in PX4's manner: ground contact declared from what the vehicle does.

While landing, a vehicle that is near the surface, no longer descends although it is asked
to go lower and the controller already demands less lift than its weight (the ground, or a
cushion of air the controller does not know, holds it up) has landed, even if it floats a
few centimetres up: PX4's "ground contact" (no vertical motion while the thrust is low for
LNDMC_TRIG_TIME). Without this a landing setpoint would sink on below the ground while the
vehicle sits in a cushion of air; the commander also stops it `landing_floor_m` below the
resting height.
"""

from __future__ import annotations

from dataclasses import dataclass

from simbridge.config import param
from simbridge.vehicle import GRAVITY_M_S2

# Above the resting height by more than this, the vehicle is in the air: samples of
# equation 3.16 are taken there only, since on the ground the contact force would pass for
# ground effect.
AIRBORNE_MARGIN_M = 0.002


@dataclass(frozen=True)
class LandDetectorParams:
    max_height_m: float = param(
        0.1,
        unit="m",
        lo=0.0,
        hi=1.0,
        doc="height above resting within which contact counts (a cushion of air holds a "
        "vehicle whose model lacks the ground effect up to a few cm; PX4 does not look at it)",
    )
    low_thrust: float = param(
        0.97,
        lo=0.0,
        hi=1.0,
        doc="lift demanded (rotors and ground effect) below this fraction of the weight: low",
    )
    max_climb_rate_m_s: float = param(
        0.05, unit="m/s", lo=0.0, hi=5.0, doc="vertical speed below which it is not moving"
    )
    min_setpoint_below_m: float = param(
        0.01, unit="m", lo=0.0, hi=1.0, doc="the setpoint this far below: it wants to go lower"
    )
    trigger_s: float = param(
        0.3, unit="s", lo=0.0, hi=10.0, doc="all of it this long: ground contact"
    )


def ground_contact(
    height_m: float,
    resting_height_m: float,
    vertical_speed_m_s: float,
    setpoint_below_m: float,
    thrust_fraction: float,
    params: LandDetectorParams,
) -> bool:
    """This step looks like ground contact (the caller requires it for `trigger_s`);
    `thrust_fraction`: the lift the controller last demanded (its vertical acceleration plus
    gravity, whatever share of it it expects from the ground effect) over the weight."""
    return (
        height_m <= resting_height_m + params.max_height_m
        and abs(vertical_speed_m_s) <= params.max_climb_rate_m_s
        and setpoint_below_m >= params.min_setpoint_below_m
        and thrust_fraction <= params.low_thrust
    )


def airborne(height_m: float, resting_height_m: float) -> bool:
    """The vehicle is off the ground (by `AIRBORNE_MARGIN_M`)."""
    return height_m > resting_height_m + AIRBORNE_MARGIN_M


def landing_contact(
    height_m: float,
    resting_height_m: float,
    vertical_speed_m_s: float,
    position_z_m: float,
    landing_setpoint_z_m: float | None,
    commanded_vertical_m_s2: float | None,
    params: LandDetectorParams,
) -> bool:
    """`ground_contact` from what the loop knows: `landing_setpoint_z_m`, the last setpoint's
    height while landing (None: not landing, so nothing is asked below);
    `commanded_vertical_m_s2`, the controller's last vertical acceleration (None: it did
    not run, rotors off). The lift it demands of rotors and ground effect together, over
    the weight: below 1 it pushes down, and a vehicle that does not follow is held up."""
    below = position_z_m - landing_setpoint_z_m if landing_setpoint_z_m is not None else 0.0
    thrust_fraction = (
        1.0 + commanded_vertical_m_s2 / GRAVITY_M_S2 if commanded_vertical_m_s2 is not None else 0.0
    )
    return ground_contact(
        height_m, resting_height_m, vertical_speed_m_s, below, thrust_fraction, params
    )


@dataclass(frozen=True)
class LandDetector:
    since_s: float | None = None  # contact seen continuously since

    def step(self, time_s: float, contact: bool) -> LandDetector:
        if not contact:
            return LandDetector(None)
        return LandDetector(self.since_s if self.since_s is not None else time_s)

    def landed(self, time_s: float, params: LandDetectorParams) -> bool:
        return self.since_s is not None and time_s - self.since_s >= params.trigger_s
