"""A rotor that coasts down on its drag (`spin_down`: no active braking, as the Crazyflie's
brushed motors; the neural-swarm take-off flights fall after each motor cut as a rotor
halving its speed in 0.1-0.3 s lets them) is named with its time, and not confused with a
symmetric motor lag. Synthetic logs of the diagnosis's own force model (test_gap_robust) whose
commands drop by a third for 60 ms once a second, as a controller's thrust cut does."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from learner.flightlogs.flightlog import write_log
from learner.gap.candidates import nominal_values, world_force
from learner.gap.flightdata import prepare
from mission.campaigns.gap_diagnosis import run_diagnosis
from simbridge.vehicle import GRAVITY_M_S2
from simbridge.world import load_world
from tests.test_gap_robust import NANO, synthetic_log, world_file


def flights(folder: Path, world: Path, true: dict) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for seed in (0, 1, 2):
        log = synthetic_log(f"f{seed}", NANO, world, {}, seed, seconds=12.0)
        n = log.rotor_speeds_rad_s.copy()
        cut = (log.time_s % 1.0) < 0.06  # a third less speed: 56% less thrust
        n[cut] *= 2.0 / 3.0
        log = dataclasses.replace(log, rotor_speeds_rad_s=n)
        w = load_world(world)
        acc = world_force({**nominal_values(w.effects, NANO), **true}, prepare(log, w, NANO), NANO)
        acc = acc / NANO.mass_kg - np.array([0.0, 0.0, GRAVITY_M_S2])
        rng = np.random.default_rng(seed + 50)
        log = dataclasses.replace(log, acceleration_m_s2=acc + rng.normal(0, 0.1, acc.shape))
        out.append(write_log(log, folder / f"f{seed}.csv"))
    return out


@pytest.mark.parametrize(
    ("true", "named", "absent"),
    [
        ({"spin_down": np.array([0.3])}, ("spin_down", 0.3), "motor_lag"),
        ({"motor_lag": np.array([0.04])}, ("motor_lag", 0.04), "spin_down"),
    ],
)
def test_a_coasting_rotor_is_named_and_told_from_a_motor_lag(
    tmp_path: Path, true: dict, named: tuple[str, float], absent: str
) -> None:
    world = world_file(tmp_path / "world.yaml")
    logs = flights(tmp_path / "logs", world, true)
    figures = run_diagnosis(logs[:2], logs[2:], str(world), tmp_path / "out", folds=2,
                            replay=False)  # fmt: skip
    effect = figures["effects"][named[0]]
    assert effect["status"] == "present"
    assert effect["parameters"]["tau"]["value"] == pytest.approx(named[1], rel=0.1)
    assert figures["effects"][absent]["status"] != "present"
    assert sorted(figures["chosen"]) == [named[0]]
    assert figures["gap"]["force_rms_n"]["shrink"] >= 0.8


def test_a_lag_alone_at_the_row_rate_is_the_physics_step_filter(tmp_path: Path) -> None:
    """`rotor_forces_n` with a motor lag and neither a coasting rotor nor a thrust curve
    computes each period's mean thrust in closed form at the row rate: the same figures as
    the lag filtered at every physics step and averaged over the period."""
    from scipy.signal import lfilter

    from learner.gap.rotor_forces import rotor_forces_n

    world = world_file(tmp_path / "world.yaml")
    log = synthetic_log("f0", NANO, world, {}, 0, seconds=6.0)
    n = log.rotor_speeds_rad_s.copy()
    n[(log.time_s % 1.0) < 0.06] *= 2.0 / 3.0  # steps for the lag to follow
    d = prepare(dataclasses.replace(log, rotor_speeds_rad_s=n), load_world(world), NANO)
    assert d.substeps == 10  # 100 Hz rows, 1 kHz physics
    for tau in (0.005, 0.04, 0.15):
        a = np.exp(-(d.dt_s / d.substeps) / tau)
        y = np.repeat(d.commands_rad_s, d.substeps, axis=0)
        y = lfilter([1.0 - a], [1.0, -a], y, axis=0, zi=a * d.commands_rad_s[:1])[0]
        steps = NANO.thrust_coefficient_n_s2 * (y * y).reshape(len(n), d.substeps, 4).mean(axis=1)
        row_rate = rotor_forces_n({"motor_lag": np.array([tau])}, d, NANO)
        np.testing.assert_allclose(row_rate, steps, rtol=1e-12)
