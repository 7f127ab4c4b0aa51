"""Effects declared once: a registry of effects keyed by name.

An `Effect` is everything the project needs to know about one physical effect: its
parameters (a frozen dataclass whose fields carry unit, range and meaning through
`simbridge.config.param`), its force on the simulated body (`force`, for an effect the
physics step does not compute itself) and what the sim-to-real diagnosis needs to fit it
(`candidate`). The world loader, the simulator and the diagnosis read this registry; a new
effect is one module that calls `register` (see docs/where-a-change-goes.md).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class BodyView:
    """What a declared effect's `force` may read at one physics step (world frame, z up)."""

    time_s: float
    position_m: tuple[float, ...]
    rotation: tuple[float, ...]  # body to world, row-major 3x3
    velocity_m_s: tuple[float, ...]
    rotor_forces_n: tuple[float, ...]  # the four rotors' thrust, after the rotor effects
    thrust_n: float
    rotor_heights_m: tuple[float, ...]  # inf: nothing below (or no effect asked for rays)
    rotor_radius_m: float
    weight_n: float


@dataclass(frozen=True)
class Candidate:
    """What the diagnosis fits for one effect (or several it cannot tell apart).

    Bounds and magnitudes are the reference vehicle's (the thesis's nano); `scale` grows the
    dimensional ones with another vehicle. `nominal` reads a world's effects as the
    candidate's values, `to_world` writes fitted values back as world-YAML effect entries,
    `log_force` is its force over a log for an effect the diagnosis's world model does not
    compute itself: (values, flight data, vehicle, rotor forces (N, 4), thrust (N,)) -> (N, 3).
    """

    name: str
    params: tuple[str, ...]
    units: tuple[str, ...]
    lo: tuple[float, ...]  # the fit's range
    hi: tuple[float, ...]
    typical: tuple[float, ...]  # a magnitude worth finding: the excitation test's probe
    effects: tuple[str, ...]  # catalogue effects it stands for
    # what a real vehicle shows; a fit outside it is reported as implausible, with `meaning`
    plausible_lo: tuple[float, ...] = ()
    plausible_hi: tuple[float, ...] = ()
    meaning: str = ""
    needs_accelerometer: bool = False  # models the accelerometer: no candidate without one
    # the parameters at which it adds nothing (empty: zeros; a thrust curve's exponent: 1)
    null: tuple[float, ...] = ()
    start: tuple[float, ...] | None = None  # a fit's start without a nominal value (typical)
    multi_start: tuple[float, ...] = ()  # more starts of the first parameter (non-convex)
    walled: bool = False  # a cut-off height steps with the parameter: scan between the steps
    history: bool = False  # its force at a row depends on the rows before it
    scale: Callable[[Any], float] | None = field(default=None, compare=False)
    nominal: Callable[[Any, Any], Sequence[float] | None] | None = field(
        default=None, compare=False
    )
    to_world: Callable[[list[float], Any], list[dict]] | None = field(default=None, compare=False)
    log_force: Callable[..., np.ndarray] | None = field(default=None, compare=False)

    def null_values(self) -> np.ndarray:
        """The parameters at which the candidate adds nothing."""
        return np.array(self.null, dtype=float) if self.null else np.zeros(len(self.params))


@dataclass(frozen=True)
class Effect:
    """One effect: its name in a world YAML, its parameters, its force, its candidate."""

    name: str
    params: type
    doc: str = ""
    # the world-frame force at the centre of mass, (params, BodyView) -> Vec3; None for the
    # effects the physics step computes itself (rotor heights, rays, rotor dynamics)
    force: Callable[[Any, BodyView], Vec3] | None = None
    candidate: Candidate | None = None  # None: outside the diagnosis's catalogue
    catalogued: bool = True  # False: a test of what the diagnosis cannot name


_EFFECTS: dict[str, Effect] = {}
_CANDIDATES: dict[str, Candidate] = {}
_version = [0]


def register(effect: Effect, *, candidate_after: str | None = None) -> Effect:
    """Add `effect` (and its candidate, after `candidate_after` or at the end) by name."""
    if effect.name in _EFFECTS:
        raise ValueError(f"effect {effect.name!r} is declared twice")
    _EFFECTS[effect.name] = effect
    c = effect.candidate
    if c is not None:
        if c.name in _CANDIDATES:
            raise ValueError(f"candidate {c.name!r} is declared twice")
        items = list(_CANDIDATES.items())
        at = len(items)
        if candidate_after is not None:
            at = [k for k, _ in items].index(candidate_after) + 1
        items.insert(at, (c.name, c))
        _CANDIDATES.clear()
        _CANDIDATES.update(items)
    _version[0] += 1
    return effect


def unregister(name: str) -> None:
    """Remove a registered effect and its candidate (a test's toy effect)."""
    effect = _EFFECTS.pop(name)
    if effect.candidate is not None:
        _CANDIDATES.pop(effect.candidate.name, None)
    _version[0] += 1


def version() -> int:
    """Changes whenever the registry does: caches of derived tables key on it."""
    return _version[0]


def effects() -> Mapping[str, Effect]:
    return _EFFECTS


def candidates() -> Mapping[str, Candidate]:
    """The diagnosis's candidates, in the order the diagnosis tries them."""
    return _CANDIDATES


class LiveView(Mapping[str, Any]):
    """A read-only mapping that always shows the registry's current contents."""

    def __init__(self, source: Callable[[], Mapping[str, Any]]) -> None:
        self._source = source

    def __getitem__(self, key: str) -> Any:
        return self._source()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._source())

    def __len__(self) -> int:
        return len(self._source())

    def __repr__(self) -> str:
        return repr(dict(self._source()))


def candidate_from_params(
    name: str,
    params: type,
    fields: Sequence[str],
    *,
    typical: Sequence[float],
    plausible: tuple[Sequence[float], Sequence[float]] | None = None,
    meaning: str = "",
    **more: Any,
) -> Candidate:
    """A candidate whose parameters are fields of the effect's parameter dataclass: names,
    units and the fit's range come from their `param(...)` declarations, the nominal value
    is read from a world's effect and fitted values are written back under the same names."""
    by_name = {f.name: f for f in dataclasses.fields(params)}
    meta = [by_name[f].metadata for f in fields]
    lo = tuple(float(m["lo"]) for m in meta)
    hi = tuple(float(m["hi"]) for m in meta)
    plo, phi = plausible if plausible is not None else (lo, hi)

    def nominal(effect_set: Any, _vehicle: Any) -> Sequence[float] | None:
        p = getattr(effect_set, name)
        return None if p is None else [float(getattr(p, f)) for f in fields]

    def to_world(x: list[float], _vehicle: Any) -> list[dict]:
        return [{"name": name, **dict(zip(fields, x, strict=True))}]

    return Candidate(
        name, tuple(fields), tuple(m["unit"] or "1" for m in meta), lo, hi, tuple(typical),
        (name,), tuple(plo), tuple(phi), meaning, nominal=nominal, to_world=to_world, **more,
    )  # fmt: skip


def declared_forces_n(
    declared: Sequence[tuple[str, Any, Callable[[Any, BodyView], Vec3]]],
    view: BodyView,
    record: dict[str, Vec3],
) -> Vec3:
    """The sum of the declared effects' forces at one physics step; each one's own force is
    written into `record` by name (what the simulator reports)."""
    fx = fy = fz = 0.0
    for name, params, force in declared:
        f = force(params, view)
        record[name] = (float(f[0]), float(f[1]), float(f[2]))
        fx, fy, fz = fx + f[0], fy + f[1], fz + f[2]
    return (fx, fy, fz)
