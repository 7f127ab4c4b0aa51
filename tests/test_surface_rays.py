"""Rays cast only when needed give the answers of rays cast at every step."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simbridge.physics import Simulation
from simbridge.pybullet_quiet import pybullet as pb
from simbridge.surface_rays import NO_HIT, SLACK_M, VerticalRays, edge_distance_m, footprint
from simbridge.vehicle import load_vehicle
from simbridge.world import Box, load_world

BOXES = (
    Box(center_m=(0.4, 0.0, 0.05), size_m=(0.3, 0.2, 0.1), yaw_deg=0.0),
    Box(center_m=(0.9, 0.1, 0.15), size_m=(0.25, 0.25, 0.3), yaw_deg=35.0),
    Box(center_m=(0.65, -0.4, 0.6), size_m=(0.4, 0.4, 0.05), yaw_deg=-20.0),  # floating
)


def _every_step(cid: int, points: list, signs: list, reach: list) -> list[float]:
    """Rays of the same length cast at every step (Bullet's hits near a box's edge depend a
    little on the ray's length)."""
    lengths = [r + SLACK_M for r in reach]
    ends = [(x, y, z + s * n) for (x, y, z), s, n in zip(points, signs, lengths, strict=True)]
    hits = pb.rayTestBatch(points, ends, collisionFilterMask=1, physicsClientId=cid)
    out = []
    for h, n, r in zip(hits, lengths, reach, strict=True):
        d = h[2] * n if h[0] >= 0 else NO_HIT
        out.append(NO_HIT if d > r else d)
    return out


def test_cached_rays_match_rays_cast_every_step_past_box_edges() -> None:
    import dataclasses

    world = dataclasses.replace(load_world("default"), obstacles=BOXES)
    with Simulation(world, load_vehicle(world.vehicle)) as sim:
        cid = sim._cid
        prints = [footprint(b.center_m, b.size_m, math.radians(b.yaw_deg)) for b in BOXES]
        signs, reach = [-1, -1, 1, -1], [0.5, 0.5, 1.0, 0.5]
        rays = VerticalRays(cid, prints, signs, reach, 1)
        steps = 3000
        for k in range(steps):
            t = k / steps
            # a path over the floor, across the boxes' edges, climbing and sinking
            x, y = -0.1 + 1.3 * t, 0.25 * math.sin(7.0 * t)
            z = 0.35 + 0.2 * math.sin(11.0 * t) + (SLACK_M if t > 0.9 else 0.0)
            points = [(x, y, z), (x + 0.03, y - 0.03, z - 0.01), (x, y, z), (x - 0.04, y, z)]
            got = rays.distances(points)
            want = _every_step(cid, points, signs, reach)
            # within 10 um (Bullet's own ray error on a box is some um), a hundredth of
            # the range sensor's resolution
            np.testing.assert_allclose(got, want, atol=1e-5, rtol=0)
        # the edges crossed made it cast again, but far from every step
        assert 10 < rays.casts < steps / 3


def _turning_body_path(boxes: tuple[Box, ...]) -> tuple[int, int, int]:
    """Four hubs of a rigid body that moves and turns along a path past `boxes`, their
    distances from `distances_about` where it knows them, checked against rays cast at every
    step; returns (steps, steps known from heights alone, casts)."""
    import dataclasses

    world = dataclasses.replace(load_world("default"), obstacles=boxes)
    with Simulation(world, load_vehicle(world.vehicle)) as sim:
        cid = sim._cid
        prints = [footprint(b.center_m, b.size_m, math.radians(b.yaw_deg)) for b in boxes]
        signs, reach = [-1] * 4, [0.5] * 4
        rays = VerticalRays(cid, prints, signs, reach, 1)
        arm = 0.05
        steps, known = 3000, 0
        for k in range(steps):
            t = k / steps
            centre = (-0.1 + 1.3 * t, 0.25 * math.sin(7.0 * t), 0.35 + 0.2 * math.sin(11.0 * t))
            yaw, tilt = 9.0 * t, 0.3 * math.sin(13.0 * t)  # turning and rolling
            hubs = []
            for i in range(4):
                a = yaw + i * math.pi / 2.0
                hubs.append((
                    centre[0] + arm * math.cos(a) * math.cos(tilt),
                    centre[1] + arm * math.sin(a) * math.cos(tilt),
                    centre[2] + arm * math.sin(tilt) * (1.0 if i % 2 else -1.0),
                ))  # fmt: skip
            got = rays.distances_about(centre, [z for _, _, z in hubs])
            if got is None:
                got = rays.distances(hubs, centre, arm)
            else:
                known += 1
            want = _every_step(cid, hubs, signs, reach)
            np.testing.assert_allclose(got, want, atol=1e-5, rtol=0)
        return steps, known, rays.casts


def test_heights_about_a_turning_body_match_rays_cast_every_step() -> None:
    """The physics step's path: hub heights alone, while the centre keeps to its safe radius."""
    steps, known, casts = _turning_body_path(BOXES)
    assert known > 0 and 10 < casts < steps / 3
    # over an open floor: one cast, then heights alone
    steps, known, casts = _turning_body_path(())
    assert (known, casts) == (steps - 1, 1)


def test_edge_distance_inside_and_outside_a_turned_box() -> None:
    fp = [footprint((1.0, 0.0), (2.0, 1.0), math.radians(90.0))]  # 1 m along x, 2 m along y
    assert edge_distance_m(1.0, 0.0, fp) == pytest.approx(0.5)
    assert edge_distance_m(1.0, 0.8, fp) == pytest.approx(0.2)
    assert edge_distance_m(2.5, 0.0, fp) == pytest.approx(1.0)
    assert edge_distance_m(2.5, 2.0, fp) == pytest.approx(math.hypot(1.0, 1.0))
    assert edge_distance_m(0.0, 0.0, []) == math.inf
