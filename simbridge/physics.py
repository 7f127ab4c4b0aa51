"""The PyBullet world: rigid-body dynamics of the vehicle with the world's physical effects.

This is the edge where the pure effect functions meet PyBullet. Each physics step reads the
body's state, ray-tests the surfaces around the rotors, sums rotor thrust (equations 3.5,
3.6) and every enabled effect into one world-frame force and torque at the centre of mass,
and steps. Plain floats and tuples on the hot path: numpy costs more than it saves at n = 4.
"""

from __future__ import annotations

import dataclasses
import math

from simbridge.effects import registry
from simbridge.effects.actuators import thrust_axis_body
from simbridge.effects.drag import body_drag_n, rotor_drag_n, wind_velocity_m_s
from simbridge.effects.ground import ground_effect_forces_n, hub_moment, thrust_gain
from simbridge.effects.learned import learned_force_n
from simbridge.effects.proximity import WALL_DIRECTIONS, wall_force_n
from simbridge.effects.uncatalogued import (
    TAKEOFF_HEIGHT_M,
    exponential_gain,
    exponential_scale,
    outwash_force_n,
)
from simbridge.frames import Vec3, xyzw_to_wxyz
from simbridge.pybullet_quiet import pybullet as pb
from simbridge.pybullet_world import WORLD_GROUP, build_body, build_surfaces, surface_footprints
from simbridge.rotor_dynamics import RotorDynamics
from simbridge.rotors import Quad, thrust_and_moments
from simbridge.sim_state import EffectForces, VehicleState
from simbridge.surface_rays import VerticalRays
from simbridge.vehicle import Vehicle
from simbridge.world import World

NO_HIT = math.inf
NO_HITS = (NO_HIT,) * 4  # four rays that met nothing
LEARNED_RAY_M = 3.0  # a learnt residual's height rays: beyond, its feature is capped anyway


def _zero3() -> list[float]:
    return [0.0, 0.0, 0.0]


class Simulation:
    """One vehicle in one PyBullet world, stepped one control period at a time."""

    def __init__(self, world: World, vehicle: Vehicle, *, held: bool = False) -> None:
        self.world, self.vehicle = world, vehicle
        # drag's coefficients and areas a world leaves out follow the vehicle
        self.effects = fx = world.effects.for_vehicle(vehicle)
        self._cid = pb.connect(pb.DIRECT)
        self._dt = world.physics_dt_s
        self._time_us = 0
        self.held = held  # on a stand at the start pose until released (see HIL link)
        build_surfaces(self._cid, world, self._dt)

        # Effective physical constants of the simulated (true) vehicle.
        self._rotors = RotorDynamics(vehicle, fx, self._dt)
        self.true_mass_kg = vehicle.mass_kg * (fx.mass_error.scale if fx.mass_error else 1.0)
        self._rotors_body = vehicle.rotor_positions_body_m()
        self._rotors_flat = tuple(c for r in self._rotors_body for c in r)  # x0, y0, z0, x1, ...
        self._span = max(math.dist(r, (0.0, 0.0, 0.0)) for r in self._rotors_body)
        self._arm, self._kz = vehicle.arm_m, vehicle.yaw_moment_coefficient_m
        self._radius = vehicle.rotor_radius_m
        self._ge = fx.ground_effect
        self._ge_cutoff = self._ge.cutoff_for(self._radius) if self._ge else 0.0
        # rho, radius, cut-off and reach, as `ground_effect_forces_n` takes them
        self._ge_args = (
            (self._ge.rho, self._radius, self._ge_cutoff, self._ge.ray_length_m) if self._ge else ()
        )
        self._ce = fx.ceiling_effect
        self._wall_effect = fx.wall_effect
        self._ce_cutoff = self._ce.cutoff_for(self._radius) if self._ce else 0.0
        # the thrust's direction in the body frame (body z unless it leans)
        self._axis = thrust_axis_body(*fx.thrust_tilt.lean_deg) if fx.thrust_tilt else None
        self._drag = fx.rotor_drag is not None or fx.body_drag is not None
        self._learned = fx.learned_residual
        self._learned_force = _zero3()
        self._gex, self._outwash = fx.ground_effect_exponential, fx.ground_outwash
        self._gex_force, self._outwash_force = _zero3(), _zero3()
        # effects declared with their own force (simbridge/effects/registry.py)
        known = registry.effects()
        self._declared = [(n, p, known[n].force) for n, p in fx.items() if known[n].force]
        self._declared_forces: dict[str, Vec3] = {n: (0.0, 0.0, 0.0) for n, *_ in self._declared}
        # one set of down rays per rotor serves every effect that reads rotor heights
        lengths = [e.ray_length_m for e in (self._ge, self._gex) if e is not None]
        lengths += [p.ray_length_m for _, p, _ in self._declared if hasattr(p, "ray_length_m")]
        self._down_m = max(lengths + ([LEARNED_RAY_M] if self._learned else []), default=None)
        self._lift_off_us: int | None = None  # see time_since_takeoff_s
        body = build_body(self._cid, world, vehicle, self.true_mass_kg)
        self._body, self.resting_height_m = body.body_id, body.resting_height_m
        self.start_position_m, self.start_quaternion = body.position_m, body.quaternion
        self._vertical_rays = self._build_rays()
        self._horizontal_effects = (
            fx.wall_effect is not None
            or self._outwash is not None
            or self._drag
            or self._learned is not None
            or bool(self._declared)
        )
        self._hub_rays_only = (
            self._down_m is not None and self._ce is None and self._outwash is None
        )

        self._heights: list[float] = [NO_HIT] * 4
        self._ge_rotor: list[float] = [0.0] * 4
        self._ge_force, self._ce_force = _zero3(), _zero3()
        self._wall_force, self._drag_force, self._wind = _zero3(), _zero3(), _zero3()
        self._acceleration: Vec3 = (0.0, 0.0, 0.0)
        # the body's velocities after the last step: only stepping changes them, so they are
        # the next step's start and what `state` reports (None: read them from PyBullet)
        self._velocity_end: tuple[Vec3, Vec3] | None = None
        # likewise the pose and its rotation matrix: read once after each physics step, they
        # are the next step's start and what `state` reports
        self._pose = self._read_pose()

    # -- construction -------------------------------------------------------------------

    def _build_rays(self) -> VerticalRays | None:
        """Down rays from the hubs (rotor heights), up rays from them (the ceiling effect),
        a down ray from the centre (the outwash's height): one batch, cast when needed."""
        signs: list[int] = []
        reach: list[float] = []
        if self._down_m is not None:
            signs += [-1] * 4
            reach += [self._down_m] * 4
        if self._ce is not None:
            signs += [1] * 4
            reach += [self._ce.ray_length_m] * 4
        if self._outwash is not None:
            signs.append(-1)
            reach.append(self._outwash.ray_length_m)
        if not signs:
            return None
        return VerticalRays(self._cid, surface_footprints(self.world), signs, reach, WORLD_GROUP)

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
        cid, body = self._cid, self._body
        end = self._velocity_end
        v0 = end[0] if end is not None else pb.getBaseVelocity(body, physicsClientId=cid)[0]
        rotors = self._rotors
        constant = rotors.constant
        # the thrust decay's clock, the same over the step's physics steps (a lift-off found
        # in one of them starts it at this step's time: 0 either way)
        since = self.time_since_takeoff_s if rotors.decay is not None else 0.0
        if constant:
            f = rotors.forces(rotors.command(rotor_commands_rad_s), since)
            tm = thrust_and_moments(f, self._arm, self._kz)  # equation 3.6, body
        for _ in range(world.substeps):
            if not constant:
                f = rotors.forces(rotors.advance(rotor_commands_rad_s), since)
                tm = thrust_and_moments(f, self._arm, self._kz)
            self._substep(f, tm)
        self._velocity_end = pb.getBaseVelocity(body, cid)
        v1 = self._velocity_end[0]
        inv = 1.0 / world.control_period_s
        self._acceleration = ((v1[0] - v0[0]) * inv, (v1[1] - v0[1]) * inv, (v1[2] - v0[2]) * inv)
        self._time_us += world.control_period_us

    def _read_pose(self) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
        """The body's position, quaternion (x, y, z, w) and rotation matrix (row-major)."""
        pos, orn = pb.getBasePositionAndOrientation(self._body, self._cid)
        return pos, orn, pb.getMatrixFromQuaternion(orn)

    def _substep(self, f: Quad, tm: tuple[float, float, float, float]) -> None:
        """One physics step with rotor forces `f` and their thrust and moments `tm`."""
        cid, body = self._cid, self._body
        pos, _, m = self._pose
        if self._lift_off_us is None and pos[2] > self.resting_height_m + TAKEOFF_HEIGHT_M:
            self._lift_off_us = self._time_us
        m0, m1, m2, m3, m4, m5, m6, m7, m8 = m

        heights, ceilings, walls, below = self._ray_tests(pos, m)

        # Equation 3.6 in the body frame, ceiling effect as extra thrust on each rotor.
        if self._ce is not None:
            rho, radius, cut = self._ce.rho, self._radius, self._ce_cutoff
            boosted = [
                fi * (1.0 + thrust_gain(d, rho, radius, cut))
                for fi, d in zip(f, ceilings, strict=True)
            ]
            extra = sum(boosted) - sum(f)
            self._ce_force[:] = (m2 * extra, m5 * extra, m8 * extra)
            f = boosted
            tm = thrust_and_moments(f, self._arm, self._kz)
        thrust, mx, my, mz = tm
        if self._axis is None:  # the thrust along body z
            force = [m2 * thrust, m5 * thrust, m8 * thrust]
        else:  # a thrust axis leaning from body z (thrust_tilt)
            ax, ay, az = self._axis
            force = [
                (m0 * ax + m1 * ay + m2 * az) * thrust,
                (m3 * ax + m4 * ay + m5 * az) * thrust,
                (m6 * ax + m7 * ay + m8 * az) * thrust,
            ]
        tx = m0 * mx + m1 * my + m2 * mz
        ty = m3 * mx + m4 * my + m5 * mz
        tz = m6 * mx + m7 * my + m8 * mz

        if self._ge is not None:  # equation 3.4: vertical, at each rotor hub
            g = ground_effect_forces_n(f, heights, *self._ge_args)
            # the torque of vertical forces g_i at the hubs R r_i: (R s)_y, -(R s)_x with
            # s = sum g_i r_i in the body frame
            sx, sy, sz = hub_moment(self._rotors_body, g)
            tx += m3 * sx + m4 * sy + m5 * sz
            ty -= m0 * sx + m1 * sy + m2 * sz
            total = g[0] + g[1] + g[2] + g[3]
            force[2] += total
            self._ge_rotor = g
            self._ge_force[2] = total
        if self._gex is not None:  # the exponential shape, vertical at each hub likewise
            gain, decay, reach = (
                self._gex.gain * self._gex_scale(),
                self._gex.decay_radii * self._radius,
                self._gex.ray_length_m,
            )
            g = [
                fi * exponential_gain(h, gain, decay) if h <= reach else 0.0
                for fi, h in zip(f, heights, strict=True)
            ]
            sx, sy, sz = hub_moment(self._rotors_body, g)
            tx += m3 * sx + m4 * sy + m5 * sz
            ty -= m0 * sx + m1 * sy + m2 * sz
            total = g[0] + g[1] + g[2] + g[3]
            force[2] += total
            self._gex_force[2] = total
        self._heights = heights
        if self._horizontal_effects:
            self._apply_horizontal(force, m, f, thrust, heights, walls, below)

        # the client id passed by position: keyword parsing costs a tenth of these calls
        pb.applyExternalForce(body, -1, force, pos, pb.WORLD_FRAME, cid)
        pb.applyExternalTorque(body, -1, (tx, ty, tz), pb.WORLD_FRAME, cid)
        pb.stepSimulation(cid)
        self._pose = self._read_pose()

    def _gex_scale(self) -> float:
        """The exponential ground effect's patch and speed fade where they are."""
        gex = self._gex
        if gex is None or (gex.patch_radius_m <= 0.0 and gex.fade_speed_m_s <= 0.0):
            return 1.0
        (x, y, _), _, _ = self._pose
        vel, _ = pb.getBaseVelocity(self._body, physicsClientId=self._cid)
        return exponential_scale(gex, x, y, math.hypot(vel[0], vel[1]))

    def _apply_horizontal(
        self,
        force: list[float],
        m: tuple[float, ...],
        f: Quad,
        thrust: float,
        heights: list[float],
        walls: tuple[float, ...],
        below: float,
    ) -> None:
        """The wall effect, the outwash, drag, a learnt residual and the declared effects,
        where the world has them."""
        wall = self._wall_effect
        if wall is not None:
            wf = wall_force_n(wall, thrust, self._radius, walls)
            force[0] += wf[0]
            force[1] += wf[1]
            self._wall_force[:] = wf
        if self._outwash is not None:
            ow = outwash_force_n(self._outwash, thrust, below, self._radius)
            force[0] += ow[0]
            force[1] += ow[1]
            self._outwash_force[:] = ow
        if self._drag:
            self._apply_drag(force, m, self._rotors.speeds_rad_s)
        if self._learned is not None:
            self._apply_learned(force, m, f, heights)
        if self._declared:
            vel, _ = pb.getBaseVelocity(self._body, physicsClientId=self._cid)
            view = registry.BodyView(
                self.time_s, self._pose[0], m, vel, tuple(f), thrust, tuple(heights),
                self._radius, self.vehicle.weight_n,
            )  # fmt: skip
            d = registry.declared_forces_n(self._declared, view, self._declared_forces)
            force[0], force[1], force[2] = force[0] + d[0], force[1] + d[1], force[2] + d[2]

    def _apply_drag(self, force: list[float], m: tuple[float, ...], n: list[float]) -> None:
        fx = self.effects
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
            self._learned, heights, m, self._pose[0], vel, f, since_s,
            self._radius, self.vehicle.weight_n,
        )  # fmt: skip
        force[0] += lf[0]
        force[1] += lf[1]
        force[2] += lf[2]
        self._learned_force[:] = lf

    def _hubs(self, pos: tuple[float, ...], m: tuple[float, ...]) -> list[Vec3]:
        """Where the rotor hubs are, in the world."""
        px, py, pz = pos
        m0, m1, m2, m3, m4, m5, m6, m7, m8 = m
        return [
            (
                px + m0 * rx + m1 * ry + m2 * rz,
                py + m3 * rx + m4 * ry + m5 * rz,
                pz + m6 * rx + m7 * ry + m8 * rz,
            )
            for rx, ry, rz in self._rotors_body
        ]

    def _ray_tests(
        self, pos: tuple[float, ...], m: tuple[float, ...]
    ) -> tuple[list[float], list[float], tuple[float, ...], float]:
        """Rotor heights, ceiling distances, wall distances and the centre's height: the
        vertical ones from `VerticalRays` (cast only when they can have changed), the walls'
        horizontal rays every step."""
        heights = ceilings = NO_HITS
        below = NO_HIT
        rays = self._vertical_rays
        if rays is not None and self._hub_rays_only:  # the usual case: rotor heights alone
            _, _, _, _, _, _, m6, m7, m8 = m
            pz = pos[2]
            x0, y0, z0, x1, y1, z1, x2, y2, z2, x3, y3, z3 = self._rotors_flat
            heights = rays.distances_about(  # the hubs' heights, written out (1 kHz)
                pos,
                (
                    pz + m6 * x0 + m7 * y0 + m8 * z0,
                    pz + m6 * x1 + m7 * y1 + m8 * z1,
                    pz + m6 * x2 + m7 * y2 + m8 * z2,
                    pz + m6 * x3 + m7 * y3 + m8 * z3,
                ),
            ) or rays.distances(self._hubs(pos, m), pos, self._span)
            if self._wall_effect is None:
                return heights, ceilings, NO_HITS, below
        elif rays is not None:
            px, py, pz = pos
            hubs = self._hubs(pos, m)
            points = []
            if self._down_m is not None:
                points += hubs
            if self._ce is not None:
                points += hubs
            if self._outwash is not None:
                points.append((px, py, pz))
            d = rays.distances(points)
            i = 0
            if self._down_m is not None:
                heights, i = d[0:4], 4
            if self._ce is not None:
                ceilings, i = d[i : i + 4], i + 4
            if self._outwash is not None:
                below = d[i]
        walls: tuple[float, ...] = NO_HITS
        wall = self._wall_effect
        if wall is not None:
            px, py, pz = pos
            ends = [
                (px + ux * wall.range_m, py + uy * wall.range_m, pz)
                for ux, uy, _ in WALL_DIRECTIONS
            ]
            hits = pb.rayTestBatch(
                [pos] * 4,
                ends,
                numThreads=1,
                collisionFilterMask=WORLD_GROUP,
                physicsClientId=self._cid,
            )
            walls = tuple(h[2] * wall.range_m if h[0] >= 0 else NO_HIT for h in hits)
        return heights, ceilings, walls, below

    # -- reading ------------------------------------------------------------------------

    def state(self) -> VehicleState:
        pos, orn, m = self._pose
        end = self._velocity_end
        if end is None:
            end = pb.getBaseVelocity(self._body, physicsClientId=self._cid)
        vel, omega = end
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
            rotor_speeds_rad_s=tuple(self._rotors.speeds_rad_s),
            range_m=self._range(pos, m),
        )

    def _range(self, pos: tuple[float, ...], m: tuple[float, ...]) -> float:
        """Downward range sensor at the centre of mass, along body -z."""
        reach = self.vehicle.range_sensor_max_m
        end = (pos[0] - m[2] * reach, pos[1] - m[5] * reach, pos[2] - m[8] * reach)
        hit = pb.rayTest(pos, end, collisionFilterMask=WORLD_GROUP, physicsClientId=self._cid)[0]
        return hit[2] * reach if hit[0] >= 0 else NO_HIT

    @property
    def ground_effect_n(self) -> Vec3:
        """The true world-frame ground-effect force of the last physics step (what the HIL
        link sends as truth each step: `effect_forces` has them all)."""
        f = self._ge_force
        return (f[0], f[1], f[2])

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
            thrust_scale=self._rotors.thrust_scale,
            declared_n=tuple(self._declared_forces.items()),
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
    return dataclasses.replace(world, effects=world.effects.replace(**effects))
