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


@dataclass(frozen=True)
class LandDetector:
    since_s: float | None = None  # contact seen continuously since

    def step(self, time_s: float, contact: bool) -> LandDetector:
        if not contact:
            return LandDetector(None)
        return LandDetector(self.since_s if self.since_s is not None else time_s)

    def landed(self, time_s: float, params: LandDetectorParams) -> bool:
        return self.since_s is not None and time_s - self.since_s >= params.trigger_s
