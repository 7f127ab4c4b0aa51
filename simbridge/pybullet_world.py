"""Building a world in PyBullet: its surfaces (ground plane, boxes, ceiling slab) and the
vehicle's body at its start pose. `Simulation` (physics.py) steps what this builds."""

from __future__ import annotations

import math
from dataclasses import dataclass

from simbridge.frames import Quat, Vec3, quat_from_euler, wxyz_to_xyzw
from simbridge.pybullet_quiet import pybullet as pb
from simbridge.surface_rays import Footprint, footprint
from simbridge.vehicle import GRAVITY_M_S2, Vehicle
from simbridge.world import World

WORLD_GROUP = 1  # collision group of the ground and obstacles: what rays see
VEHICLE_GROUP = 2
CEILING_SIZE_M = (1000.0, 1000.0)  # the ceiling slab's extent


def build_surfaces(cid: int, world: World, dt_s: float) -> list[int]:
    """Gravity, the step, and the world's surfaces; their body ids."""
    pb.setGravity(0.0, 0.0, -GRAVITY_M_S2, physicsClientId=cid)
    pb.setPhysicsEngineParameter(
        fixedTimeStep=dt_s, deterministicOverlappingPairs=1, physicsClientId=cid
    )
    plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=cid)
    surfaces = [pb.createMultiBody(0.0, plane, physicsClientId=cid)]
    for box in world.obstacles:
        half = [s / 2 for s in box.size_m]
        shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=cid)
        orn = wxyz_to_xyzw(quat_from_euler(0.0, 0.0, math.radians(box.yaw_deg)))
        surfaces.append(
            pb.createMultiBody(
                0.0, shape, basePosition=box.center_m, baseOrientation=orn, physicsClientId=cid
            )
        )
    if world.ceiling_height_m is not None:
        half = [CEILING_SIZE_M[0] / 2, CEILING_SIZE_M[1] / 2, 0.05]
        slab = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=cid)
        surfaces.append(
            pb.createMultiBody(
                0.0,
                slab,
                basePosition=[0.0, 0.0, world.ceiling_height_m + 0.05],
                physicsClientId=cid,
            )
        )
    for uid in surfaces:
        # Surfaces accept every mask, so that rays (of the default group) see them.
        pb.setCollisionFilterGroupMask(uid, -1, WORLD_GROUP, 0xFFFF, physicsClientId=cid)
        pb.changeDynamics(
            uid, -1, lateralFriction=world.ground_friction, restitution=0.0, physicsClientId=cid
        )
    return surfaces


def surface_footprints(world: World) -> list[Footprint]:
    """The footprints of the world's boxes and ceiling slab (the ground has no edge)."""
    prints = [footprint(b.center_m, b.size_m, math.radians(b.yaw_deg)) for b in world.obstacles]
    if world.ceiling_height_m is not None:
        prints.append(footprint((0.0, 0.0), CEILING_SIZE_M, 0.0))
    return prints


@dataclass(frozen=True)
class Body:
    body_id: int
    resting_height_m: float  # of the centre of mass over the surface below the start point
    position_m: Vec3  # the start pose
    quaternion: Quat


def build_body(cid: int, world: World, vehicle: Vehicle, true_mass_kg: float) -> Body:
    """The vehicle's box at the world's start pose: resting on the surface below its start
    point unless started in the air."""
    start = world.start
    half = [s / 2 for s in vehicle.body_size_m]
    shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=cid)
    body = pb.createMultiBody(true_mass_kg, shape, physicsClientId=cid)
    scale = true_mass_kg / vehicle.mass_kg  # uniform density: inertia scales with mass
    pb.changeDynamics(
        body,
        -1,
        linearDamping=0.0,
        angularDamping=0.0,
        restitution=0.0,
        lateralFriction=world.ground_friction,
        localInertiaDiagonal=[i * scale for i in vehicle.inertia_kg_m2],
        physicsClientId=cid,
    )
    pb.setCollisionFilterGroupMask(body, -1, VEHICLE_GROUP, WORLD_GROUP, physicsClientId=cid)
    x, y = start.xy_m
    ceiling = world.ceiling_height_m
    top = 1000.0 if ceiling is None else ceiling - 1e-3  # under a ceiling, not on it
    hit = pb.rayTest(
        [x, y, top], [x, y, -1.0], collisionFilterMask=WORLD_GROUP, physicsClientId=cid
    )[0]
    resting = (hit[3][2] if hit[0] >= 0 else 0.0) + half[2]
    z = start.altitude_m if start.altitude_m is not None else resting
    quaternion = quat_from_euler(
        math.radians(start.roll_deg), math.radians(start.pitch_deg), math.radians(start.yaw_deg)
    )
    position: Vec3 = (x, y, z)
    pb.resetBasePositionAndOrientation(
        body, position, wxyz_to_xyzw(quaternion), physicsClientId=cid
    )
    return Body(body, resting, position, quaternion)
