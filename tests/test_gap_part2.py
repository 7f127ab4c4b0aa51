"""The diagnosis names the right effect or says it cannot: a wind enters with the
drag it acts through and is the same on every flight; a force outside the catalogue is
reported as unexplained, learnt, and carried into a corrected world the simulator loads."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from learner.flightlogs.flightlog import write_log
from learner.gap.flightdata import prepare
from learner.gap.unexplained import sentence
from learner.gap.verdicts import mark_confidence
from mission.campaigns.gap_diagnosis import run_diagnosis
from simbridge.config import ConfigError
from simbridge.physics import Simulation
from simbridge.world import StartPose, load_world
from tests.test_gap_robust import NANO, synthetic_log, world_file


def test_a_wind_without_a_drag_in_the_nominal_world_is_named_with_its_speed_and_direction(
    tmp_path: Path,
) -> None:
    """Rotor drag and a 3.6 m/s wind in a world that has neither: the wind is present (it
    enters the search together with the drag), within 10% of its speed, and blows the same
    way on every flight. Without yaw, a constant horizontal force is also an accelerometer
    bias in the data, but one of 1.7 m/s^2: beyond a working IMU's, so physics names it."""
    world = world_file(tmp_path / "world.yaml")
    k = np.array([8.8e-5, 4.0e-5])  # four catalogue magnitudes (horizontal, vertical)
    wind = np.array([3.0, -2.0])
    true = {"rotor_drag": k, "wind": wind}
    logs = [
        write_log(synthetic_log(f"f{s}", NANO, world, true, s, seconds=20.0), tmp_path / f"{s}.csv")
        for s in (0, 1, 2)
    ]
    result = run_diagnosis(logs[:2], logs[2:], str(world), tmp_path / "out", 2, replay=False)
    w = result["effects"]["wind"]
    assert w["status"] == "present", w
    got = np.array([w["parameters"]["wx"]["value"], w["parameters"]["wy"]["value"]])
    assert np.linalg.norm(got - wind) <= 0.1 * np.linalg.norm(wind)
    towards = np.degrees(np.arctan2(wind[1], wind[0])) % 360.0
    assert len(w["per_flight"]) == 3
    for row in w["per_flight"]:
        assert abs((row["towards_deg"] - towards + 180.0) % 360.0 - 180.0) < 10.0
    assert result["effects"]["sensor_bias"]["status"] != "present"


def _with_outwash(log, world_path: Path, gain: float):
    """The log with a sideways force near the ground no catalogue effect has: gain x weight x
    exp(-h / 2R) along world +y, h the centre's height."""
    d = prepare(log, load_world(world_path), NANO)
    h = np.where(np.isfinite(d.height_m), d.height_m, 1e9)
    extra = np.zeros_like(log.acceleration_m_s2)
    extra[:, 1] = gain * 9.81 * np.exp(-h / (2.0 * NANO.rotor_radius_m))
    return dataclasses.replace(log, acceleration_m_s2=log.acceleration_m_s2 + extra)


def test_a_force_outside_the_catalogue_is_reported_unexplained_and_learnt(tmp_path: Path) -> None:
    """A sideways outwash near the ground: no catalogue effect is named present with
    confidence, the report gives the unexplained share and where it is (low heights, world
    y), and the learnt residual closes most of the held-out gap in a corrected world that
    carries it as a `learned_residual` effect."""
    world = world_file(tmp_path / "world.yaml")
    logs = []
    for s in (0, 1, 2):
        log = synthetic_log(f"f{s}", NANO, world, {}, s, seconds=30.0)
        logs.append(write_log(_with_outwash(log, world, 0.3), tmp_path / f"{s}.csv"))
    out = tmp_path / "out"
    result = run_diagnosis(logs[:2], logs[2:], str(world), out, 2, replay=False)
    confident = [
        e for e, r in result["effects"].items()
        if r["status"] == "present" and r.get("confident", True)
    ]  # fmt: skip
    assert confident == []
    u = result["unexplained"]
    assert u["significant"] and u["share"] > 0.3, {k: v for k, v in u.items() if k != "shape"}
    assert any(
        w["variable"] == "height_r" and w["component"] == "world_y" for w in u["where"]
    ) or any(w["variable"] == "height_r" for w in u["where"])
    learned = result["gap"]["force_rms_n_learned"]
    assert learned["shrink"] >= 0.6, learned
    assert learned["shrink"] > learned["shrink_catalogue"]
    figures = json.loads((out / "gap.json").read_text())
    assert figures["unexplained"]["sentence"].startswith("the catalogue leaves")
    text = (out / "corrected_world_learned.yaml").read_text()
    assert "learned_residual" in text
    assert "## Unexplained" in (out / "report.md").read_text()
    # the simulator loads the corrected world (the model read beside it) and feels the push
    world_learned = load_world(out / "corrected_world_learned.yaml")
    low = dataclasses.replace(world_learned, start=StartPose(altitude_m=0.15))  # as flown
    with Simulation(low, NANO) as sim:
        hover = NANO.hover_rotor_speed_rad_s
        for _ in range(25):
            sim.step((hover * 1.01,) * 4)
        # outwash along +y near the pad: 6% of the weight at 0.15 m
        assert sim.effect_forces().learned_n[1] > 0.02 * NANO.weight_n


def test_a_learned_residual_whose_model_file_is_missing_is_refused(tmp_path: Path) -> None:
    path = world_file(tmp_path / "world.yaml", effects=[{"name": "learned_residual",
                                                         "model_path": "gone.npz"}])  # fmt: skip
    with pytest.raises(ConfigError, match=r"learned_residual.model_path: no such file .*gone.npz"):
        load_world(path)


@pytest.mark.parametrize("seed", [0])
def test_a_catalogue_effect_leaves_nothing_unexplained(tmp_path: Path, seed: int) -> None:
    """A ground effect the catalogue has (rho 3, against a nominal world without one): named
    present with confidence, and nothing systematic is left."""
    world = world_file(tmp_path / "world.yaml")
    true = {"ground_effect": np.array([3.0])}
    logs = [
        write_log(synthetic_log(f"f{s}", NANO, world, true, s + seed, seconds=20.0),
                  tmp_path / f"{s}.csv")
        for s in (0, 1, 2)
    ]  # fmt: skip
    result = run_diagnosis(logs[:2], logs[2:], str(world), tmp_path / "out", 2, replay=False)
    ge = result["effects"]["ground_effect"]
    assert ge["status"] == "present" and ge["confident"]
    assert ge["parameters"]["rho"]["value"] == pytest.approx(3.0, rel=0.1)
    assert not result["unexplained"]["significant"]


def test_a_thrust_scale_against_an_accelerometer_bias_is_a_cancelling_pair(tmp_path: Path) -> None:
    """C_T x 0.6 against a 3.9 m/s^2 z bias: together they leave about nothing of either, the
    pair is found cancelling, and both are outside their physical ranges."""
    from learner.flightlogs.readers import read_log
    from learner.gap.candidates import nominal_values
    from learner.gap.fit import Fit, problem_for
    from learner.gap.search import cancelling_pairs, set_problems

    world = world_file(tmp_path / "world.yaml")
    path = write_log(synthetic_log("f0", NANO, world, {}, 0, seconds=10.0), tmp_path / "f0.csv")
    w = load_world(world)
    d = prepare(read_log(path, None, NANO), w, NANO)
    problem = problem_for([d], nominal_values(w.effects, NANO), NANO)
    values = {"thrust_mass": np.array([-0.4]), "sensor_bias": np.array([0.0, 0.0, 3.9])}
    cov = np.eye(4) * 1e-6
    cov[0, 3] = cov[3, 0] = 0.99e-6  # the two trade off
    fitted = Fit(("thrust_mass", "sensor_bias"), values, {}, 0.0, 1, 4, 0.0, cov)
    pairs = cancelling_pairs(problem, fitted)
    assert [p["members"] for p in pairs] == [["thrust_mass", "sensor_bias"]]
    assert pairs[0]["cosine"] < -0.9
    issues = set_problems(problem, fitted)
    assert set(issues["implausible"]) == {"thrust_mass", "sensor_bias"}


def test_an_effect_that_differs_between_flights_is_not_named_with_confidence(
    tmp_path: Path,
) -> None:
    """A thrust curve is a property of the vehicle: flights that ask for exponents of 0.7 and
    0.4 (as a neighbour's downwash, read as a curve, does: swaps of the neural-swarm data ask
    for 0.51, 0.35 and 0.25) pool to a plausible value, but refitted on one flight alone it
    leaves the physical range (0.5-2), and the verdict says so."""
    world = world_file(tmp_path / "world.yaml")
    gammas = {0: 0.7, 1: 0.4, 2: 0.55}
    logs = [
        write_log(
            synthetic_log(f"f{s}", NANO, world, {"thrust_curve": np.array([g])}, s, seconds=20.0),
            tmp_path / f"f{s}.csv",
        )
        for s, g in gammas.items()
    ]
    result = run_diagnosis(logs[:2], logs[2:], str(world), tmp_path / "out", 2, replay=False)
    curve = result["effects"]["thrust_curve"]
    assert curve["status"] == "present", curve
    per_flight = {row["flight"]: row["values"][0] for row in curve["per_flight"]}
    assert curve["parameters"]["gamma"]["value"] >= 0.5  # pooled: plausible
    assert per_flight["f1"] < 0.5  # alone: outside the physical range
    assert curve["confident"] is False
    assert "f1" in curve["confidence_note"] and "physical range" in curve["confidence_note"]
    report = (tmp_path / "out/report.md").read_text()
    assert "| thrust_curve | present |" in report and "not named with confidence" in report


def test_a_large_remainder_no_network_carries_over_is_not_called_nothing() -> None:
    """Neural-Swarm's two-vehicle flights: the catalogue left 57% of the gap and a network
    on the vehicle's state removed none of it on the held-out flight (the neighbour's wake
    is not in the state). That is not "nothing systematic left"; a small remainder is."""
    large = sentence(0.57, -0.14, False)
    assert "nothing systematic" not in large and "differs between them" in large
    assert "nothing systematic is left" in sentence(0.05, -0.14, False)
    # a share the network removes is never printed negative or undefined
    for learnable in (-0.52, float("nan")):
        text = sentence(0.3, learnable, False)
        assert "-" not in text.replace("-flight", "") and "nan" not in text, text
    assert "does not carry over" in sentence(0.3, -0.52, False) and "52% more" in sentence(
        0.3, -0.52, False
    )


def test_effects_named_beside_a_remainder_larger_than_what_they_explain_are_not_confident() -> None:
    """Neural-Swarm's large pair: a thrust curve and a latency named while 57% of the gap is
    left, which no network carries to the held-out flight (a neighbour's wake). Learnable or
    not, a catalogue that explains less than it leaves names nothing with confidence."""
    for share, learnable, confident in ((0.57, False, False), (0.3, False, True),
                                        (0.3, True, False)):  # fmt: skip
        effects = {"thrust_curve": {"status": "present"}, "wind": {"status": "absent"}}
        mark_confidence(effects, {"share": share, "significant": learnable})
        assert effects["thrust_curve"]["confident"] is confident
        assert "confident" not in effects["wind"]
        if not confident:
            assert (
                f"leaves {share * 100:.0f}% of the gap"
                in effects["thrust_curve"]["confidence_note"]
            )
