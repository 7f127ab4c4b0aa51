"""The downward range (the flow deck's, or DISTANCE_SENSOR's): the height above the surface
below, for the terrain estimate and as a height source (`navigation`'s height fusion)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from autopilot.estimation.estimator_params import HEIGHT_RANGE
from autopilot.estimation.sources import Navigation, Source, register
from simbridge.config import param

if TYPE_CHECKING:
    from autopilot.estimation.sensors import Imu
    from autopilot.types import Step

LABEL = "range"


@dataclass(frozen=True)
class RangeParams:
    rng_ctrl: int = param(
        1,
        lo=0,
        hi=2,
        doc="range: 1 conditional (terrain; the height while low and slow over a baro or "
        "GPS reference, PX4's range aid), 2 terrain, and the height when it is the reference",
    )
    rng_aid_max_height_m: float = param(
        0.5, unit="m", lo=0.0, hi=10.0, doc="range aid below this height (hysteresis 20 %)"
    )
    rng_aid_max_speed_m_s: float = param(
        1.0, unit="m/s", lo=0.0, hi=10.0, doc="range aid below this horizontal speed"
    )
    rng_noise_m: float = param(0.003, unit="m", lo=1e-4, hi=1.0, doc="range sd at short range")
    rng_noise_per_m: float = param(0.01, lo=0.0, hi=1.0, doc="range sd added per metre")

    def sd_m(self, range_m: float) -> float:
        return self.rng_noise_m + self.rng_noise_per_m * range_m


def range_reading(step: Step) -> float | None:
    """The newest downward range: the flow deck's float metres, else DISTANCE_SENSOR's cm."""
    if "HIL_OPTICAL_FLOW" in step.new and step.latest["HIL_OPTICAL_FLOW"]["distance"] > 0.0:
        return float(step.latest["HIL_OPTICAL_FLOW"]["distance"])
    if "DISTANCE_SENSOR" in step.new:
        d = step.latest["DISTANCE_SENSOR"]
        if d["min_distance"] <= d["current_distance"] <= d["max_distance"]:
            return d["current_distance"] * 0.01
    return None


def fuse(nav: Navigation, step: Step, imu: Imu, s: RangeParams, t: float) -> None:
    """The step's reading, for the height fusion that closes the step."""
    nav.range_m = range_reading(step)
    if nav.range_m is not None:
        nav.seen(LABEL, t)


register(Source(
    name="range",
    label=LABEL,
    sensor="flow_deck",
    settings=RangeParams,
    names={
        "EKF2_RNG_CTRL": "rng_ctrl",
        "EKF2_RNG_NOISE": "rng_noise_m",
        "EKF2_RNG_SFE": "rng_noise_per_m",
        "EKF2_RNG_A_HMAX": "rng_aid_max_height_m",
        "EKF2_RNG_A_VMAX": "rng_aid_max_speed_m_s",
    },
    fuse=fuse,
    active=lambda nav, s: bool(s.rng_ctrl),
    sets={"flow": {"EKF2_HGT_REF": HEIGHT_RANGE}},
))  # fmt: skip
