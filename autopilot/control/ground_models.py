"""Ground-effect models for the controller, chosen by name: `none`, `analytic`, `neural`.

A model maps the thesis's 12 features (height above the surface, world velocity, attitude
quaternion, rotor speeds) to the ground-effect force in the world frame [N].
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from simbridge.config import ConfigError
from simbridge.effects.ground import cutoff_height_m, ground_effect_force_n
from simbridge.frames import Quat, Vec3
from simbridge.rotors import Quad
from simbridge.vehicle import Vehicle

MODEL_NAMES = ("none", "analytic", "neural")


@dataclass(frozen=True)
class GroundEffectInputs:
    """The 12 features of thesis section 3.5."""

    height_m: float  # centre of mass above the surface below
    velocity_m_s: Vec3
    quaternion: Quat
    rotor_speeds_rad_s: Quad


class GroundEffectModel(Protocol):
    name: str

    def predict(self, inputs: GroundEffectInputs) -> Vec3: ...


@dataclass(frozen=True)
class NoGroundEffect:
    """The baseline: the controller ignores the ground effect."""

    name: str = "none"

    def predict(self, inputs: GroundEffectInputs) -> Vec3:
        return (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class AnalyticGroundEffect:
    """Equation 3.4 with a given rho, per rotor at its own height: the expert pilot."""

    vehicle: Vehicle
    rho: float
    name: str = "analytic"

    def __post_init__(self) -> None:
        v = self.vehicle
        object.__setattr__(self, "_rotors", v.rotor_positions_body_m())
        object.__setattr__(self, "_cutoff", cutoff_height_m(self.rho, v.rotor_radius_m))

    def predict(self, inputs: GroundEffectInputs) -> Vec3:
        v = self.vehicle
        c_t, radius, rho, cutoff = (
            v.thrust_coefficient_n_s2,
            v.rotor_radius_m,
            self.rho,
            self._cutoff,
        )
        w, x, y, z = inputs.quaternion
        # the third row of the rotation matrix: how far each rotor sits above the centre
        r20, r21, r22 = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
        total = 0.0
        for (rx, ry, rz), n in zip(self._rotors, inputs.rotor_speeds_rad_s, strict=True):
            height = inputs.height_m + r20 * rx + r21 * ry + r22 * rz
            total += ground_effect_force_n(c_t * n * n, height, rho, radius, cutoff)
        return (0.0, 0.0, total)


class NeuralGroundEffect:
    """A trained network (the learner's model file) on the 12 features."""

    name = "neural"

    def __init__(self, net: object) -> None:
        self.net = net  # learner.model.GroundEffectNet; swapped whole by the online learner

    def predict(self, inputs: GroundEffectInputs) -> Vec3:
        v, q, n = inputs.velocity_m_s, inputs.quaternion, inputs.rotor_speeds_rad_s
        f = self.net.predict(
            (inputs.height_m, v[0], v[1], v[2], q[0], q[1], q[2], q[3], n[0], n[1], n[2], n[3])
        )
        return (float(f[0]), float(f[1]), float(f[2]))


def default_network(rho: float) -> str:
    """The packaged network trained at the rho closest to `rho` (rho1 or rho2)."""
    return "rho1" if abs(rho - 1.0) <= abs(rho - 2.0) else "rho2"


def make_model(
    name: str, vehicle: Vehicle, rho: float = 1.0, network: str | Path | None = None
) -> GroundEffectModel:
    """The model called `name`; bad choices stop with a message naming the option."""
    if name == "none":
        return NoGroundEffect()
    if name == "analytic":
        if not 0.0 < rho <= 50.0:
            raise ConfigError(f"--rho: {rho:g} is outside the allowed range (0, 50]")
        return AnalyticGroundEffect(vehicle, rho)
    if name == "neural":
        from learner.model import load_model

        return NeuralGroundEffect(
            load_model(network if network is not None else default_network(rho))
        )
    raise ConfigError(f"--model: unknown model {name!r}; choose one of {', '.join(MODEL_NAMES)}")


def fixed_point_step(previous: Vec3, target: Vec3, rotor_thrust_n: float) -> Vec3:
    """The next ground-effect estimate, from the model's value at the last rotor speeds.

    The estimate depends on the rotor speeds it helps choose: a fixed point. Fed straight
    back (next = target) the iteration has slope -G, G = f_ge / T, and diverges once the
    ground effect exceeds the thrust causing it (rho = 2 below 2.5 cm). Moving a fraction
    1 / (1 + G) of the way gives slope 0 for an effect proportional to thrust, as equation
    3.4 is: the fixed point in one step, and no lag where G is small.
    """
    gain = max(target[2], 0.0) / rotor_thrust_n if rotor_thrust_n > 0.0 else 0.0
    beta = 1.0 / (1.0 + gain)
    return (
        previous[0] + beta * (target[0] - previous[0]),
        previous[1] + beta * (target[1] - previous[1]),
        previous[2] + beta * (target[2] - previous[2]),
    )
