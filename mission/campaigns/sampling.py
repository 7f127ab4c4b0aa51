"""Where the expert flies to gather data: the thesis's random waypoints (section 3.5.1).

x and y uniform in [-0.25, 0.25] m; two waypoints in three with z uniform in [0, 0.25] m,
the others in [0, 1.5] m. z is the centre of mass: a waypoint below resting-plus-margin
would press the vehicle into the ground, so it is raised to `min_altitude_m`.
"""

from __future__ import annotations

import random

from autopilot.commander.mission_items import Waypoint

MIN_ALTITUDE_M = 0.018  # the vehicle rests with its centre at 0.0126 m


def thesis_waypoints(
    seed: int,
    count: int,
    min_altitude_m: float = MIN_ALTITUDE_M,
    hold_s: float = 0.5,
    timeout_s: float = 4.0,
) -> tuple[Waypoint, ...]:
    rng = random.Random(seed)
    out = []
    for k in range(count):
        x, y = rng.uniform(-0.25, 0.25), rng.uniform(-0.25, 0.25)
        z = rng.uniform(0.0, 0.25) if k % 3 != 2 else rng.uniform(0.0, 1.5)
        out.append(
            Waypoint(
                (x, y, max(z, min_altitude_m)),
                acceptance_radius_m=0.03,
                hold_s=hold_s,
                timeout_s=timeout_s,
            )
        )
    return tuple(out)
