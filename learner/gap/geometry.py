"""Distances from logged positions to the nominal world's surfaces, as the simulator's rays
measure them: down to the ground plane or a box top, up to the ceiling, sideways to walls.

Pure numpy over arrays of points; boxes are the world's (yawed) obstacles.
"""

from __future__ import annotations

import math

import numpy as np

from simbridge.effects.proximity import WALL_DIRECTIONS
from simbridge.world import Box


def _local(points: np.ndarray, box: Box) -> np.ndarray:
    """Points in the box's frame (centre at the origin, axes along its sides)."""
    c, s = math.cos(math.radians(box.yaw_deg)), math.sin(math.radians(box.yaw_deg))
    d = points - np.asarray(box.center_m)
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])


def height_below_m(points: np.ndarray, boxes: tuple[Box, ...], ray_length_m: float) -> np.ndarray:
    """Distance straight down to the ground plane z = 0 or a box top; inf beyond the ray."""
    h = points[:, 2].copy()
    for box in boxes:
        local = _local(points, box)
        hx, hy, hz = (s / 2.0 for s in box.size_m)
        over = (np.abs(local[:, 0]) <= hx) & (np.abs(local[:, 1]) <= hy) & (local[:, 2] >= hz)
        h = np.where(over, np.minimum(h, local[:, 2] - hz), h)
    return np.where((h >= 0.0) & (h <= ray_length_m), h, np.inf)


def distance_above_m(
    points: np.ndarray, ceiling_height_m: float | None, ray_length_m: float
) -> np.ndarray:
    """Distance straight up to the ceiling; inf without one or beyond the ray."""
    if ceiling_height_m is None:
        return np.full(len(points), np.inf)
    d = ceiling_height_m - points[:, 2]
    return np.where((d >= 0.0) & (d <= ray_length_m), d, np.inf)


def wall_distances_m(points: np.ndarray, boxes: tuple[Box, ...], range_m: float) -> np.ndarray:
    """(N, 4) distances along WALL_DIRECTIONS (+x, -x, +y, -y) to the nearest box; inf beyond
    `range_m`."""
    out = np.full((len(points), len(WALL_DIRECTIONS)), np.inf)
    for box in boxes:
        local = _local(points, box)
        half = np.asarray(box.size_m) / 2.0
        level = np.abs(local[:, 2]) <= half[2]
        c, s = math.cos(math.radians(box.yaw_deg)), math.sin(math.radians(box.yaw_deg))
        for k, (ux, uy, _) in enumerate(WALL_DIRECTIONS):
            u = np.array([c * ux + s * uy, -s * ux + c * uy])
            t_in = np.full(len(points), -np.inf)
            t_out = np.full(len(points), np.inf)
            for axis in range(2):
                if abs(u[axis]) < 1e-12:
                    inside = np.abs(local[:, axis]) <= half[axis]
                    t_in = np.where(inside, t_in, np.inf)
                    continue
                t1 = (-half[axis] - local[:, axis]) / u[axis]
                t2 = (half[axis] - local[:, axis]) / u[axis]
                t_in = np.maximum(t_in, np.minimum(t1, t2))
                t_out = np.minimum(t_out, np.maximum(t1, t2))
            hit = level & (t_in <= t_out) & (t_out >= 0.0)
            d = np.where(hit, np.maximum(t_in, 0.0), np.inf)
            out[:, k] = np.minimum(out[:, k], d)
    return np.where(out <= range_m, out, np.inf)
