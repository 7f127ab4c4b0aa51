"""The PyBullet vehicle: the ground effect as applied, hover, and the other effects in flight."""

from __future__ import annotations

import dataclasses
import math

import pytest

from simbridge.effects.actuators import (
    MassErrorParams,
    MotorLagParams,
    SpinDownParams,
    ThrustCoefficientParams,
)
from simbridge.effects.drag import RotorDragParams, WindParams
from simbridge.effects.ground import CeilingEffectParams, GroundEffectParams
from simbridge.effects.proximity import WallEffectParams
from simbridge.frames import quat_from_euler
from simbridge.physics import Simulation, with_effects
from simbridge.pybullet_quiet import pybullet as pb
from simbridge.vehicle import GRAVITY_M_S2, load_vehicle
from simbridge.world import Box, load_world, with_start

VEHICLE = load_vehicle()
C_T, R, MASS = VEHICLE.thrust_coefficient_n_s2, VEHICLE.rotor_radius_m, VEHICLE.mass_kg
HOVER = VEHICLE.hover_rotor_speed_rad_s


def world_with(rho: float | None = 1.0, start=(0.0, 0.0, 1.0), **effects):
    world = with_start(load_world("default"), start)
    ge = GroundEffectParams(rho=rho) if rho is not None else None
    return with_effects(world, ground_effect=ge, **effects)


def equation_3_4(n: float, z: float, rho: float, cutoff: float = 0.02) -> float:
    z = max(z, cutoff)
    return C_T * n**2 * (1.0 / (1.0 - rho * (R / (4.0 * z)) ** 2) - 1.0)


def hover_speed_at(z: float, rho: float) -> float:
    """Rotor speed at which four rotors plus their ground effect carry the weight."""
    gain = 1.0 / (1.0 - rho * (R / (4.0 * max(z, 0.02))) ** 2)
    return math.sqrt(MASS * GRAVITY_M_S2 / 4.0 / gain / C_T)


@pytest.mark.parametrize("rho", [1.0, 2.0])
@pytest.mark.parametrize("z", [0.02, 0.025, 0.03, 0.05, 0.1, 0.2, 0.35, 0.5])
def test_applied_ground_effect_matches_equation_3_4_within_1_percent(rho, z):
    n = hover_speed_at(z, rho)
    with Simulation(world_with(rho, (0.0, 0.0, z)), VEHICLE) as sim:
        sim.step((n, n, n, n))
        forces = sim.effect_forces()
        height = sim.state().position_m[2]
    assert height == pytest.approx(z, abs=1e-4)  # it hovers: the height is still z
    for rotor_height, force in zip(
        forces.rotor_heights_m, forces.ground_effect_rotor_n, strict=True
    ):
        assert rotor_height == pytest.approx(z, abs=1e-4)  # the ray reaches the ground
        assert force == pytest.approx(equation_3_4(n, z, rho), rel=0.01)
    assert forces.ground_effect_n[2] == pytest.approx(4 * equation_3_4(n, z, rho), rel=0.01)


def test_ground_effect_is_constant_below_the_cutoff():
    n = hover_speed_at(0.02, 2.0)  # balanced, so the drone does not climb out of the cut-off
    applied = []
    for z in (0.0135, 0.016, 0.019, 0.02):
        with Simulation(world_with(2.0, (0.0, 0.0, z)), VEHICLE) as sim:
            sim.step((n,) * 4)
            assert sim.effect_forces().rotor_heights_m[0] == pytest.approx(z, abs=1e-4)
            applied.append(sim.effect_forces().ground_effect_rotor_n[0])
    assert applied[0] == pytest.approx(equation_3_4(n, 0.02, 2.0), rel=0.01)
    assert max(applied) == pytest.approx(min(applied), rel=1e-6)


def test_a_box_under_one_rotor_changes_its_ground_effect_and_tilts_the_drone():
    # Rotor 0 (front-left, +x +y) hangs over a 10 cm box; the others over the ground.
    box = Box(center_m=(0.2, 0.2, 0.05), size_m=(0.34, 0.34, 0.1))
    world = dataclasses.replace(world_with(1.0, (0.0, 0.0, 0.15)), obstacles=(box,))
    n = VEHICLE.hover_rotor_speed_rad_s
    with Simulation(world, VEHICLE) as sim:
        sim.step((n,) * 4)
        forces = sim.effect_forces()
        heights = forces.rotor_heights_m
        assert heights[0] == pytest.approx(0.05, abs=1e-3)
        assert heights[1:] == pytest.approx((0.15, 0.15, 0.15), abs=1e-3)
        assert forces.ground_effect_rotor_n[0] == pytest.approx(
            equation_3_4(n, 0.05, 1.0), rel=0.01
        )
        assert forces.ground_effect_rotor_n[1] == pytest.approx(
            equation_3_4(n, 0.15, 1.0), rel=0.01
        )
        for _ in range(25):
            sim.step((n,) * 4)
        wx, wy, _ = sim.state().angular_velocity_body_rad_s
    # more lift at front-left: rolls right (+x body rate) and pitches nose up (-y body rate)
    assert wx > 0.05 and wy < -0.05
    with Simulation(world_with(1.0, (0.0, 0.0, 0.15)), VEHICLE) as flat:
        flat.step((n,) * 4)
        assert flat.effect_forces().ground_effect_rotor_n[0] < forces.ground_effect_rotor_n[0] / 2


def test_hover_at_one_metre_stays_within_a_millimetre_for_a_second():
    n = hover_speed_at(1.0, 1.0)
    with Simulation(world_with(1.0, (0.0, 0.0, 1.0)), VEHICLE) as sim:
        worst = 0.0
        for _ in range(250):
            sim.step((n,) * 4)
            x, y, z = sim.state().position_m
            worst = max(worst, math.dist((x, y, z), (0.0, 0.0, 1.0)))
    assert worst < 1e-3


@pytest.mark.parametrize("rho", [1.0, 2.0])
def test_at_three_centimetres_free_air_hover_speed_accelerates_up_as_equation_3_4_predicts(rho):
    with Simulation(world_with(rho, (0.0, 0.0, 0.03)), VEHICLE) as sim:
        sim.step((HOVER,) * 4)
        accel = sim.state().acceleration_m_s2
    expected = 4 * equation_3_4(HOVER, 0.03, rho) / MASS
    assert accel[2] == pytest.approx(expected, rel=0.01)
    assert abs(accel[0]) < 1e-6 and abs(accel[1]) < 1e-6


def test_without_rotors_it_rests_on_the_ground_and_on_a_box():
    world = load_world("default")  # start altitude null: resting on the surface below
    with Simulation(world, VEHICLE, held=True) as sim:
        assert sim.state().position_m[2] == pytest.approx(0.0126, abs=1e-9)  # placed touching
        sim.release()
        for _ in range(100):
            sim.step((0.0,) * 4)
        state = sim.state()
        assert state.position_m[2] == pytest.approx(0.0126, abs=2e-4)
        assert state.range_m == pytest.approx(0.0126, abs=2e-4)
    world = dataclasses.replace(
        load_world("obstacles"), start=dataclasses.replace(world.start, xy_m=(1.0, 0.0))
    )
    with Simulation(world, VEHICLE) as sim:
        assert sim.state().position_m[2] == pytest.approx(0.1126, abs=1e-9)  # on the box top
        for _ in range(100):
            sim.step((0.0,) * 4)
        assert sim.state().position_m[2] == pytest.approx(0.1126, abs=2e-4)
    low_ceiling = dataclasses.replace(load_world("default"), ceiling_height_m=0.85)
    with Simulation(low_ceiling, VEHICLE, held=True) as sim:  # under it, not on top of it
        assert sim.state().position_m[2] == pytest.approx(0.0126, abs=1e-9)


def test_motor_lag_delays_the_actual_rotor_speeds():
    world = world_with(None, motor_lag=MotorLagParams(time_constant_s=0.02))
    with Simulation(world, VEHICLE) as sim:
        for _ in range(5):  # 20 ms = one time constant
            sim.step((100.0,) * 4)
        speeds = sim.state().rotor_speeds_rad_s
    assert speeds == pytest.approx((100.0 * (1 - math.exp(-1)),) * 4, rel=1e-6)


def test_an_unbraked_rotor_spins_up_at_once_and_coasts_down_on_its_drag():
    """From hover speed to a zero command: n = n_h / (1 + t / tau), half the speed after tau
    (0.3 s); back to hover at once (no lag asked for)."""
    world = world_with(None, spin_down=SpinDownParams(time_constant_s=0.3))
    n_h = VEHICLE.hover_rotor_speed_rad_s
    with Simulation(world, VEHICLE) as sim:
        sim.step((n_h,) * 4)
        assert sim.state().rotor_speeds_rad_s == pytest.approx((n_h,) * 4, rel=1e-12)
        for _ in range(round(0.3 / world.control_period_s)):
            sim.step((0.0,) * 4)
        assert sim.state().rotor_speeds_rad_s == pytest.approx((n_h / 2,) * 4, rel=1e-9)
        sim.step((0.9 * n_h,) * 4)  # above the coasting rotor: followed at once
        assert sim.state().rotor_speeds_rad_s == pytest.approx((0.9 * n_h,) * 4, rel=1e-12)


@pytest.mark.parametrize(
    ("effect", "expected_accel"),
    [
        ({"mass_error": MassErrorParams(scale=1.1)}, GRAVITY_M_S2 * (1 / 1.1 - 1)),
        ({"thrust_coefficient": ThrustCoefficientParams(scale=0.9)}, GRAVITY_M_S2 * (0.9 - 1)),
    ],
)
def test_mass_and_thrust_coefficient_errors_change_the_hover_balance(effect, expected_accel):
    with Simulation(world_with(None, **effect), VEHICLE) as sim:
        sim.step((HOVER,) * 4)
        assert sim.state().acceleration_m_s2[2] == pytest.approx(expected_accel, rel=0.01)


def test_wind_pushes_a_hovering_drone_through_rotor_drag():
    drag = RotorDragParams(coefficient_n_s_m=(2.2e-5, 2.2e-5, 1.0e-5))
    world = world_with(None, rotor_drag=drag, wind=WindParams(mean_m_s=(2.0, 0.0, 0.0)))
    with Simulation(world, VEHICLE) as sim:
        sim.step((HOVER,) * 4)
        accel = sim.state().acceleration_m_s2
        force = sim.effect_forces().drag_n
    expected = 2.2e-5 * 4 * HOVER * 2.0  # -k (sum n) (v - w) with v = 0
    assert force[0] == pytest.approx(expected, rel=0.02)
    assert accel[0] == pytest.approx(expected / MASS, rel=0.02)


def test_ceiling_effect_pulls_a_drone_up_near_the_ceiling():
    world = dataclasses.replace(
        world_with(None, (0.0, 0.0, 1.0), ceiling_effect=CeilingEffectParams(rho=1.0)),
        ceiling_height_m=1.05,
    )
    with Simulation(world, VEHICLE) as sim:
        sim.step((HOVER,) * 4)
        up = sim.state().acceleration_m_s2[2]
        assert sim.effect_forces().ceiling_effect_n[2] == pytest.approx(
            4 * equation_3_4(HOVER, 0.05, 1.0), rel=0.01
        )
    assert up == pytest.approx(4 * equation_3_4(HOVER, 0.05, 1.0) / MASS, rel=0.01)


def test_a_wall_pulls_the_drone_sideways():
    wall = Box(center_m=(0.0, 0.3, 1.0), size_m=(4.0, 0.1, 2.0))  # face at y = 0.25
    world = dataclasses.replace(
        world_with(None, (0.0, 0.0, 1.0), wall_effect=WallEffectParams(gain=0.5)), obstacles=(wall,)
    )
    with Simulation(world, VEHICLE) as sim:
        sim.step((HOVER,) * 4)
        force = sim.effect_forces().wall_effect_n
    expected = 0.5 * MASS * GRAVITY_M_S2 * (R / (4 * 0.25)) ** 2
    assert force[1] == pytest.approx(expected, rel=0.01) and force[0] == 0.0


def test_a_tilted_start_pose_is_honoured():
    world = with_start(load_world("default"), (0.3, -0.2, 1.0))
    world = dataclasses.replace(
        world, start=dataclasses.replace(world.start, roll_deg=10.0, yaw_deg=30.0)
    )
    with Simulation(world, VEHICLE, held=True) as sim:
        sim.step((0.0,) * 4)  # held on its stand: time passes, nothing moves
        state = sim.state()
    assert state.position_m == pytest.approx((0.3, -0.2, 1.0))
    assert state.quaternion == pytest.approx(
        quat_from_euler(math.radians(10), 0.0, math.radians(30))
    )
    assert state.time_s == pytest.approx(0.004)


def test_the_bare_loop_reference_steps_the_body_it_is_given():
    """`bench sim`'s physics reference (and the physics ping-pong's): the simulator's own body
    under a bare quadrotor loop whose four thrusts hold the weight. Set climbing at 0.1 m/s,
    it climbs on at that speed: PyBullet integrates it, and nothing but the weight and the
    thrusts acts on it (2000 steps at 1 kHz: 0.2 m)."""
    from simbridge.bare_loop import BareQuadrotor

    world = world_with(None, start=(0.0, 0.0, 0.5))
    with Simulation(world, VEHICLE) as sim:
        bare = BareQuadrotor(sim, VEHICLE)
        pb.resetBaseVelocity(sim._body, [0.0, 0.0, 0.1], [0.0, 0.0, 0.0], sim._cid)
        bare.run(2000)
        pos, _ = pb.getBasePositionAndOrientation(sim._body, physicsClientId=sim._cid)
        vel, _ = pb.getBaseVelocity(sim._body, physicsClientId=sim._cid)
    assert pos[2] == pytest.approx(0.7, abs=1e-3) and vel[2] == pytest.approx(0.1, abs=1e-3)
    assert abs(pos[0]) < 1e-6 and abs(pos[1]) < 1e-6
