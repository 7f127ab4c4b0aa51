"""A thrust curve (rotors whose thrust grows faster or slower than the modelled C_T n^2 away
from hover): the simulator's effect, the candidate, and how the diagnosis tells it from a
thrust scale or a mass error (they scale the thrust; a curve moves it with T - W) and says
when the flights cannot (a hover)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from learner.flightlogs.flightlog import FlightLog
from learner.gap import fit as gapfit
from learner.gap import selection
from learner.gap.candidates import (
    CANDIDATES,
    implausible_parameters,
    nominal_values,
    rotor_forces_n,
    to_world_effects,
    world_force,
)
from learner.gap.flightdata import prepare
from learner.gap.search import forward_search
from learner.gap.verdicts import effect_report
from simbridge.config import ConfigError
from simbridge.effects import parse_effects
from simbridge.effects.actuators import (
    ThrustCoefficientParams,
    ThrustCurveParams,
    thrust_curve_array,
    thrust_curve_forces_n,
)
from simbridge.physics import Simulation, with_effects
from simbridge.vehicle import GRAVITY_M_S2
from simbridge.world import load_world, with_start
from tests.test_gap_robust import NANO, synthetic_log, world_file

PIVOT_N = 0.25 * NANO.weight_n


def test_the_curve_keeps_hover_and_bends_thrust_about_it() -> None:
    f = (PIVOT_N, 2.0 * PIVOT_N, 0.5 * PIVOT_N, 0.0)
    got = thrust_curve_forces_n(f, 1.3, PIVOT_N)
    assert got == pytest.approx((PIVOT_N, 2.0**1.3 * PIVOT_N, 0.5**1.3 * PIVOT_N, 0.0))
    assert thrust_curve_forces_n(f, 1.0, PIVOT_N) == pytest.approx(f)
    assert thrust_curve_array(np.array(f), 1.3, PIVOT_N) == pytest.approx(got)
    # about hover it leaves (gamma - 1)(f - W/4) to first order
    near = thrust_curve_forces_n((1.01 * PIVOT_N,) * 4, 1.3, PIVOT_N)[0]
    assert near - 1.01 * PIVOT_N == pytest.approx(0.3 * 0.01 * PIVOT_N, rel=0.02)


def test_the_effect_parses_from_a_world_and_a_bad_exponent_names_its_field() -> None:
    fx = parse_effects([{"name": "thrust_curve", "gamma": 1.35}], "w")
    assert fx.thrust_curve == ThrustCurveParams(1.35)
    with pytest.raises(ConfigError, match=r"thrust_curve\)\.gamma: 9 is outside"):
        parse_effects([{"name": "thrust_curve", "gamma": 9}], "w")


def _accelerations(world, commands: tuple[float, ...], steps: int = 3) -> list[tuple]:
    with Simulation(world, NANO) as sim:
        out = []
        for _ in range(steps):
            sim.step(commands)
            out.append(sim.state().acceleration_m_s2)
        return out


def test_in_the_simulator_gamma_one_is_the_nominal_world_and_a_curve_moves_thrust_off_hover():
    world = with_effects(with_start(load_world("default"), (0.0, 0.0, 1.0)), ground_effect=None)
    hover = NANO.hover_rotor_speed_rad_s
    up = (hover * 1.1,) * 4  # 1.21 times the hover thrust
    nominal = _accelerations(world, up)
    same = _accelerations(with_effects(world, thrust_curve=ThrustCurveParams(1.0)), up)
    assert same == nominal
    curved = with_effects(world, thrust_curve=ThrustCurveParams(1.3))
    assert _accelerations(curved, (hover,) * 4, 1)[0][2] == pytest.approx(0.0, abs=1e-6)
    expected = (1.21**1.3 - 1.0) * GRAVITY_M_S2
    assert _accelerations(curved, up, 1)[0][2] == pytest.approx(expected, rel=1e-3)
    # a C_T scale applies after the curve: s (W/4) (f/(W/4))^gamma
    both = with_effects(curved, thrust_coefficient=ThrustCoefficientParams(1.05))
    expected = (1.05 * 1.21**1.3 - 1.0) * GRAVITY_M_S2
    assert _accelerations(both, up, 1)[0][2] == pytest.approx(expected, rel=1e-3)


def test_the_candidate_is_physical_from_half_to_twice_and_written_as_the_simulators() -> None:
    c = CANDIDATES["thrust_curve"]
    assert c.null == (1.0,) and c.plausible_lo == (0.5,) and c.plausible_hi == (2.0,)
    assert c.lo[0] < 0.5 and c.hi[0] > 2.0 and not c.needs_accelerometer
    assert selection.null_values("thrust_curve", {}) == pytest.approx([1.0])
    assert selection.effect_size("thrust_curve", np.array([1.3]), {}) == pytest.approx(3.0)
    # its low bound is a bound (below the null), as a wind's is
    assert selection.bound_hits("thrust_curve", np.array([c.lo[0]]))[0]["side"] == "low"
    effects = to_world_effects({"thrust_curve": np.array([1.3])})
    assert effects == [{"name": "thrust_curve", "gamma": 1.3}]
    fx = parse_effects(effects, "w")
    assert nominal_values(fx)["thrust_curve"] == pytest.approx([1.3])


def test_the_fit_model_is_the_simulators(tmp_path: Path) -> None:
    world = world_file(tmp_path / "world.yaml")
    d = prepare(synthetic_log("f0", NANO, world, {}, 0, seconds=5.0), load_world(world), NANO)
    plain = rotor_forces_n({}, d, NANO)
    assert rotor_forces_n({"thrust_curve": np.array([1.0])}, d, NANO) == pytest.approx(plain)
    both = {"thrust_curve": np.array([1.3]), "thrust_mass": np.array([0.05])}
    assert rotor_forces_n(both, d, NANO) == pytest.approx(1.05 * PIVOT_N * (plain / PIVOT_N) ** 1.3)


def _problem(tmp_path: Path, true: dict, seeds=(0, 1), hover: bool = False) -> gapfit.Problem:
    world_path = world_file(tmp_path / "world.yaml")
    world = load_world(world_path)
    logs = []
    for s in seeds:
        log = synthetic_log(f"f{s}", NANO, world_path, true, s, seconds=15.0)
        logs.append(_hovering(log, world, true, s) if hover else log)
    data = [prepare(log, world, NANO) for log in logs]
    problem = gapfit.problem_for(data, nominal_values(world.effects, NANO), NANO)
    problem.ess_ratio = 0.5
    return problem


def _hovering(log: FlightLog, world, true: dict, seed: int) -> FlightLog:
    """The flight held at one point, level, at hover rotor speeds with a 0.2% ripple: the
    thrust hardly leaves the weight. Its logged acceleration is the force model's, noisy."""
    rng = np.random.default_rng(seed)
    n = len(log.time_s)
    hover = NANO.hover_rotor_speed_rad_s
    ripple = 1.0 + 0.002 * np.sin(np.outer(log.time_s, [1.3, 1.7, 2.3, 2.9]))
    still = dataclasses.replace(
        log,
        position_m=np.tile([0.0, 0.0, 0.5], (n, 1)),
        velocity_m_s=np.zeros((n, 3)),
        quaternion=np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
        rotor_speeds_rad_s=hover * ripple,
    )
    d = prepare(still, world, NANO)
    acc = world_force({**nominal_values(world.effects, NANO), **true}, d, NANO)
    acc = acc / NANO.mass_kg - np.array([0.0, 0.0, GRAVITY_M_S2])
    return dataclasses.replace(still, acceleration_m_s2=acc + rng.normal(0, 0.1, acc.shape))


def test_the_search_finds_the_exponent_where_the_thrust_varies(tmp_path: Path) -> None:
    problem = _problem(tmp_path, {"thrust_curve": np.array([1.3])})
    # not collinear with the thrust/mass group: T - W is not a share of T
    sens = {n: gapfit.sensitivities(problem, n) for n in ("thrust_curve", "thrust_mass")}
    r2 = gapfit.collinearity_r2(sens["thrust_curve"], sens["thrust_mass"])
    assert r2 < gapfit.COLLINEAR_R2
    best, _ = forward_search(problem, ["thrust_curve", "thrust_mass", "motor_lag"], folds=2)
    assert best.names == ("thrust_curve",)
    assert best.values["thrust_curve"][0] == pytest.approx(1.3, abs=0.03)


def test_at_hover_the_curve_is_reported_not_identifiable(tmp_path: Path) -> None:
    problem = _problem(tmp_path, {"thrust_curve": np.array([1.3])}, hover=True)
    tried = ["thrust_curve", "thrust_mass"]
    excitation = {c: gapfit.excitation_z(problem, c) for c in CANDIDATES}
    assert excitation["thrust_curve"] < gapfit.Z_EXCITE <= excitation["thrust_mass"]
    excited = [c for c in tried if excitation[c] >= gapfit.Z_EXCITE]
    best, trail = forward_search(problem, tried, folds=2)
    assert "thrust_curve" not in best.names
    verdict = effect_report(problem, best, excitation, excited, trail, tried)["thrust_curve"]
    assert verdict["status"] == "not identifiable" and "not excited" in verdict["why"]


def test_a_thrust_curve_on_its_ranges_edge_within_its_error_is_not_called_unphysical():
    """The physical range's edge is a margin, not a knife edge: 0.499 with a standard error
    of 0.02 is as plausible as 0.506 (reruns on the same data flipped between the two);
    0.45 with the same error is outside it."""
    cat = dict(CANDIDATES)
    se = np.array([0.02])
    assert implausible_parameters("thrust_curve", np.array([0.499]), cat) != []  # no error: edge
    assert implausible_parameters("thrust_curve", np.array([0.499]), cat, se) == []
    assert implausible_parameters("thrust_curve", np.array([0.506]), cat, se) == []
    (far,) = implausible_parameters("thrust_curve", np.array([0.45]), cat, se)
    assert far["parameter"] == "gamma" and far["range"][0] == pytest.approx(0.5)
