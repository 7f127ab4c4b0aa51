"""Vehicle and world files: loaded into validated dataclasses; bad input named precisely."""

from __future__ import annotations

import math

import pytest
import yaml

from simbridge.config import ConfigError
from simbridge.vehicle import VEHICLES_DIR, load_vehicle
from simbridge.world import load_world, parse_start, with_start
from tests.helpers import run_groundfx


def test_thesis_vehicle_loads_with_its_values():
    v = load_vehicle()
    assert (v.mass_kg, v.rotor_radius_m, v.thrust_coefficient_n_s2, v.max_rotor_speed_rad_s) == (
        0.056,
        0.047,
        2.39e-5,
        140.0,
    )
    assert v.body_size_m == (0.08, 0.08, 0.0252)
    assert v.arm_m == pytest.approx(0.06328 / 2)
    # "hover is about 76 rad/s" (DESIGN.md): sqrt(m g / 4 C_T)
    assert v.hover_rotor_speed_rad_s == pytest.approx(math.sqrt(0.056 * 9.81 / 4 / 2.39e-5))
    assert 75 < v.hover_rotor_speed_rad_s < 77
    with pytest.raises(AttributeError):
        v.mass_kg = 1.0  # frozen


def _vehicle_yaml(tmp_path, **changes):
    data = yaml.safe_load((VEHICLES_DIR / "nano.yaml").read_text())
    data.update(changes)
    path = tmp_path / "vehicle.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(
    ("changes", "expected"),
    [
        ({"mass_kg": -1.0}, "mass_kg: -1 is outside the allowed range (0, 10] kg"),
        ({"rotor_radius_m": "big"}, "rotor_radius_m: expected a number in (0, 1] m"),
        ({"inertia_kg_m2": [1e-5, 1e-5]}, "inertia_kg_m2: expected a list of 3 values"),
        ({"max_rotor_speed_rad_s": 50.0}, "cannot lift the vehicle"),
        ({"wingspan_m": 1.0}, "unknown field 'wingspan_m'"),
    ],
)
def test_bad_vehicle_values_name_file_field_and_range(tmp_path, changes, expected):
    path = _vehicle_yaml(tmp_path, **changes)
    with pytest.raises(ConfigError) as err:
        load_vehicle(path)
    assert str(path) in str(err.value)
    assert expected in str(err.value)


def test_missing_vehicle_field_is_named(tmp_path):
    data = yaml.safe_load((VEHICLES_DIR / "nano.yaml").read_text())
    del data["thrust_coefficient_n_s2"]
    path = tmp_path / "v.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(
        ConfigError, match=r"thrust_coefficient_n_s2: missing; allowed range \(0, 1\]"
    ):
        load_vehicle(path)


def test_packaged_worlds_load():
    default = load_world()
    assert default.physics_rate_hz == 1000 and default.control_period_s == 0.004
    assert default.substeps == 4
    assert default.effects.ground_effect is not None and default.effects.ground_effect.rho == 1.0
    obstacles = load_world("obstacles")
    assert len(obstacles.obstacles) == 3
    wall = obstacles.obstacles[2]
    assert wall.size_m == pytest.approx((2.0, 0.1, 2.0)) and wall.center_m == pytest.approx(
        (0.0, 1.2, 1.0)
    )
    gusty = load_world("gusty")
    assert len(gusty.effects.names()) == 10


@pytest.mark.parametrize(
    ("data", "expected"),
    [
        ({"control_period_s": 0.0025}, "whole number of physics steps"),
        (
            {"physics_rate_hz": 20},
            "physics_rate_hz: 20 is outside the allowed range [50, 10000] Hz",
        ),
        (
            {"effects": [{"name": "ground_effect", "rho": 0}]},
            "rho: 0 is outside the allowed range (0, 50]",
        ),
        ({"effects": [{"name": "antigravity"}]}, "unknown effect 'antigravity'"),
        ({"effects": [{"name": "wind"}]}, "wind acts only through drag"),
        ({"effects": [{"name": "motor_lag"}, {"name": "motor_lag"}]}, "listed twice"),
        ({"obstacles": [{"kind": "box", "center_m": [0, 0, 0]}]}, "size_m: missing"),
        ({"obstacles": [{"kind": "cone"}]}, "kind: expected one of box, wall, step"),
        (
            {"start": {"pitch_deg": 120}},
            "start.pitch_deg: 120 is outside the allowed range [-90, 90] deg",
        ),
    ],
)
def test_bad_world_values_are_named(write_world, data, expected):
    path = write_world(data)
    with pytest.raises(ConfigError) as err:
        load_world(path)
    assert str(path) in str(err.value)
    assert expected in str(err.value)


def test_unparseable_yaml_names_the_line(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("physics_rate_hz: 1000\neffects: [\n")
    with pytest.raises(ConfigError, match=r"broken.yaml: not valid YAML at line"):
        load_world(path)


def test_start_override():
    world = with_start(load_world(), parse_start("0.5,-0.25,1.5"))
    assert world.start.xy_m == (0.5, -0.25) and world.start.altitude_m == 1.5
    with pytest.raises(ConfigError, match="--start: expected X,Y,Z"):
        parse_start("1,2")


def test_broken_world_stops_the_cli_with_a_message_not_a_traceback(write_world):
    path = write_world({"effects": [{"name": "ground_effect", "rho": -2}]})
    result = run_groundfx("sim", "--world", str(path), "--port", "0")
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert str(path) in result.stderr and "rho" in result.stderr and "(0, 50]" in result.stderr
    result = run_groundfx("sim", "--start", "1,2,x", "--port", "0")
    assert (
        result.returncode == 2 and "--start" in result.stderr and "Traceback" not in result.stderr
    )
