"""Ground and ceiling effect: thesis equations 2.13 and 3.4, per rotor.

    f_ge = C_T n^2 (1 / (1 - rho (R / 4z)^2) - 1)

z is the rotor's height above the surface actually below it (a ray in the simulator), held at
the cut-off height below it: the smallest two-decimal value above the singular point
z* = R sqrt(rho) / 4 (thesis section 3.3.1; 0.02 m for rho = 1 and 2), a centimetre higher
where the gain at that height would exceed tenfold (`cutoff_height_m`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from simbridge.config import param


def singular_height_m(rho: float, rotor_radius_m: float) -> float:
    """The height z* at which equation 3.4 goes to infinity."""
    return rotor_radius_m * math.sqrt(rho) / 4.0


# The largest thrust gain the cut-off rule allows (f_ge / f_rotor at and below the cut-off).
MAX_CUTOFF_GAIN = 10.0


def cutoff_height_m(rho: float, rotor_radius_m: float) -> float:
    """The smallest two-decimal height strictly above the singular point (the thesis's rule),
        and a centimetre higher where the gain there would exceed MAX_CUTOFF_GAIN.

        The thesis used rho 1 and 2 (gains 0.53 and 2.2 at its 0.02 m on the nano). Applied
        beyond them the rule can land just above the singularity: at rho 2.8 the nano's cut-off
        0.02 m is 0.3 mm above it and a rotor near the ground would lift 29 times its thrust
        (140 times at rho 2.88), which no rotor does; such rho take the next centimetre (or the
    next that brings the gain within bounds)."""
    singular = singular_height_m(rho, rotor_radius_m)
    cutoff = (math.floor(singular * 100.0 + 1e-9) + 1.0) / 100.0
    # a large rotor's singular height is tens of cm, where a centimetre may not be enough
    while 1.0 / (1.0 - rho * (rotor_radius_m / (4.0 * cutoff)) ** 2) - 1.0 > MAX_CUTOFF_GAIN:
        cutoff = round(cutoff + 0.01, 2)
    return cutoff


def resolve_cutoff_m(rho: float, cutoff_m: float | None, rotor_radius_m: float) -> float:
    """The thesis's cut-off rule, or a given cut-off, which must clear the singular point."""
    if cutoff_m is None:
        return cutoff_height_m(rho, rotor_radius_m)
    singular = singular_height_m(rho, rotor_radius_m)
    if cutoff_m <= singular:
        raise ValueError(
            f"cutoff_m {cutoff_m:g} must be above the singular height {singular:.4f} m"
        )
    return cutoff_m


def thrust_gain(height_m: float, rho: float, rotor_radius_m: float, cutoff_m: float) -> float:
    """f_ge / f_rotor of equation 3.4; constant below the cut-off, 0 when nothing is below."""
    if height_m == math.inf:
        return 0.0
    z = height_m if height_m > cutoff_m else cutoff_m
    r = rotor_radius_m / (4.0 * z)
    return 1.0 / (1.0 - rho * r * r) - 1.0


def thrust_gain_array(
    height_m: np.ndarray, rho: float, rotor_radius_m: float, cutoff_m: float
) -> np.ndarray:
    """`thrust_gain` over arrays of heights (the gap diagnosis evaluates it on whole logs)."""
    h = np.asarray(height_m, dtype=float)
    r = rotor_radius_m / (4.0 * np.maximum(np.where(np.isinf(h), 1e9, h), cutoff_m))
    return np.where(np.isinf(h), 0.0, 1.0 / (1.0 - rho * r * r) - 1.0)


def ground_effect_force_n(
    rotor_thrust_n: float, height_m: float, rho: float, rotor_radius_m: float, cutoff_m: float
) -> float:
    """Equation 3.4: the vertical force one rotor gains at `height_m` above the surface."""
    return rotor_thrust_n * thrust_gain(height_m, rho, rotor_radius_m, cutoff_m)


def ground_effect_forces_n(
    rotor_thrusts_n: Sequence[float],  # four rotors
    heights_m: Sequence[float],
    rho: float,
    rotor_radius_m: float,
    cutoff_m: float,
    reach_m: float,
) -> list[float]:
    """Equation 3.4 for every rotor in one call (the simulator's physics step): the same
    values as `ground_effect_force_n`, 0 where the height is beyond `reach_m` (or none)."""
    k = rho * rotor_radius_m * rotor_radius_m / 16.0  # rho (R / 4z)^2 = k / z^2
    c2 = cutoff_m * cutoff_m
    f0, f1, f2, f3 = rotor_thrusts_n
    h0, h1, h2, h3 = heights_m
    # written out: the physics step calls this at 1 kHz
    return [
        0.0 if h0 > reach_m else f0 * (1.0 / (1.0 - k / (h0 * h0 if h0 > cutoff_m else c2)) - 1.0),
        0.0 if h1 > reach_m else f1 * (1.0 / (1.0 - k / (h1 * h1 if h1 > cutoff_m else c2)) - 1.0),
        0.0 if h2 > reach_m else f2 * (1.0 / (1.0 - k / (h2 * h2 if h2 > cutoff_m else c2)) - 1.0),
        0.0 if h3 > reach_m else f3 * (1.0 / (1.0 - k / (h3 * h3 if h3 > cutoff_m else c2)) - 1.0),
    ]


def hover_rotor_speed_in_ground_effect_rad_s(
    weight_n: float,
    thrust_coefficient_n_s2: float,
    height_m: float,
    rho: float,
    rotor_radius_m: float,
    cutoff_m: float,
) -> float:
    """The rotor speed at which four level rotors at `height_m` carry the weight (fig. 3.2)."""
    per_rotor_n = weight_n / 4.0 / (1.0 + thrust_gain(height_m, rho, rotor_radius_m, cutoff_m))
    return math.sqrt(per_rotor_n / thrust_coefficient_n_s2)


@dataclass(frozen=True)
class GroundEffectParams:
    """The thesis's ground effect; `rho` is rho_sim (the thesis used 1 and 2)."""

    rho: float = param(1.0, lo=0.0, hi=50.0, lo_open=True, doc="strength rho of equation 3.4")
    cutoff_m: float | None = param(
        None,
        unit="m",
        lo=0.0,
        hi=1.0,
        lo_open=True,
        doc="height below which the force is constant; default: the thesis's rule",
    )
    ray_length_m: float = param(
        3.0, unit="m", lo=0.1, hi=100.0, doc="beyond this nothing is below (f_ge = 0)"
    )

    def cutoff_for(self, rotor_radius_m: float) -> float:
        return resolve_cutoff_m(self.rho, self.cutoff_m, rotor_radius_m)


@dataclass(frozen=True)
class CeilingEffectParams:
    """Ceiling effect: the same law with the distance to the surface above, a thrust gain."""

    rho: float = param(1.0, lo=0.0, hi=50.0, lo_open=True, doc="strength, as rho of eq. 3.4")
    cutoff_m: float | None = param(
        None, unit="m", lo=0.0, hi=1.0, lo_open=True, doc="distance below which it is constant"
    )
    ray_length_m: float = param(3.0, unit="m", lo=0.1, hi=100.0, doc="beyond this: no ceiling")

    def cutoff_for(self, rotor_radius_m: float) -> float:
        return resolve_cutoff_m(self.rho, self.cutoff_m, rotor_radius_m)


def hub_moment(rotors_body_m: Sequence[Sequence[float]], g: Sequence[float]) -> tuple[float, ...]:
    """sum g_i r_i over the rotors' body positions r_i: with vertical forces g_i at the hubs
    R r_i, the world torque is ((R s)_y, -(R s)_x, 0) for this s."""
    r0, r1, r2, r3 = rotors_body_m
    g0, g1, g2, g3 = g
    return (
        g0 * r0[0] + g1 * r1[0] + g2 * r2[0] + g3 * r3[0],
        g0 * r0[1] + g1 * r1[1] + g2 * r2[1] + g3 * r3[1],
        g0 * r0[2] + g1 * r1[2] + g2 * r2[2] + g3 * r3[2],
    )
