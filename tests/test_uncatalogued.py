"""Effects outside the diagnosis's catalogue (simbridge/effects/uncatalogued.py) and the learnt
residual: their pure functions, and each one felt by the PyBullet vehicle."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from simbridge.config import ConfigError
from simbridge.effects import UNCATALOGUED, parse_effects
from simbridge.effects.learned import (
    FEATURES,
    ResidualModel,
    headings,
    load_residual_model,
    residual_features,
    save_residual_model,
)
from simbridge.effects.uncatalogued import (
    GroundEffectExponentialParams,
    GroundOutwashParams,
    RotorAsymmetryParams,
    ThrustDecayParams,
    asymmetric_forces_n,
    exponential_gain,
    exponential_gain_array,
    exponential_scale,
    outwash_force_n,
    thrust_decay_scale,
)
from simbridge.physics import Simulation, with_effects
from simbridge.vehicle import GRAVITY_M_S2, load_vehicle
from simbridge.world import load_world, with_start

VEHICLE = load_vehicle()
R, MASS, HOVER = VEHICLE.rotor_radius_m, VEHICLE.mass_kg, VEHICLE.hover_rotor_speed_rad_s


def bare_world(start=(0.0, 0.0, 1.0), **effects):
    """The default world without its ground effect, with `effects`."""
    return with_effects(with_start(load_world("default"), start), ground_effect=None, **effects)


# -- pure functions ------------------------------------------------------------------------


def test_exponential_gain_decays_from_its_gain_at_the_surface():
    assert exponential_gain(0.0, 0.3, 0.05) == pytest.approx(0.3)
    assert exponential_gain(0.05, 0.3, 0.05) == pytest.approx(0.3 / math.e)
    assert exponential_gain(-0.01, 0.3, 0.05) == pytest.approx(0.3)  # inside a surface: held
    assert exponential_gain(math.inf, 0.3, 0.05) == 0.0
    h = np.array([0.0, 0.02, 0.1, np.inf])
    expected = [exponential_gain(x, 0.3, 0.05) for x in h]
    assert exponential_gain_array(h, 0.3, 0.05) == pytest.approx(expected)


def test_the_exponential_ground_effect_fades_with_speed_and_keeps_to_its_patch():
    fading = GroundEffectExponentialParams(fade_speed_m_s=0.6)
    assert exponential_scale(fading, 5.0, 5.0, 0.0) == 1.0
    assert exponential_scale(fading, 0.0, 0.0, 0.6) == pytest.approx(math.exp(-1.0))
    pad = GroundEffectExponentialParams(patch_center_m=(0.8, 0.0), patch_radius_m=0.4)
    assert exponential_scale(pad, 0.9, 0.1, 2.0) == 1.0  # on the pad, no fade asked
    assert exponential_scale(pad, -0.8, 0.0, 0.0) == 0.0  # the floor around it
    assert exponential_scale(GroundEffectExponentialParams(), -9.0, 9.0, 9.0) == 1.0


def test_thrust_decay_is_linear_in_time_since_takeoff_and_floored():
    p = ThrustDecayParams(rate_per_s=0.01, floor=0.8)
    assert thrust_decay_scale(p, 0.0) == 1.0
    assert thrust_decay_scale(p, 10.0) == pytest.approx(0.9)
    assert thrust_decay_scale(p, 100.0) == 0.8


def test_rotor_asymmetry_scales_each_rotor():
    p = RotorAsymmetryParams(scales=(1.0, 1.0, 0.85, 1.1))
    assert asymmetric_forces_n(p, (0.1, 0.2, 0.3, 0.4)) == pytest.approx((0.1, 0.2, 0.255, 0.44))


def test_outwash_points_along_its_direction_and_fades_with_height():
    p = GroundOutwashParams(gain=0.1, decay_radii=2.0, direction_deg=90.0)
    fx, fy, fz = outwash_force_n(p, 0.5, 0.0, R)
    assert fx == pytest.approx(0.0, abs=1e-12) and fy == pytest.approx(0.05) and fz == 0.0
    assert outwash_force_n(p, 0.5, 2 * R, R)[1] == pytest.approx(0.05 / math.e)
    assert outwash_force_n(p, 0.5, math.inf, R) == (0.0, 0.0, 0.0)


def test_the_effects_parse_from_a_world_file_and_bad_values_name_their_field():
    fx = parse_effects(
        [
            {"name": "ground_effect_exponential", "gain": 0.4, "decay_radii": 1.0},
            {"name": "thrust_decay", "rate_per_s": 0.003},
            {"name": "rotor_asymmetry", "scales": [1, 1, 0.85, 1]},
            {"name": "ground_outwash", "gain": 0.08, "direction_deg": 0},
        ],
        "w",
    )
    assert sorted(fx.names()) == sorted(UNCATALOGUED)
    assert fx.rotor_asymmetry.scales == (1.0, 1.0, 0.85, 1.0)
    with pytest.raises(ConfigError, match=r"rotor_asymmetry\)\.scales: expected a list of 4"):
        parse_effects([{"name": "rotor_asymmetry", "scales": [1, 1, 0.85]}], "w")
    with pytest.raises(ConfigError, match=r"thrust_decay\)\.rate_per_s: 0.5 is outside"):
        parse_effects([{"name": "thrust_decay", "rate_per_s": 0.5}], "w")


# -- in the simulator ----------------------------------------------------------------------


def test_the_exponential_ground_effect_lifts_at_each_rotor():
    gex = GroundEffectExponentialParams(gain=0.3, decay_radii=1.5)
    with Simulation(bare_world((0.0, 0.0, 0.05), ground_effect_exponential=gex), VEHICLE) as sim:
        sim.step((HOVER,) * 4)
        up = sim.state().acceleration_m_s2[2]
        force = sim.effect_forces().ground_effect_exponential_n
    expected = MASS * GRAVITY_M_S2 * exponential_gain(0.05, 0.3, 1.5 * R)
    assert force[2] == pytest.approx(expected, rel=0.01)
    assert up == pytest.approx(expected / MASS, rel=0.02)


def test_a_weak_rotor_rolls_and_pitches_the_vehicle_under_equal_commands():
    weak = RotorAsymmetryParams(scales=(1.0, 1.0, 0.85, 1.0))  # back-right
    with Simulation(bare_world(rotor_asymmetry=weak), VEHICLE) as sim:
        for _ in range(25):
            sim.step((HOVER,) * 4)
        wx, wy, _ = sim.state().angular_velocity_body_rad_s
    # less lift at back-right: M_x = k(f0 + f1 - f2 - f3) > 0, M_y = k(-f0 + f1 + f2 - f3) < 0
    assert wx > 0.05 and wy < -0.05


def test_the_outwash_pushes_sideways_near_the_ground_and_not_at_a_metre():
    ow = GroundOutwashParams(gain=0.1, decay_radii=2.0, direction_deg=90.0)  # toward +y
    pushes = {}
    for z in (0.03, 1.0):
        with Simulation(bare_world((0.0, 0.0, z), ground_outwash=ow), VEHICLE) as sim:
            sim.step((HOVER,) * 4)
            pushes[z] = sim.state().acceleration_m_s2
    expected = 0.1 * GRAVITY_M_S2 * math.exp(-0.03 / (2.0 * R))
    assert pushes[0.03][1] == pytest.approx(expected, rel=0.02)
    assert abs(pushes[0.03][0]) < 1e-3 * expected
    assert abs(pushes[1.0][1]) < 1e-3 * expected * 10


def test_thrust_decays_only_after_takeoff():
    decay = ThrustDecayParams(rate_per_s=0.05)
    # the default world rests the vehicle on the ground
    world = with_effects(load_world("default"), ground_effect=None, thrust_decay=decay)
    with Simulation(world, VEHICLE) as sim:
        for _ in range(50):  # 0.2 s on the ground, rotors at rest
            sim.step((0.0,) * 4)
        assert sim.time_since_takeoff_s == 0.0
        assert sim.effect_forces().thrust_scale == 1.0
        for _ in range(100):  # full rotor speed lifts it off within a few steps
            sim.step((1.2 * HOVER,) * 4)
        since = sim.time_since_takeoff_s
        assert 0.25 < since < 0.4
        assert sim.effect_forces().thrust_scale == pytest.approx(1 - 0.05 * since, abs=0.002)
    with Simulation(bare_world(thrust_decay=decay), VEHICLE) as sim:  # in the air: at once
        for _ in range(250):
            sim.step((HOVER,) * 4)
        assert sim.time_since_takeoff_s == pytest.approx(1.0, abs=0.005)
        down = sim.state().acceleration_m_s2[2]
    assert down == pytest.approx(-0.05 * GRAVITY_M_S2, rel=0.03)


# -- the learnt residual -------------------------------------------------------------------


def constant_model(force_n: tuple[float, float, float]) -> ResidualModel:
    """One linear layer with zero weights: its bias, whatever the features."""
    k = len(FEATURES)
    return ResidualModel(
        weights=(np.zeros((3, k)),),
        biases=(np.array(force_n) / 0.01,),
        input_mean=np.zeros(k),
        input_std=np.ones(k),
        output_scale_n=0.01,
    )


def world_yaml(path: Path, effects: list[dict]) -> Path:
    data = {"vehicle": "nano", "start": {"altitude_m": 1.0}, "effects": effects}
    path.write_text(yaml.safe_dump(data))
    return path


def test_a_learned_residual_read_beside_the_world_file_pushes_the_vehicle(tmp_path: Path):
    (tmp_path / "models").mkdir()
    save_residual_model(tmp_path / "models" / "push.npz", constant_model((0.02, 0.0, -0.01)))
    path = world_yaml(
        tmp_path / "world.yaml", [{"name": "learned_residual", "model_path": "models/push.npz"}]
    )
    world = load_world(path)
    model_path = Path(world.effects.learned_residual.model_path)
    assert model_path.is_absolute() and model_path == (tmp_path / "models" / "push.npz").resolve()
    with Simulation(world, VEHICLE) as sim:
        sim.step((HOVER,) * 4)
        accel = sim.state().acceleration_m_s2
        assert sim.effect_forces().learned_n == pytest.approx((0.02, 0.0, -0.01))
    assert accel[0] == pytest.approx(0.02 / MASS, rel=0.01)
    assert accel[2] == pytest.approx(-0.01 / MASS, rel=0.01)


def test_a_learned_residual_without_its_model_file_is_refused_naming_the_field(tmp_path: Path):
    path = world_yaml(tmp_path / "world.yaml", [{"name": "learned_residual"}])
    with pytest.raises(ConfigError, match=r"learned_residual.model_path: no such file"):
        load_world(path)


def test_a_learnt_force_turns_with_the_heading_and_a_model_names_its_inputs(tmp_path: Path):
    """The network's output is in the heading frame: a forward push flown at yaw 90 deg
    pushes along world y. A model on some of the features loads; one on a feature this
    version does not compute is refused with both lists."""
    model = constant_model((0.02, 0.0, 0.0))
    yaw90 = np.array([[[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]])
    x = residual_features(np.full((1, 4), np.inf), yaw90, np.zeros((1, 3)), np.zeros((1, 3)),
                          np.full((1, 4), 0.01), np.zeros(1), R, MASS * GRAVITY_M_S2)  # fmt: skip
    assert model.force_n(x, headings(yaw90))[0] == pytest.approx((0.0, 0.02, 0.0), abs=1e-12)
    some = dataclasses.replace(
        model, weights=(np.zeros((3, 2)),), input_mean=np.zeros(2), input_std=np.ones(2),
        features=("horizontal_speed_m_s", "height_0"),
    )  # fmt: skip
    save_residual_model(tmp_path / "some.npz", some)
    assert load_residual_model(str(tmp_path / "some.npz")).columns == [7, 0]
    save_residual_model(
        tmp_path / "old.npz", dataclasses.replace(some, features=("vx_m_s", "height_0"))
    )
    with pytest.raises(ConfigError, match=r"written for the features \['vx_m_s', 'height_0'\]"):
        load_residual_model(str(tmp_path / "old.npz"))
