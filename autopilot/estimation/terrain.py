"""PX4's terrain estimator, as a pure update: the height of the surface under the vehicle.

One state and its variance. The surface is a random walk of TERRAIN_SLOPE per metre flown;
each measurement (the estimated altitude less a range reading, or less the resting height
while the vehicle stands) corrects it. An innovation beyond GATE_SD standard deviations is a
new surface (a box, a step): the estimate starts over from it.
"""

from __future__ import annotations

from dataclasses import dataclass

TERRAIN_SLOPE = 0.005  # m of surface height change per m flown, as the terrain's process noise
GATE_SD = 5.0


@dataclass(frozen=True)
class Terrain:
    height_m: float = 0.0  # world z of the surface below
    variance_m2: float = 1.0
    time_us: int = 0  # of the last update; 0: none yet


def terrain_update(
    terrain: Terrain, measured_m: float, variance_m2: float, speed_m_s: float, time_us: int
) -> tuple[Terrain, bool]:
    """The terrain after one measurement of its height (with its variance), the vehicle moving
    at `speed_m_s` horizontally; and whether it started over on a new surface."""
    flown_m = speed_m_s * (time_us - terrain.time_us) * 1e-6 if terrain.time_us else 0.0
    prior = terrain.variance_m2 + (TERRAIN_SLOPE * flown_m) ** 2 + 1e-12
    innovation = measured_m - terrain.height_m
    if innovation * innovation > GATE_SD * GATE_SD * (prior + variance_m2):
        return Terrain(measured_m, variance_m2, time_us), True
    gain = prior / (prior + variance_m2)
    return Terrain(terrain.height_m + gain * innovation, prior * (1.0 - gain), time_us), False
