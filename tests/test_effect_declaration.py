"""An effect declared once: a new effect written as one module (its parameters, its force,
its fit candidate) and named in a world file flies in the simulator and is fitted by the
diagnosis, with no other file edited (docs/where-a-change-goes.md)."""

from __future__ import annotations

import dataclasses
import importlib
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from learner.gap.candidates import (
    CANDIDATES,
    catalogue,
    nominal_values,
    to_world_effects,
    world_force,
)
from learner.gap.fit import fit, problem_for
from learner.gap.flightdata import FlightData
from simbridge.effects import PARAMS_BY_NAME, parse_effects, registry
from simbridge.physics import Simulation, with_effects
from simbridge.vehicle import GRAVITY_M_S2, load_vehicle
from simbridge.world import load_world

# The whole of a new effect: what a contributor writes, in one module of their own.
TOY_MODULE = '''
"""A toy effect: a push along world x in proportion to the rotors' thrust."""

from dataclasses import dataclass

import numpy as np

from simbridge.config import param
from simbridge.effects.registry import Effect, candidate_from_params, register


@dataclass(frozen=True)
class ToyPushParams:
    gain: float = param(0.0, unit="1", lo=-0.5, hi=0.5, doc="push along world x over thrust")


def toy_push_n(params, view):
    return (params.gain * view.thrust_n, 0.0, 0.0)


def toy_push_log_n(values, data, vehicle, rotor_forces_n, thrust_n):
    out = np.zeros((len(thrust_n), 3))
    out[:, 0] = values[0] * thrust_n
    return out


register(
    Effect(
        "toy_push",
        ToyPushParams,
        "a push along x",
        force=toy_push_n,
        candidate=candidate_from_params(
            "toy_push", ToyPushParams, ("gain",), typical=(0.05,), log_force=toy_push_log_n
        ),
    )
)
'''
GAIN = 0.1


@pytest.fixture
def toy_world(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """The toy effect's module in a package of its own, imported; a world file naming it."""
    (tmp_path / "toy_effects").mkdir()
    (tmp_path / "toy_effects" / "__init__.py").write_text("")
    (tmp_path / "toy_effects" / "toy_push.py").write_text(TOY_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    importlib.import_module("toy_effects.toy_push")
    world = tmp_path / "toy.yaml"
    world.write_text(
        textwrap.dedent(f"""\
        vehicle: nano
        start: {{xy_m: [0.0, 0.0], altitude_m: 1.0}}
        effects:
          - name: toy_push
            gain: {GAIN}
        """)
    )
    try:
        yield world
    finally:
        registry.unregister("toy_push")
        for name in ("toy_effects.toy_push", "toy_effects"):
            sys.modules.pop(name, None)


def test_a_world_naming_a_declared_effect_flies_with_its_force(toy_world: Path) -> None:
    world = load_world(toy_world)
    assert world.effects.names() == ["toy_push"]
    assert world.effects.toy_push.gain == GAIN
    vehicle = load_vehicle("nano")
    hover = (vehicle.hover_rotor_speed_rad_s,) * 4
    with Simulation(world, vehicle) as sim, Simulation(with_effects(world, toy_push=None),
                                                        vehicle) as plain:  # fmt: skip
        for _ in range(25):
            sim.step(hover)
            plain.step(hover)
        pushed, still = sim.state(), plain.state()
        forces = dict(sim.effect_forces().declared_n)
    # a push of GAIN times the weight along x: GAIN g of acceleration, nothing along y
    assert pushed.acceleration_m_s2[0] == pytest.approx(GAIN * GRAVITY_M_S2, rel=0.02)
    assert still.acceleration_m_s2[0] == pytest.approx(0.0, abs=1e-9)
    assert abs(pushed.velocity_m_s[1]) < 1e-9
    assert forces["toy_push"][0] == pytest.approx(GAIN * vehicle.weight_n, rel=1e-6)


def _synthetic_log(values: dict[str, np.ndarray], seed: int = 0) -> FlightData:
    """Two seconds of a level vehicle whose thrust varies, its acceleration what a world with
    `values` gives, with accelerometer noise."""
    vehicle = load_vehicle("nano")
    n_rows, dt = 500, 0.004
    t = np.arange(n_rows) * dt
    hover = vehicle.hover_rotor_speed_rad_s
    commands = np.repeat((hover * (1.0 + 0.1 * np.sin(2.0 * np.pi * t)))[:, None], 4, axis=1)
    inf3, inf4 = np.full(n_rows, np.inf), np.full((n_rows, 4), np.inf)
    d = FlightData(
        "synthetic", t, dt, np.zeros(n_rows, dtype=int), np.tile([0.0, 0.0, 1.0], (n_rows, 1)),
        np.zeros((n_rows, 3)), np.zeros((n_rows, 3)), np.tile(np.eye(3), (n_rows, 1, 1)),
        np.zeros((n_rows, 3)), commands, np.zeros((n_rows, 3)), True, inf4, inf4, inf4, inf3,
        4, {},
    )  # fmt: skip
    accel = world_force(values, d, vehicle) / vehicle.mass_kg
    accel[:, 2] -= GRAVITY_M_S2
    accel += np.random.default_rng(seed).normal(0.0, 0.05, accel.shape)
    return dataclasses.replace(d, acceleration_m_s2=accel)


def test_the_diagnosis_fits_a_declared_effect_from_its_declaration_alone(
    toy_world: Path,
) -> None:
    vehicle = load_vehicle("nano")
    assert "toy_push" in CANDIDATES and "toy_push" in PARAMS_BY_NAME
    cand = catalogue(vehicle)["toy_push"]
    # units and the fit's range are the parameter's own declaration
    assert (cand.params, cand.units, cand.lo, cand.hi) == (("gain",), ("1",), (-0.5,), (0.5,))

    log = _synthetic_log({"toy_push": np.array([GAIN])})
    problem = problem_for([log], {}, vehicle)
    fitted = fit(problem, ("toy_push",))
    assert fitted.values["toy_push"][0] == pytest.approx(GAIN, rel=0.02)

    # a world's toy effect is a nominal value, and a fitted value a world entry again
    world = load_world(toy_world)
    assert nominal_values(world.effects, vehicle)["toy_push"][0] == GAIN
    entries = to_world_effects(fitted.values, vehicle)
    assert entries[0]["name"] == "toy_push"
    assert parse_effects(entries, "corrected").toy_push.gain == pytest.approx(GAIN, rel=0.02)


def test_an_effect_is_declared_once() -> None:
    with pytest.raises(ValueError, match="declared twice"):
        registry.register(registry.effects()["ground_effect"])
