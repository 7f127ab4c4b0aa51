"""The PyBullet world: rigid-body dynamics of the vehicle with the world's physical effects.

This is the edge where the pure effect functions meet PyBullet. Each physics step reads the
body's state, ray-tests the surfaces around the rotors, sums rotor thrust (equations 3.5,
3.6) and every enabled effect into one world-frame force and torque at the centre of mass,
and steps. Plain floats and tuples on the hot path: numpy costs more than it saves at n = 4.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from simbridge.effects.actuators import motor_lag_step, thrust_axis_body
from simbridge.effects.drag import body_drag_n, rotor_drag_n, wind_velocity_m_s
from simbridge.effects.ground import ground_effect_force_n, thrust_gain
from simbridge.effects.learned import learned_force_n
from simbridge.effects.proximity import WALL_DIRECTIONS, wall_force_n
from simbridge.effects.uncatalogued import (
    TAKEOFF_HEIGHT_M,
    asymmetric_forces_n,
    exponential_gain,
    outwash_force_n,
    thrust_decay_scale,
)
from simbridge.frames import Quat, Vec3, quat_from_euler, wxyz_to_xyzw, xyzw_to_wxyz
from simbridge.pybullet_quiet import pybullet as pb
from simbridge.rotors import Quad, rotor_forces_n, thrust_and_moments
from simbridge.vehicle import GRAVITY_M_S2, Vehicle
from simbridge.world import World

WORLD_GROUP = 1  # collision group of the ground and obstacles: what rays see
VEHICLE_GROUP = 2
NO_HIT = math.inf
LEARNED_RAY_M = 3.0  # a learnt residual's height rays: beyond, its feature is capped anyway


@dataclass(frozen=True)
class VehicleState:
    """The true state after a control step (world x east, y north, z up; body FLU)."""

    time_s: float
    position_m: Vec3
    quaternion: Quat  # (w, x, y, z), body to world
    velocity_m_s: Vec3  # world frame
    angular_velocity_body_rad_s: Vec3  # body frame
    acceleration_m_s2: Vec3  # world frame, mean over the last control period
    rotor_speeds_rad_s: Quad  # actual (after motor lag)
    range_m: float  # downward range sensor: distance along body -z to a surface, inf if none


@dataclass(frozen=True)
class EffectForces:
    """The true effect forces of the last physics step, world frame unless stated."""

    rotor_heights_m: Quad  # height of each rotor above the surface below it (inf: none)
    ground_effect_rotor_n: Quad  # equation 3.4 per rotor, vertical
    ground_effect_n: Vec3
    ceiling_effect_n: Vec3
    wall_effect_n: Vec3
    drag_n: Vec3  # rotor drag + body drag
    wind_m_s: Vec3
    learned_n: Vec3 = (0.0, 0.0, 0.0)  # a gap diagnosis's learnt residual
    # outside the catalogue (simbridge/effects/uncatalogued.py)
    ground_effect_exponential_n: Vec3 = (0.0, 0.0, 0.0)
    outwash_n: Vec3 = (0.0, 0.0, 0.0)
    thrust_scale: float = 1.0  # thrust_decay's C_T scale


def _zero3() -> list[float]:
    return [0.0, 0.0, 0.0]


class Simulation:
    """One vehicle in one PyBullet world, stepped one control period at a time."""

    def __init__(self, world: World, vehicle: Vehicle, *, held: bool = False) -> None:
        self.world, self.vehicle = world, vehicle
        fx = world.effects
        self._cid = pb.connect(pb.DIRECT)
        self._dt = world.physics_dt_s
        self._time_us = 0
        self.held = held  # on a stand at the start pose until released (see HIL link)
        self._build_world()

        # Effective physical constants of the simulated (true) vehicle.
        self._c_t = vehicle.thrust_coefficient_n_s2 * (
            fx.thrust_coefficient.scale if fx.thrust_coefficient else 1.0
        )
        self.true_mass_kg = vehicle.mass_kg * (fx.mass_error.scale if fx.mass_error else 1.0)
        self._rotors_body = vehicle.rotor_positions_body_m()
        self._arm, self._kz = vehicle.arm_m, vehicle.yaw_moment_coefficient_m
        self._radius = vehicle.rotor_radius_m
        self._ge = fx.ground_effect
        self._ge_cutoff = self._ge.cutoff_for(self._radius) if self._ge else 0.0
        self._ce = fx.ceiling_effect
        self._ce_cutoff = self._ce.cutoff_for(self._radius) if self._ce else 0.0
        self._lag_tau = fx.motor_lag.time_constant_s if fx.motor_lag else None
        # the thrust's direction in the body frame (body z unless it leans)
        self._axis = (
            thrust_axis_body(*fx.thrust_tilt.lean_deg) if fx.thrust_tilt else (0.0, 0.0, 1.0)
        )
        self._drag = fx.rotor_drag is not None or fx.body_drag is not None
        self._learned = fx.learned_residual
        self._learned_force = _zero3()
        self._gex, self._outwash = fx.ground_effect_exponential, fx.ground_outwash
        self._gex_force, self._outwash_force = _zero3(), _zero3()
        self._decay, self._asym = fx.thrust_decay, fx.rotor_asymmetry
        self._thrust_scale = 1.0
        # one set of down rays per rotor serves every effect that reads rotor heights
        lengths = [e.ray_length_m for e in (self._ge, self._gex) if e is not None]
        self._down_m = max(lengths + ([LEARNED_RAY_M] if self._learned else []), default=None)
        self._lift_off_us: int | None = None  # see time_since_takeoff_s
        self._build_vehicle()

        self._rotor_speeds: list[float] = [0.0, 0.0, 0.0, 0.0]
        self._heights: list[float] = [NO_HIT] * 4
        self._ge_rotor: list[float] = [0.0] * 4
        self._ge_force, self._ce_force = _zero3(), _zero3()
        self._wall_force, self._drag_force, self._wind = _zero3(), _zero3(), _zero3()
        self._acceleration: Vec3 = (0.0, 0.0, 0.0)

    # -- construction -------------------------------------------------------------------

    def _build_world(self) -> None:
        cid, w = self._cid, self.world
        pb.setGravity(0.0, 0.0, -GRAVITY_M_S2, physicsClientId=cid)
        pb.setPhysicsEngineParameter(
            fixedTimeStep=self._dt, deterministicOverlappingPairs=1, physicsClientId=cid
        )
        plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=cid)
        self._surfaces = [pb.createMultiBody(0.0, plane, physicsClientId=cid)]
        for box in w.obstacles:
            half = [s / 2 for s in box.size_m]
            shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=cid)
            orn = wxyz_to_xyzw(quat_from_euler(0.0, 0.0, math.radians(box.yaw_deg)))
            self._surfaces.append(
                pb.createMultiBody(
                    0.0, shape, basePosition=box.center_m, baseOrientation=orn, physicsClientId=cid
                )
            )
        if w.ceiling_height_m is not None:
            slab = pb.createCollisionShape(
                pb.GEOM_BOX, halfExtents=[500.0, 500.0, 0.05], physicsClientId=cid
            )
            self._surfaces.append(
                pb.createMultiBody(
                    0.0,
                    slab,
                    basePosition=[0.0, 0.0, w.ceiling_height_m + 0.05],
                    physicsClientId=cid,
                )
            )
        for uid in self._surfaces:
            # Surfaces accept every mask, so that rays (of the default group) see them.
            pb.setCollisionFilterGroupMask(uid, -1, WORLD_GROUP, 0xFFFF, physicsClientId=cid)
            pb.changeDynamics(
                uid, -1, lateralFriction=w.ground_friction, restitution=0.0, physicsClientId=cid
            )

    def _build_vehicle(self) -> None:
        cid, v, start = self._cid, self.vehicle, self.world.start
        half = [s / 2 for s in v.body_size_m]
        shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=cid)
        self._body = pb.createMultiBody(self.true_mass_kg, shape, physicsClientId=cid)
        scale = self.true_mass_kg / v.mass_kg  # uniform density: inertia scales with mass
        pb.changeDynamics(
            self._body,
            -1,
            linearDamping=0.0,
            angularDamping=0.0,
            restitution=0.0,
            lateralFriction=self.world.ground_friction,
            localInertiaDiagonal=[i * scale for i in v.inertia_kg_m2],
            physicsClientId=cid,
        )
        pb.setCollisionFilterGroupMask(
            self._body, -1, VEHICLE_GROUP, WORLD_GROUP, physicsClientId=cid
        )
        x, y = start.xy_m
        # the surface below the start point: the vehicle rests there unless started in the air
        ceiling = self.world.ceiling_height_m
        top = 1000.0 if ceiling is None else ceiling - 1e-3  # under a ceiling, not on it
        hit = pb.rayTest(
            [x, y, top], [x, y, -1.0], collisionFilterMask=WORLD_GROUP, physicsClientId=cid
        )[0]
        self.resting_height_m = (hit[3][2] if hit[0] >= 0 else 0.0) + half[2]
        z = start.altitude_m if start.altitude_m is not None else self.resting_height_m
        self.start_quaternion = quat_from_euler(
            math.radians(start.roll_deg), math.radians(start.pitch_deg), math.radians(start.yaw_deg)
        )
        self.start_position_m: Vec3 = (x, y, z)
        pb.resetBasePositionAndOrientation(
            self._body,
            self.start_position_m,
            wxyz_to_xyzw(self.start_quaternion),
            physicsClientId=cid,
        )

    # -- stepping -----------------------------------------------------------------------

    @property
    def time_us(self) -> int:
        return self._time_us

    @property
    def time_s(self) -> float:
        return self._time_us * 1e-6

    @property
    def time_since_takeoff_s(self) -> float:
        """Time since the first physics step at which the body was more than 5 mm above its
        resting height over the start point (at once for a start in the air); 0 before."""
        if self._lift_off_us is None:
            return 0.0
        return (self._time_us - self._lift_off_us) * 1e-6

    def release(self) -> None:
        """Take the vehicle off its stand: from now on physics integrates it."""
        self.held = False

    def step(self, rotor_commands_rad_s: Quad) -> None:
        """Advance one control period with the rotor speed commands held constant."""
        world = self.world
        if self.held:
            self._time_us += world.control_period_us
            self._acceleration = (0.0, 0.0, 0.0)
            return
        v0, _ = pb.getBaseVelocity(self._body, physicsClientId=self._cid)
        for _ in range(world.substeps):
            self._substep(rotor_commands_rad_s)
        v1, _ = pb.getBaseVelocity(self._body, physicsClientId=self._cid)
        inv = 1.0 / world.control_period_s
        self._acceleration = ((v1[0] - v0[0]) * inv, (v1[1] - v0[1]) * inv, (v1[2] - v0[2]) * inv)
        self._time_us += world.control_period_us

    def _substep(self, cmd: Quad) -> None:
        cid, body, dt = self._cid, self._body, self._dt
        pos, orn = pb.getBasePositionAndOrientation(body, physicsClientId=cid)
        m = pb.getMatrixFromQuaternion(orn)
        if self._lift_off_us is None and pos[2] > self.resting_height_m + TAKEOFF_HEIGHT_M:
            self._lift_off_us = self._time_us
        n = self._rotor_speeds
        if self._lag_tau is None:
            n[0], n[1], n[2], n[3] = cmd
        else:
            tau = self._lag_tau
            for i in range(4):
                n[i] = motor_lag_step(n[i], cmd[i], dt, tau)
        if self._decay is None:
            f = rotor_forces_n(self._c_t, n)  # equation 3.5
        else:
            self._thrust_scale = thrust_decay_scale(self._decay, self.time_since_takeoff_s)
            f = rotor_forces_n(self._c_t * self._thrust_scale, n)
        if self._asym is not None:
            f = asymmetric_forces_n(self._asym, f)

        # Rotor hubs relative to the centre of mass, in the world frame.
        offsets = [
            (
                m[0] * rx + m[1] * ry + m[2] * rz,
                m[3] * rx + m[4] * ry + m[5] * rz,
                m[6] * rx + m[7] * ry + m[8] * rz,
            )
            for rx, ry, rz in self._rotors_body
        ]
        heights, ceilings, walls, below = self._ray_tests(pos, offsets)

        # Equation 3.6 in the body frame, ceiling effect as extra thrust on each rotor.
        if self._ce is not None:
            rho, radius, cut = self._ce.rho, self._radius, self._ce_cutoff
            boosted = [
                fi * (1.0 + thrust_gain(d, rho, radius, cut))
                for fi, d in zip(f, ceilings, strict=True)
            ]
            extra = sum(boosted) - sum(f)
            self._ce_force[:] = (m[2] * extra, m[5] * extra, m[8] * extra)
            f = boosted
        thrust, mx, my, mz = thrust_and_moments(f, self._arm, self._kz)  # equation 3.6, body
        ax, ay, az = self._axis
        force = [
            (m[0] * ax + m[1] * ay + m[2] * az) * thrust,
            (m[3] * ax + m[4] * ay + m[5] * az) * thrust,
            (m[6] * ax + m[7] * ay + m[8] * az) * thrust,
        ]
        torque = [
            m[0] * mx + m[1] * my + m[2] * mz,
            m[3] * mx + m[4] * my + m[5] * mz,
            m[6] * mx + m[7] * my + m[8] * mz,
        ]

        if self._ge is not None:  # equation 3.4: vertical, at each rotor hub
            rho, radius, cut = self._ge.rho, self._radius, self._ge_cutoff
            total = 0.0
            reach = self._ge.ray_length_m  # the rays may reach further for another effect
            for i in range(4):
                h = heights[i] if heights[i] <= reach else NO_HIT
                g = ground_effect_force_n(f[i], h, rho, radius, cut)
                self._ge_rotor[i] = g
                total += g
                torque[0] += offsets[i][1] * g
                torque[1] -= offsets[i][0] * g
            force[2] += total
            self._ge_force[2] = total
        if self._gex is not None:  # the exponential shape, vertical at each hub likewise
            gain, decay, reach = (
                self._gex.gain,
                self._gex.decay_radii * self._radius,
                self._gex.ray_length_m,
            )
            total = 0.0
            for i in range(4):
                h = heights[i]
                g = f[i] * exponential_gain(h, gain, decay) if h <= reach else 0.0
                total += g
                torque[0] += offsets[i][1] * g
                torque[1] -= offsets[i][0] * g
            force[2] += total
            self._gex_force[2] = total
        self._heights = heights

        fx = self.world.effects
        if fx.wall_effect is not None:
            wf = wall_force_n(fx.wall_effect, thrust, self._radius, walls)
            force[0] += wf[0]
            force[1] += wf[1]
            self._wall_force[:] = wf
        if self._outwash is not None:
            ow = outwash_force_n(self._outwash, thrust, below, self._radius)
            force[0] += ow[0]
            force[1] += ow[1]
            self._outwash_force[:] = ow
        if self._drag:
            self._apply_drag(force, m, n)
        if self._learned is not None:
            self._apply_learned(force, m, f, heights)

        pb.applyExternalForce(body, -1, force, pos, pb.WORLD_FRAME, physicsClientId=cid)
        pb.applyExternalTorque(body, -1, torque, pb.WORLD_FRAME, physicsClientId=cid)
        pb.stepSimulation(physicsClientId=cid)

    def _apply_drag(self, force: list[float], m: tuple[float, ...], n: list[float]) -> None:
        fx = self.world.effects
        vel, _ = pb.getBaseVelocity(self._body, physicsClientId=self._cid)
        wind = wind_velocity_m_s(fx.wind, self.time_s) if fx.wind is not None else (0.0, 0.0, 0.0)
        va = (vel[0] - wind[0], vel[1] - wind[1], vel[2] - wind[2])
        vb = (
            m[0] * va[0] + m[3] * va[1] + m[6] * va[2],
            m[1] * va[0] + m[4] * va[1] + m[7] * va[2],
            m[2] * va[0] + m[5] * va[1] + m[8] * va[2],
        )
        fb = [0.0, 0.0, 0.0]
        if fx.rotor_drag is not None:
            d = rotor_drag_n(fx.rotor_drag, n[0] + n[1] + n[2] + n[3], vb)
            fb = [fb[0] + d[0], fb[1] + d[1], fb[2] + d[2]]
        if fx.body_drag is not None:
            d = body_drag_n(fx.body_drag, vb)
            fb = [fb[0] + d[0], fb[1] + d[1], fb[2] + d[2]]
        fw = (
            m[0] * fb[0] + m[1] * fb[1] + m[2] * fb[2],
            m[3] * fb[0] + m[4] * fb[1] + m[5] * fb[2],
            m[6] * fb[0] + m[7] * fb[1] + m[8] * fb[2],
        )
        force[0] += fw[0]
        force[1] += fw[1]
        force[2] += fw[2]
        self._drag_force[:] = fw
        self._wind[:] = wind

    def _apply_learned(
        self,
        force: list[float],
        m: tuple[float, ...],
        f: list[float],
        heights: list[float],
    ) -> None:
        """The residual force a gap diagnosis learnt (simbridge/effects/learned.py)."""
        since_s = self.time_since_takeoff_s
        vel, _ = pb.getBaseVelocity(self._body, physicsClientId=self._cid)
        lf = learned_force_n(
            self._learned, heights, (m[2], m[5], m[8]), vel, f, since_s,
            self._radius, self.vehicle.weight_n,
        )  # fmt: skip
        force[0] += lf[0]
        force[1] += lf[1]
        force[2] += lf[2]
        self._learned_force[:] = lf

    def _ray_tests(
        self, pos: tuple[float, ...], offsets: list[Vec3]
    ) -> tuple[list[float], list[float], tuple[float, ...], float]:
        """One batch of rays: down and up from each rotor hub, sideways from the centre, and
        down from the centre (the outwash's height)."""
        starts, ends = [], []
        px, py, pz = pos
        ce, wall, outwash = self._ce, self.world.effects.wall_effect, self._outwash
        down = self._down_m
        if down is not None:
            for ox, oy, oz in offsets:
                starts.append((px + ox, py + oy, pz + oz))
                ends.append((px + ox, py + oy, pz + oz - down))
        if ce is not None:
            length = ce.ray_length_m
            for ox, oy, oz in offsets:
                starts.append((px + ox, py + oy, pz + oz))
                ends.append((px + ox, py + oy, pz + oz + length))
        if wall is not None:
            for ux, uy, _ in WALL_DIRECTIONS:
                starts.append(pos)
                ends.append((px + ux * wall.range_m, py + uy * wall.range_m, pz))
        if outwash is not None:
            starts.append(pos)
            ends.append((px, py, pz - outwash.ray_length_m))
        if not starts:
            return [NO_HIT] * 4, [NO_HIT] * 4, (NO_HIT,) * 4, NO_HIT
        hits = pb.rayTestBatch(
            starts, ends, collisionFilterMask=WORLD_GROUP, physicsClientId=self._cid
        )
        i = 0
        heights = ceilings = [NO_HIT] * 4
        if down is not None:
            heights = [h[2] * down if h[0] >= 0 else NO_HIT for h in hits[0:4]]
            i = 4
        if ce is not None:
            ceilings = [h[2] * ce.ray_length_m if h[0] >= 0 else NO_HIT for h in hits[i : i + 4]]
            i += 4
        walls: tuple[float, ...] = (NO_HIT,) * 4
        if wall is not None:
            walls = tuple(h[2] * wall.range_m if h[0] >= 0 else NO_HIT for h in hits[i : i + 4])
            i += 4
        below = NO_HIT
        if outwash is not None and hits[i][0] >= 0:
            below = hits[i][2] * outwash.ray_length_m
        return heights, ceilings, walls, below

    # -- reading ------------------------------------------------------------------------

    def state(self) -> VehicleState:
        cid, body = self._cid, self._body
        pos, orn = pb.getBasePositionAndOrientation(body, physicsClientId=cid)
        vel, omega = pb.getBaseVelocity(body, physicsClientId=cid)
        m = pb.getMatrixFromQuaternion(orn)
        omega_body = (
            m[0] * omega[0] + m[3] * omega[1] + m[6] * omega[2],
            m[1] * omega[0] + m[4] * omega[1] + m[7] * omega[2],
            m[2] * omega[0] + m[5] * omega[1] + m[8] * omega[2],
        )
        return VehicleState(
            time_s=self.time_s,
            position_m=tuple(pos),
            quaternion=xyzw_to_wxyz(orn),
            velocity_m_s=tuple(vel),
            angular_velocity_body_rad_s=omega_body,
            acceleration_m_s2=self._acceleration,
            rotor_speeds_rad_s=tuple(self._rotor_speeds),
            range_m=self._range(pos, m),
        )

    def _range(self, pos: tuple[float, ...], m: tuple[float, ...]) -> float:
        """Downward range sensor at the centre of mass, along body -z."""
        reach = self.vehicle.range_sensor_max_m
        end = (pos[0] - m[2] * reach, pos[1] - m[5] * reach, pos[2] - m[8] * reach)
        hit = pb.rayTest(pos, end, collisionFilterMask=WORLD_GROUP, physicsClientId=self._cid)[0]
        return hit[2] * reach if hit[0] >= 0 else NO_HIT

    def effect_forces(self) -> EffectForces:
        return EffectForces(
            rotor_heights_m=tuple(self._heights),
            ground_effect_rotor_n=tuple(self._ge_rotor),
            ground_effect_n=tuple(self._ge_force),
            ceiling_effect_n=tuple(self._ce_force),
            wall_effect_n=tuple(self._wall_force),
            drag_n=tuple(self._drag_force),
            wind_m_s=tuple(self._wind),
            learned_n=tuple(self._learned_force),
            ground_effect_exponential_n=tuple(self._gex_force),
            outwash_n=tuple(self._outwash_force),
            thrust_scale=self._thrust_scale,
        )

    def close(self) -> None:
        if self._cid >= 0:
            pb.disconnect(physicsClientId=self._cid)
            self._cid = -1

    def __enter__(self) -> Simulation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def with_effects(world: World, **effects: object) -> World:
    """A copy of `world` with some effects replaced (None removes one)."""
    return dataclasses.replace(world, effects=dataclasses.replace(world.effects, **effects))
