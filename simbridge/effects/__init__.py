"""The catalogue of physical effects, chosen by name in the world YAML.

Each effect is declared once (`simbridge.effects.registry.Effect`): its frozen parameter
dataclass (fields with units and ranges), its force and its fit candidate. The declared
effects are in `simbridge.effects.catalogue`; the simulator composes them, the world loader
parses them and the sim-to-real diagnosis fits the same ones.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from simbridge.config import ConfigError, build
from simbridge.effects import registry
from simbridge.effects.drag import body_drag_for, rotor_drag_for
from simbridge.vehicle import Vehicle


class EffectSet:
    """The enabled effects of one world, read by name (`fx.ground_effect`); a declared
    effect the world does not name reads None. Immutable; `replace` makes a changed copy."""

    def __init__(self, **chosen: Any) -> None:
        known = registry.effects()
        for name, params in chosen.items():
            if name not in known:
                raise TypeError(f"unknown effect {name!r}; known: {', '.join(known)}")
            if params is not None:
                object.__setattr__(self, name, params)

    def __getattr__(self, name: str) -> Any:  # only for the effects the world lacks
        if name in registry.effects():
            return None
        raise AttributeError(name)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("EffectSet is immutable: use replace()")

    def _chosen(self) -> dict[str, Any]:
        return {n: self.__dict__[n] for n in registry.effects() if n in self.__dict__}

    def names(self) -> list[str]:
        """The enabled effects, in the catalogue's order."""
        return list(self._chosen())

    def items(self) -> Iterator[tuple[str, Any]]:
        return iter(self._chosen().items())

    def replace(self, **changes: Any) -> EffectSet:
        """A copy with some effects replaced (None removes one)."""
        return EffectSet(**{**self._chosen(), **changes})

    def __eq__(self, other: object) -> bool:
        return isinstance(other, EffectSet) and self._chosen() == other._chosen()

    def __hash__(self) -> int:
        return hash(tuple(self._chosen().items()))

    def __repr__(self) -> str:
        inner = ", ".join(f"{n}={p!r}" for n, p in self._chosen().items())
        return f"EffectSet({inner})"

    def for_vehicle(self, vehicle: Vehicle) -> EffectSet:
        """The effects with the values their world left to the vehicle filled in (drag's
        coefficients and areas: `simbridge.effects.drag`)."""
        rotor, body = self.rotor_drag, self.body_drag
        return self.replace(
            rotor_drag=None if rotor is None else rotor_drag_for(rotor, vehicle),
            body_drag=None if body is None else body_drag_for(body, vehicle),
        )


def parse_effects(entries: Any, where: str) -> EffectSet:
    """A YAML list of `{name: ..., <params>}` mappings into an EffectSet."""
    if entries is None:
        return EffectSet()
    if not isinstance(entries, list):
        raise ConfigError(f"{where}: expected a list of effects, got {entries!r}")
    known = registry.effects()
    chosen: dict[str, Any] = {}
    for i, entry in enumerate(entries):
        at = f"{where}[{i}]"
        if not isinstance(entry, dict) or "name" not in entry:
            raise ConfigError(f"{at}: expected a mapping with a 'name', got {entry!r}")
        name = entry["name"]
        if name not in known:
            raise ConfigError(f"{at}.name: unknown effect {name!r}; known: {', '.join(known)}")
        if name in chosen:
            raise ConfigError(f"{at}.name: effect {name!r} is listed twice")
        params = {k: v for k, v in entry.items() if k != "name"}
        chosen[name] = build(known[name].params, params, f"{at} ({name})")
    effects = EffectSet(**chosen)
    if effects.wind is not None and effects.rotor_drag is None and effects.body_drag is None:
        raise ConfigError(f"{where}: wind acts only through drag; add rotor_drag or body_drag")
    return effects


# the declared effects (importing the catalogue registers them)
from simbridge.effects import catalogue  # noqa: E402,F401

PARAMS_BY_NAME = registry.LiveView(lambda: {n: e.params for n, e in registry.effects().items()})
UNCATALOGUED = tuple(n for n, e in registry.effects().items() if not e.catalogued)
