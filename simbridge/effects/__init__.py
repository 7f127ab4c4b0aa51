"""The catalogue of physical effects, chosen by name in the world YAML.

Each effect is a frozen parameter dataclass (fields with units and ranges) and pure functions
in its module. The simulator composes them; the sim-to-real diagnosis fits the same ones.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any

from simbridge.config import ConfigError, build
from simbridge.effects.actuators import (
    MassErrorParams,
    MotorLagParams,
    SpinDownParams,
    ThrustCoefficientParams,
    ThrustCurveParams,
    ThrustTiltParams,
)
from simbridge.effects.drag import (
    BodyDragParams,
    RotorDragParams,
    WindParams,
    body_drag_for,
    rotor_drag_for,
)
from simbridge.effects.ground import CeilingEffectParams, GroundEffectParams
from simbridge.effects.learned import LearnedResidualParams
from simbridge.effects.proximity import WallEffectParams
from simbridge.effects.sensor_errors import SensorBiasParams, SensorLatencyParams
from simbridge.effects.uncatalogued import (
    GroundEffectExponentialParams,
    GroundOutwashParams,
    RotorAsymmetryParams,
    ThrustDecayParams,
)
from simbridge.vehicle import Vehicle


@dataclass(frozen=True)
class EffectSet:
    """The enabled effects of one world; None means the effect is absent."""

    ground_effect: GroundEffectParams | None = None
    ceiling_effect: CeilingEffectParams | None = None
    wall_effect: WallEffectParams | None = None
    rotor_drag: RotorDragParams | None = None
    body_drag: BodyDragParams | None = None
    wind: WindParams | None = None
    motor_lag: MotorLagParams | None = None
    spin_down: SpinDownParams | None = None
    thrust_coefficient: ThrustCoefficientParams | None = None
    mass_error: MassErrorParams | None = None
    thrust_tilt: ThrustTiltParams | None = None
    thrust_curve: ThrustCurveParams | None = None
    sensor_latency: SensorLatencyParams | None = None
    sensor_bias: SensorBiasParams | None = None
    learned_residual: LearnedResidualParams | None = None  # what a gap diagnosis learnt
    # outside the diagnosis's catalogue (simbridge/effects/uncatalogued.py): the gap bench's
    # tests of what the diagnosis cannot name
    ground_effect_exponential: GroundEffectExponentialParams | None = None
    thrust_decay: ThrustDecayParams | None = None
    rotor_asymmetry: RotorAsymmetryParams | None = None
    ground_outwash: GroundOutwashParams | None = None

    def names(self) -> list[str]:
        return [f.name for f in fields(self) if getattr(self, f.name) is not None]

    def for_vehicle(self, vehicle: Vehicle) -> EffectSet:
        """The effects with the values their world left to the vehicle filled in (drag's
        coefficients and areas: `simbridge.effects.drag`)."""
        rotor, body = self.rotor_drag, self.body_drag
        return replace(
            self,
            rotor_drag=None if rotor is None else rotor_drag_for(rotor, vehicle),
            body_drag=None if body is None else body_drag_for(body, vehicle),
        )


PARAMS_BY_NAME: dict[str, type] = {
    "ground_effect": GroundEffectParams,
    "ceiling_effect": CeilingEffectParams,
    "wall_effect": WallEffectParams,
    "rotor_drag": RotorDragParams,
    "body_drag": BodyDragParams,
    "wind": WindParams,
    "motor_lag": MotorLagParams,
    "spin_down": SpinDownParams,
    "thrust_coefficient": ThrustCoefficientParams,
    "mass_error": MassErrorParams,
    "thrust_tilt": ThrustTiltParams,
    "thrust_curve": ThrustCurveParams,
    "sensor_latency": SensorLatencyParams,
    "sensor_bias": SensorBiasParams,
    "learned_residual": LearnedResidualParams,
    "ground_effect_exponential": GroundEffectExponentialParams,
    "thrust_decay": ThrustDecayParams,
    "rotor_asymmetry": RotorAsymmetryParams,
    "ground_outwash": GroundOutwashParams,
}
UNCATALOGUED = ("ground_effect_exponential", "thrust_decay", "rotor_asymmetry", "ground_outwash")


def parse_effects(entries: Any, where: str) -> EffectSet:
    """A YAML list of `{name: ..., <params>}` mappings into an EffectSet."""
    if entries is None:
        return EffectSet()
    if not isinstance(entries, list):
        raise ConfigError(f"{where}: expected a list of effects, got {entries!r}")
    chosen: dict[str, Any] = {}
    for i, entry in enumerate(entries):
        at = f"{where}[{i}]"
        if not isinstance(entry, dict) or "name" not in entry:
            raise ConfigError(f"{at}: expected a mapping with a 'name', got {entry!r}")
        name = entry["name"]
        if name not in PARAMS_BY_NAME:
            raise ConfigError(
                f"{at}.name: unknown effect {name!r}; known: {', '.join(PARAMS_BY_NAME)}"
            )
        if name in chosen:
            raise ConfigError(f"{at}.name: effect {name!r} is listed twice")
        params = {k: v for k, v in entry.items() if k != "name"}
        chosen[name] = build(PARAMS_BY_NAME[name], params, f"{at} ({name})")
    effects = EffectSet(**chosen)
    if effects.wind is not None and effects.rotor_drag is None and effects.body_drag is None:
        raise ConfigError(f"{where}: wind acts only through drag; add rotor_drag or body_drag")
    return effects
