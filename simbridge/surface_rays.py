"""Vertical distances from points on the vehicle to the surfaces below (or above) them, with
rays cast only when the answer can have changed by more than moving the point says.

Every surface of a world is horizontal where a vertical ray meets it: the ground plane, the
tops and bottoms of boxes turned about z only, the ceiling slab. Over one surface a point's
height then changes exactly by its own vertical motion, and the surface below a point can
change only where its vertical line crosses the edge of a box's footprint. So after a cast,
each point keeps the distance cast plus its vertical motion for as long as it stays within
its safe radius (the horizontal distance from where it was cast to the nearest footprint
edge, less a margin for Bullet's fuzzy edges); a point that reaches it makes all rays cast
again, in one batch, on one thread. Over the open floor they are cast once. The answers are
those of rays cast at every step (the tests compare the two on a path past boxes).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from simbridge.pybullet_quiet import pybullet as pb

NO_HIT = math.inf
# Rays reach this far beyond their reach, so that a miss stays a miss while the point moves
# less than this vertically (then they are cast again). Not much further: Bullet's ray test
# on a box errs in proportion to the ray's length (5 um on a 1 km ray).
SLACK_M = 1.0
# Bullet's rays find a box's edge only to about a millimetre (they hit a floating box's
# underside from 0.8 mm outside it): within this of an edge, rays are cast every time.
EDGE_MARGIN_M = 0.01
Footprint = tuple[float, float, float, float, float, float]  # cx, cy, cos, sin, half x, y
Point = tuple[float, float, float]


def footprint(center_m: Sequence[float], size_m: Sequence[float], yaw_rad: float) -> Footprint:
    """A box's footprint on the horizontal plane."""
    return (
        center_m[0],
        center_m[1],
        math.cos(yaw_rad),
        math.sin(yaw_rad),
        size_m[0] / 2.0,
        size_m[1] / 2.0,
    )


def edge_distance_m(x: float, y: float, footprints: Sequence[Footprint]) -> float:
    """Horizontal distance from (x, y) to the nearest footprint edge; inf if there is none."""
    nearest = NO_HIT
    for cx, cy, c, s, hx, hy in footprints:
        dx, dy = x - cx, y - cy
        ax = abs(c * dx + s * dy) - hx
        ay = abs(-s * dx + c * dy) - hy
        inside = ax <= 0.0 and ay <= 0.0  # then to the nearer side
        d = min(-ax, -ay) if inside else math.hypot(max(ax, 0.0), max(ay, 0.0))
        nearest = min(nearest, d)
    return nearest


class VerticalRays:
    """Distances along vertical rays from points, down (sign -1) or up (+1); each reported
    only within its reach (NO_HIT beyond)."""

    def __init__(
        self,
        physics_client: int,
        footprints: Sequence[Footprint],
        signs: Sequence[int],
        reach_m: Sequence[float],
        collision_mask: int,
    ) -> None:
        self._cid, self._mask = physics_client, collision_mask
        self._footprints = tuple(footprints)
        self._signs, self._reach = tuple(signs), tuple(reach_m)
        self._cast_at: list[Point] = []
        self._levels: list[float] = []
        self._lengths = tuple(r + SLACK_M for r in self._reach)
        self._safe2: list[float] = []  # squared safe radius of each point
        # where the points' rigid body had its centre at the last cast, and how far that may
        # move with every point still inside its safe radius (squared; -1: not at all)
        self._centre_at: Point | None = None
        self._centre_safe2 = -1.0
        self._cast_z: list[float] = []
        self.casts = 0  # batches cast, for the benchmark

    def distances_about(self, centre: Point, heights_m: Sequence[float]) -> list[float] | None:
        """The distances of the points of the last cast made with a `centre`, now at world
        heights `heights_m` with their body's centre at `centre`, without their horizontal
        positions: known while the centre keeps within its safe radius (then so does every
        point, whichever way the body turned); None when they must be given (`distances`)."""
        c0 = self._centre_at
        if c0 is None:
            return None
        dx, dy = centre[0] - c0[0], centre[1] - c0[1]
        if dx * dx + dy * dy >= self._centre_safe2:
            return None
        if len(heights_m) == 4:  # a quadrotor's hubs, written out: asked at 1 kHz
            z0, z1, z2, z3 = heights_m
            c0, c1, c2, c3 = self._cast_z
            if (
                abs(z0 - c0) >= SLACK_M
                or abs(z1 - c1) >= SLACK_M
                or abs(z2 - c2) >= SLACK_M
                or abs(z3 - c3) >= SLACK_M
            ):
                return None
            l0, l1, l2, l3 = self._levels
            s0, s1, s2, s3 = self._signs
            r0, r1, r2, r3 = self._reach
            h0, h1, h2, h3 = s0 * (l0 - z0), s1 * (l1 - z1), s2 * (l2 - z2), s3 * (l3 - z3)
            return [
                NO_HIT if h0 > r0 else (h0 if h0 > 0.0 else 0.0),
                NO_HIT if h1 > r1 else (h1 if h1 > 0.0 else 0.0),
                NO_HIT if h2 > r2 else (h2 if h2 > 0.0 else 0.0),
                NO_HIT if h3 > r3 else (h3 if h3 > 0.0 else 0.0),
            ]
        out = []
        for z, z0, level, sign, reach in zip(  # noqa: B905 (lengths equal)
            heights_m, self._cast_z, self._levels, self._signs, self._reach
        ):
            if abs(z - z0) >= SLACK_M:
                return None
            h = sign * (level - z)
            out.append(NO_HIT if h > reach else (h if h > 0.0 else 0.0))
        return out

    def distances(
        self, points: Sequence[Point], centre: Point | None = None, span_m: float = 0.0
    ) -> list[float]:
        """The distances of `points`; with the `centre` of the rigid body they belong to (all
        within `span_m` of it), a cast here serves `distances_about` too."""
        if self._cast_at:
            out = []
            # one pass: still within its safe radius and the vertical slack, each point's
            # distance is its surface's level less its height (lengths equal by
            # construction; a strict zip costs a check per call on the hot path)
            for (x, y, z), (x0, y0, z0), level, sign, reach, r2 in zip(  # noqa: B905
                points, self._cast_at, self._levels, self._signs, self._reach, self._safe2
            ):
                dx, dy = x - x0, y - y0
                if dx * dx + dy * dy >= r2 or abs(z - z0) >= SLACK_M:
                    break
                h = sign * (level - z)
                out.append(NO_HIT if h > reach else (h if h > 0.0 else 0.0))
            else:
                return out
        self._cast(points, centre, span_m)
        out = []
        for (_, _, z), level, sign, reach in zip(  # noqa: B905
            points, self._levels, self._signs, self._reach
        ):
            h = sign * (level - z)
            out.append(NO_HIT if h > reach else (h if h > 0.0 else 0.0))
        return out

    def _cast(self, points: Sequence[Point], centre: Point | None, span_m: float) -> None:
        ends = [
            (x, y, z + sign * length)
            for (x, y, z), sign, length in zip(points, self._signs, self._lengths, strict=True)
        ]
        hits = pb.rayTestBatch(
            list(points),
            ends,
            numThreads=1,  # a handful of rays: threads cost more than they save
            collisionFilterMask=self._mask,
            physicsClientId=self._cid,
        )
        self._cast_at = list(points)
        # the level of the surface each ray met (+-inf: none within its length)
        self._levels = [
            z + sign * (h[2] * length if h[0] >= 0 else NO_HIT)
            for (_, _, z), h, sign, length in zip(
                points, hits, self._signs, self._lengths, strict=True
            )
        ]
        safe = [edge_distance_m(x, y, self._footprints) - EDGE_MARGIN_M for x, y, _ in points]
        # within the margin: cast again at every call there
        self._safe2 = [d * d if d > 0.0 else -1.0 for d in safe]
        # a point is within span_m of the centre, at the cast and later: the centre moving d
        # moves it at most d + 2 span_m from where it was cast
        self._centre_at = centre
        self._cast_z = [z for _, _, z in points]
        room = min(safe) - 2.0 * span_m
        self._centre_safe2 = room * room if centre is not None and room > 0.0 else -1.0
        self.casts += 1
