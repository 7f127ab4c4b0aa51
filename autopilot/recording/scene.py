"""The static 3-D scene of a recording: ground, obstacles, the drone's body and the mission.

Pure geometry from the world file, the vehicle file and the mission; the recorder logs it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import rerun as rr

from autopilot.commander.mission_items import PlanStep
from learner.flightlogs.recording import (
    DRONE_ARMS,
    DRONE_BODY,
    DRONE_ROTORS,
    GROUND,
    MISSION_LABELS,
    MISSION_PATH,
    OBSTACLES,
    WAYPOINTS,
    WORLD,
)
from simbridge.frames import Vec3
from simbridge.vehicle import Vehicle
from simbridge.world import Box

GROUND_MARGIN_M = 0.5  # the ground slab reaches this far beyond everything in the scene
GROUND_THICKNESS_M = 0.01
ROTOR_DISC_SEGMENTS = 24
COLOR_GROUND = (205, 205, 195, 200)  # light and a little translucent: the scene reads over it
COLOR_OBSTACLE = (150, 110, 70)
COLOR_BODY = (40, 40, 40)
COLOR_FRONT_ROTOR = (220, 60, 60)  # so that the heading reads at a glance
COLOR_BACK_ROTOR = (170, 170, 170)
COLOR_MISSION = (80, 160, 255)
LABEL_LIFT_M = 0.15  # mission labels at least this far above their points ...
LABEL_LIFT_SHARE = 0.25  # ... or this share of the mission's height, whichever is more


def surface_height_m(x: float, y: float, boxes: Sequence[Box]) -> float:
    """The height of the highest surface under (x, y): the ground (0) or a box's top."""
    top = 0.0
    for box in boxes:
        yaw = math.radians(box.yaw_deg)
        dx, dy = x - box.center_m[0], y - box.center_m[1]
        u = math.cos(yaw) * dx + math.sin(yaw) * dy  # (x, y) in the box's frame
        v = -math.sin(yaw) * dx + math.cos(yaw) * dy
        if abs(u) <= box.size_m[0] / 2 and abs(v) <= box.size_m[1] / 2:
            top = max(top, box.center_m[2] + box.size_m[2] / 2)
    return top


def log_world(rec: rr.RecordingStream, boxes: Sequence[Box], extent_m: Sequence[Vec3]) -> None:
    """World axes, a ground slab under everything in `extent_m`, and the obstacles."""
    rec.log(WORLD, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    corners = [p[:2] for p in extent_m]
    for box in boxes:
        reach = math.hypot(box.size_m[0], box.size_m[1]) / 2
        corners += [
            (box.center_m[0] - reach, box.center_m[1] - reach),
            (box.center_m[0] + reach, box.center_m[1] + reach),
        ]
    xy = np.asarray(corners or [(0.0, 0.0)], dtype=float)
    low, high = xy.min(axis=0) - GROUND_MARGIN_M, xy.max(axis=0) + GROUND_MARGIN_M
    rec.log(
        GROUND,
        rr.Boxes3D(
            centers=[((low[0] + high[0]) / 2, (low[1] + high[1]) / 2, -GROUND_THICKNESS_M / 2)],
            half_sizes=[((high[0] - low[0]) / 2, (high[1] - low[1]) / 2, GROUND_THICKNESS_M / 2)],
            colors=[COLOR_GROUND],
            fill_mode="solid",
        ),
        static=True,
    )
    if boxes:
        rec.log(
            OBSTACLES,
            rr.Boxes3D(
                centers=[b.center_m for b in boxes],
                half_sizes=[tuple(s / 2 for s in b.size_m) for b in boxes],
                rotation_axis_angles=[
                    rr.RotationAxisAngle(axis=(0, 0, 1), degrees=b.yaw_deg) for b in boxes
                ],
                colors=[COLOR_OBSTACLE] * len(boxes),
                fill_mode="solid",
            ),
            static=True,
        )


def log_drone(rec: rr.RecordingStream, vehicle: Vehicle) -> None:
    """The body box, arms and rotor discs in the body frame (x forward, y left, z up)."""
    rec.log(
        DRONE_BODY,
        rr.Boxes3D(
            half_sizes=[tuple(s / 2 for s in vehicle.body_size_m)],
            colors=[COLOR_BODY],
            fill_mode="solid",
        ),
        static=True,
    )
    hubs = vehicle.rotor_positions_body_m()
    rec.log(
        DRONE_ARMS,
        rr.LineStrips3D([[(0.0, 0.0, h[2]), h] for h in hubs], colors=[COLOR_BODY], radii=0.003),
        static=True,
    )
    angles = np.linspace(0.0, 2.0 * math.pi, ROTOR_DISC_SEGMENTS + 1)
    r = vehicle.rotor_radius_m
    discs = [
        np.column_stack(
            (h[0] + r * np.cos(angles), h[1] + r * np.sin(angles), np.full_like(angles, h[2]))
        )
        for h in hubs
    ]
    colors = [COLOR_FRONT_ROTOR if h[0] > 0 else COLOR_BACK_ROTOR for h in hubs]
    rec.log(
        DRONE_ROTORS,
        # the rotors' numbers on hovering (shown, they would cover the drone at a distance)
        rr.LineStrips3D(
            discs, colors=colors, labels=[str(i) for i in range(len(hubs))], show_labels=False
        ),
        static=True,
    )


def mission_path(
    plan: Sequence[PlanStep], start_m: Vec3, home_m: Vec3 | None, boxes: Sequence[Box]
) -> tuple[list[Vec3], list[str], list[Vec3]]:
    """The plan drawn from where the vehicle is: (item points, their labels, the path).

    A take-off climbs above the point it starts from, a landing ends on the surface below
    (its own position, or where the vehicle is), a return goes home and lands there.
    """
    home = home_m if home_m is not None else start_m
    here = start_m
    points: list[Vec3] = []
    labels: list[str] = []
    path = [start_m]
    for step in plan:
        if step.kind == "takeoff":
            here = (here[0], here[1], home[2] + step.altitude_m)
        elif step.kind == "waypoint" and step.position_m is not None:
            here = step.position_m
        elif step.kind in ("land", "return"):
            x, y = home[:2] if step.kind == "return" else (step.position_m or here)[:2]
            if step.kind == "return":
                path.append((x, y, here[2]))
            here = (x, y, surface_height_m(x, y, boxes))
        else:
            continue
        points.append(here)
        labels.append(f"{step.kind} {step.seq}")
        path.append(here)
    return points, labels, path


def merged_points(
    points: Sequence[Vec3], labels: Sequence[str], within_m: float = 0.05
) -> tuple[list[Vec3], list[str]]:
    """Items at one place drawn as one point with one label ("takeoff 0, waypoint 4"): labels
    drawn on top of each other cannot be read."""
    out_points: list[Vec3] = []
    out_labels: list[str] = []
    for p, label in zip(points, labels, strict=True):
        for i, q in enumerate(out_points):
            if max(abs(a - b) for a, b in zip(p, q, strict=True)) <= within_m:
                out_labels[i] += f", {label}"
                break
        else:
            out_points.append(p)
            out_labels.append(label)
    return out_points, out_labels


def log_mission(
    rec: rr.RecordingStream, points: Sequence[Vec3], labels: Sequence[str], path: Sequence[Vec3]
) -> None:
    """Waypoints with labels and the planned path, at the current time (a new mission
    replaces the old one)."""
    shown, text = merged_points(points, labels)
    rec.log(WAYPOINTS, rr.Points3D(shown, radii=0.01, colors=[COLOR_MISSION]))
    # the labels above their points: at the point, the landing's would cover the vehicle
    # standing there (10 cm across, small in a view framed on the whole mission)
    heights = [z for _, _, z in shown] or [0.0]
    lift = max(LABEL_LIFT_M, LABEL_LIFT_SHARE * (max(heights) - min(heights)))
    lifted = [(x, y, z + lift) for x, y, z in shown]
    rec.log(MISSION_LABELS, rr.Points3D(lifted, radii=0.0, colors=[COLOR_MISSION], labels=text))
    rec.log(MISSION_PATH, rr.LineStrips3D([list(path)], colors=[COLOR_MISSION], radii=0.002))
