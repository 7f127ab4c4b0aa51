"""A leaning thrust axis (a bent frame, motors or an IMU mounted askew): the simulator's effect,
the candidate, and how the diagnosis tells it from an accelerometer bias (the logged
acceleration's mean against the velocity's change) and from a wind (it cannot, at one
heading, unless one of them would be implausible)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from learner.flightlogs.flightlog import FlightLog, write_log
from learner.gap import bias_or_tilt
from learner.gap.candidates import CANDIDATES, to_world_effects
from learner.gap.flightdata import prepare
from mission.campaigns.gap_diagnosis import run_diagnosis
from simbridge.effects import parse_effects
from simbridge.effects.actuators import ThrustTiltParams, thrust_axis_body
from simbridge.physics import Simulation, with_effects
from simbridge.vehicle import GRAVITY_M_S2
from simbridge.world import load_world, with_start
from tests.test_gap_robust import NANO, synthetic_log, world_file


def test_the_thrust_axis_leans_by_the_given_angles_and_stays_a_unit_vector() -> None:
    ax, ay, az = thrust_axis_body(2.0, -1.0)
    assert ax == pytest.approx(math.sin(math.radians(2.0)))
    assert ay == pytest.approx(-math.sin(math.radians(1.0)))
    assert math.hypot(ax, ay, az) == pytest.approx(1.0)
    assert thrust_axis_body(0.0, 0.0) == (0.0, 0.0, 1.0)


def test_a_leaning_thrust_pushes_a_level_hovering_drone_sideways() -> None:
    world = with_start(load_world("default"), (0.0, 0.0, 1.0))
    world = with_effects(world, ground_effect=None, thrust_tilt=ThrustTiltParams((2.0, 0.0)))
    hover = NANO.hover_rotor_speed_rad_s
    with Simulation(world, NANO) as sim:
        sim.step((hover,) * 4)
        accel = sim.state().acceleration_m_s2
    assert accel[0] == pytest.approx(GRAVITY_M_S2 * math.sin(math.radians(2.0)), rel=0.02)
    assert abs(accel[1]) < 1e-3


def test_the_candidate_is_physical_within_three_degrees_and_written_as_the_simulators() -> None:
    c = CANDIDATES["thrust_tilt"]
    assert c.plausible_hi == (3.0, 3.0) and c.hi[0] > 3.0 and not c.needs_accelerometer
    effects = to_world_effects({"thrust_tilt": np.array([1.5, -0.5])})
    assert effects == [{"name": "thrust_tilt", "lean_deg": [1.5, -0.5]}]
    assert parse_effects(effects, "w").thrust_tilt == ThrustTiltParams((1.5, -0.5))


def leaning_log(name: str, world: Path, lean_deg: tuple[float, float], seed: int) -> FlightLog:
    """A flight whose thrust leans by `lean_deg` in the body frame: the attitude turned so that
    the leaning axis carries the specific force the trajectory needs. Its logged acceleration
    is the trajectory's, consistent with its velocity, as a real accelerometer's is."""
    log = synthetic_log(name, NANO, world, {}, seed, seconds=20.0)
    axis = np.array(thrust_axis_body(*lean_deg))
    # the rotation taking the leaning axis to body z, applied before the attitude
    turn, _ = Rotation.align_vectors([[0.0, 0.0, 1.0]], [axis])
    rot = Rotation.from_quat(log.quaternion[:, [1, 2, 3, 0]]) * turn
    return dataclasses.replace(log, quaternion=rot.as_quat()[:, [3, 0, 1, 2]])


def test_the_logged_offset_is_a_bias_not_a_force(tmp_path: Path) -> None:
    world = world_file(tmp_path / "world.yaml")
    w = load_world(world)
    clean = prepare(leaning_log("f0", world, (2.0, 0.0), 0), w, NANO)
    # horizontally (the rule's part; the synthetic thrust's ripple is not in the velocity)
    assert np.abs(bias_or_tilt.logged_offset_m_s2([clean])[:2]).max() < 0.01
    shifted = clean.acceleration_m_s2 + np.array([0.3, 0.0, 0.0])
    offset = bias_or_tilt.logged_offset_m_s2(
        [dataclasses.replace(clean, acceleration_m_s2=shifted)]
    )
    assert offset[:2] == pytest.approx([0.3, 0.0], abs=0.01)
    derived = dataclasses.replace(clean, measured_acceleration=False)
    assert bias_or_tilt.logged_offset_m_s2([derived]) is None
    # the rule: a bias explains a logged offset like its own; a force leaves none
    member = np.array([0.3, 0.0, 0.0])
    assert "a force would have moved" in bias_or_tilt.ruled_out("thrust_tilt", member, offset)
    assert bias_or_tilt.ruled_out("sensor_bias", member, offset) is None
    assert "a real force" in bias_or_tilt.ruled_out("sensor_bias", member, np.zeros(3))
    assert bias_or_tilt.ruled_out("thrust_tilt", member, np.zeros(3)) is None


def test_a_leaning_thrust_is_named_and_a_bias_ruled_out_by_the_velocity(tmp_path: Path) -> None:
    world = world_file(tmp_path / "world.yaml")
    lean = (1.5, -1.0)
    logs = [
        write_log(leaning_log(f"f{s}", world, lean, s), tmp_path / f"f{s}.csv") for s in (0, 1, 2)
    ]
    result = run_diagnosis(logs[:2], logs[2:], str(world), tmp_path / "out", 2, replay=False)
    tilt = result["effects"]["thrust_tilt"]
    assert tilt["status"] == "present", tilt
    got = [tilt["parameters"][p]["value"] for p in ("ax", "ay")]
    assert got == pytest.approx(lean, abs=0.1)
    assert result["effects"]["sensor_bias"]["status"] != "present"


def test_an_accelerometer_bias_is_named_and_a_lean_ruled_out_by_the_velocity(
    tmp_path: Path,
) -> None:
    world = world_file(tmp_path / "world.yaml")
    bias = np.array([0.3, -0.2, 0.0])
    logs = [
        write_log(
            synthetic_log(f"f{s}", NANO, world, {"sensor_bias": bias}, s, seconds=20.0),
            tmp_path / f"f{s}.csv",
        )
        for s in (0, 1, 2)
    ]
    result = run_diagnosis(logs[:2], logs[2:], str(world), tmp_path / "out", 2, replay=False)
    b = result["effects"]["sensor_bias"]
    # the bias carries the fitted value (its z part, at one thrust, grouped with thrust/mass)
    got = [b["parameters"][p]["value"] for p in ("bx", "by")]
    assert got == pytest.approx(bias[:2], abs=0.02), b
    assert "a force would have moved the velocity" in b["alternatives_ruled_out"]["thrust_tilt"]
    assert result["effects"]["thrust_tilt"]["status"] != "present"


def test_a_group_member_says_what_it_would_take_in_the_others_place() -> None:
    from learner.gap.verdicts import _carry_text

    text = _carry_text("thrust_tilt", {"ax": 2.67, "ay": -0.924})
    assert text == "; in its place it would take ax 2.67 deg, ay -0.924 deg"
    assert _carry_text("mass_error", {"c": 0.05}) == "; in its place it would take c 0.05"
    assert _carry_text("wind", None) == ""


def test_a_bias_beside_a_lean_is_told_apart_where_the_logs_measure_the_bias() -> None:
    """Fitted together, a bias and a lean pass as two effects only where the logged
    acceleration's mean departs from the velocity's change as the fitted bias says (its own
    share, not the lean's): the gap bench's `bias_and_tilt` flies it."""
    bias = np.array([-0.29, 0.22, 0.1])  # what a fitted bias puts in the residual, m/s^2
    assert bias_or_tilt.measured_bias(bias, np.array([-0.30, 0.20, 0.0]))
    # the logs show none of it (a force moved the velocity) or a different one
    assert not bias_or_tilt.measured_bias(bias, np.zeros(3))
    assert not bias_or_tilt.measured_bias(bias, np.array([0.3, -0.2, 0.0]))
    # a bias too small for the logged offset to judge
    assert not bias_or_tilt.measured_bias(np.array([0.01, 0.0, 0.0]), np.array([0.01, 0, 0]))


def test_a_bias_beside_a_wind_is_told_apart_where_the_logs_measure_the_bias(
    tmp_path: Path,
) -> None:
    """A blind case: an accelerometer bias of (0.2, -0.1) m/s^2 beside a 0.7 m/s wind on the
    large Crazyflie, flown at one heading. In the residual both are a constant horizontal
    force; the logged acceleration departs from the velocity's change by the bias alone (a
    wind moves the velocity). Before, one group whose bias carried both (bx 35% high)."""
    from mission.campaigns.gap_bench import run_case
    from mission.campaigns.gap_bench_cases import DRAG, GE, Case

    case = Case(
        "bias_wind",
        ({"name": "sensor_bias", "accel_bias_m_s2": [0.2, -0.1, 0.0]},
         {"name": "wind", "mean_m_s": [0.6, 0.4, 0.0]}),
        {"sensor_bias": {"bx": 0.2, "by": -0.1, "bz": 0.0}, "wind": {"wx": 0.6, "wy": 0.4}},
        kind="aggressive", nominal=(GE, DRAG), world={"vehicle": "crazyflie2_large"},
    )  # fmt: skip
    scored = run_case(case, tmp_path, replay=False)
    effects = scored["effects"]
    assert effects["wind"]["status"] == "present"
    bias_errors = effects["sensor_bias"]["relative_errors"]
    assert max(bias_errors) < 0.1  # the bias is the bias, not the bias and the wind
