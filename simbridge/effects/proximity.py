"""Wall proximity: a lateral force toward (gain > 0) or away from a nearby wall.

Per horizontal direction u_k in which a wall lies at distance d_k (within `range_m`):

    f = gain * T * (R / 4 d)^2 * u_k,   d held at `min_distance_m` below it

the ground-effect law turned sideways: recirculation near a wall is strongest within a few
rotor radii and decays with the inverse square of the distance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simbridge.config import param

# World directions probed for walls: +x, -x, +y, -y.
WALL_DIRECTIONS = ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0))


@dataclass(frozen=True)
class WallEffectParams:
    gain: float = param(0.5, lo=-10.0, hi=10.0, doc="strength; > 0 pulls toward the wall")
    range_m: float = param(0.5, unit="m", lo=0.0, hi=5.0, lo_open=True, doc="probe distance")
    min_distance_m: float = param(
        0.02, unit="m", lo=0.0, hi=1.0, lo_open=True, doc="distance below which it is constant"
    )


def wall_force_n(
    params: WallEffectParams,
    total_thrust_n: float,
    rotor_radius_m: float,
    wall_distances_m: tuple[float, ...],
) -> tuple[float, float, float]:
    """The world-frame lateral force from walls at `wall_distances_m` along WALL_DIRECTIONS."""
    fx = fy = 0.0
    for (ux, uy, _), d in zip(WALL_DIRECTIONS, wall_distances_m, strict=True):
        if d > params.range_m:
            continue
        r = rotor_radius_m / (4.0 * max(d, params.min_distance_m))
        magnitude = params.gain * total_thrust_n * r * r
        fx += magnitude * ux
        fy += magnitude * uy
    return (fx, fy, 0.0)


def wall_force_array(
    params: WallEffectParams,
    total_thrust_n: np.ndarray,
    rotor_radius_m: float,
    wall_distances_m: np.ndarray,
) -> np.ndarray:
    """`wall_force_n` over a log: thrust (N,), distances (N, 4) -> world forces (N, 3)."""
    d = np.asarray(wall_distances_m, dtype=float)
    near = d <= params.range_m
    r = rotor_radius_m / (4.0 * np.maximum(np.where(near, d, 1.0), params.min_distance_m))
    magnitude = np.where(near, params.gain * r * r, 0.0) * np.asarray(total_thrust_n)[:, None]
    return magnitude @ np.asarray(WALL_DIRECTIONS)
