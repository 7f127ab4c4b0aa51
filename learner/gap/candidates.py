"""The effect catalogue as fit candidates, read from the effects' declarations
(`simbridge.effects.catalogue`: parameters, units, bounds, a typical magnitude, what real
vehicles show), and one force model of the whole world, built on simbridge/effects' formulas.

`world_force(values, data, vehicle)` is the force, besides gravity, that a world whose effects
have parameters `values` (name -> array, or absent) puts on the logged flight: rotor thrust
(with motor lag and thrust-coefficient scale), ground, ceiling and wall effects, rotor and body
drag on the air-relative velocity, the force of any effect declared with its own `log_force`,
and the measurement terms an accelerometer bias or delay add.

Bounds and typical magnitudes are the nano's (the declarations'), scaled to any other vehicle
by `catalogue(vehicle)`, so that the same relative effect sits at the same place in its range.
"""

from __future__ import annotations

import functools
import weakref
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from learner.gap.flightdata import FlightData, as_differentiated
from learner.gap.rotor_forces import Values, rotor_forces_n
from simbridge.effects import EffectSet, registry
from simbridge.effects.actuators import thrust_axis_body
from simbridge.effects.catalogue import SIM_WIND_MAX_M_S
from simbridge.effects.drag import (
    BodyDragParams,
    RotorDragParams,
    body_areas_m2,
    body_drag_n,
    rotor_drag_n,
)
from simbridge.effects.ground import (
    CeilingEffectParams,
    GroundEffectParams,
    thrust_gain_array,
)
from simbridge.effects.proximity import WallEffectParams, wall_force_array
from simbridge.effects.registry import Candidate
from simbridge.vehicle import Vehicle, nano_vehicle

__all__ = ["CANDIDATES", "Candidate", "Values", "catalogue", "nominal_values", "world_force"]

# Names, parameters, units and groups (the same for every vehicle); bounds and magnitudes of
# the reference vehicle: use `catalogue(vehicle)` for those. Always the declared candidates.
CANDIDATES = registry.LiveView(registry.candidates)


# A value is outside its physical range only beyond this many of its standard errors: a
# verdict that flipped on a thrust curve of 0.499 against 0.506 (the range's edge 0.5) on
# reruns of the same data now holds
PLAUSIBLE_MARGIN_SE = 1.96


def implausible_parameters(
    name: str, value: np.ndarray, cat: dict[str, Candidate], stderr: np.ndarray | None = None
) -> list[dict]:
    """The parameters outside the physical range (by more than PLAUSIBLE_MARGIN_SE of their
    `stderr`, where given), with what such a value would mean."""
    c = cat[name]
    out = []
    for i, p in enumerate(c.params):
        v = float(value[i])
        margin = 0.0 if stderr is None else PLAUSIBLE_MARGIN_SE * float(stderr[i])
        margin = margin if np.isfinite(margin) else 0.0
        if not c.plausible_lo[i] - margin <= v <= c.plausible_hi[i] + margin:
            out.append(
                {"parameter": p, "value": v, "range": [c.plausible_lo[i], c.plausible_hi[i]],
                 "meaning": c.meaning}
            )  # fmt: skip
    return out


def scale_factors(vehicle: Vehicle) -> dict[str, float]:
    """How the catalogue's dimensional magnitudes grow from the reference vehicle to
    `vehicle` (each candidate's `scale`), so that the same relative effect sits at the same
    place in its range: rotor drag with weight over hover rotor speed (the same share of the
    weight per m/s at hover), wind with sqrt(weight / frontal area) (the air speed at which
    body drag is a given share of the weight). The rest needs none: rho and the wall gain
    are relative to the thrust with distances in rotor radii, C_d applies to the vehicle's
    own areas, the thrust-mass error is a ratio, a bias is an acceleration (relative to g),
    lag and latency are times."""
    return {n: c.scale(vehicle) for n, c in CANDIDATES.items() if c.scale is not None}


def catalogue(vehicle: Vehicle) -> dict[str, Candidate]:
    """The candidates with bounds and typical magnitudes for `vehicle` (`scale_factors`);
    the reference vehicle's are the declared values themselves."""
    return _catalogue(vehicle, registry.version())


@functools.lru_cache(maxsize=16)
def _catalogue(vehicle: Vehicle, _version: int) -> dict[str, Candidate]:
    factors = scale_factors(vehicle)
    out = {}
    for c in CANDIDATES.values():
        f = factors.get(c.name, 1.0)
        if f != 1.0:
            c = replace(
                c,
                lo=tuple(x * f for x in c.lo),
                hi=tuple(x * f for x in c.hi),
                typical=tuple(x * f for x in c.typical),
                plausible_lo=tuple(x * f for x in c.plausible_lo),
                plausible_hi=tuple(x * f for x in c.plausible_hi),
            )
        if c.name == "wind":  # never past the simulator's own range
            c = replace(
                c,
                lo=tuple(max(x, -SIM_WIND_MAX_M_S) for x in c.lo),
                hi=tuple(min(x, SIM_WIND_MAX_M_S) for x in c.hi),
                plausible_lo=tuple(max(x, -SIM_WIND_MAX_M_S) for x in c.plausible_lo),
                plausible_hi=tuple(min(x, SIM_WIND_MAX_M_S) for x in c.plausible_hi),
            )
        out[c.name] = c
    return out


def nominal_values(effects: EffectSet, vehicle: Vehicle | None = None) -> Values:
    """The nominal world's effects as candidate values (absent effects are left out), each
    read by its candidate's `nominal`. With `vehicle`, a body drag's C_d is restated on the
    vehicle's own areas (the candidate's). Drag values the world leaves out are the
    vehicle's defaults (the nano's without one)."""
    effects = effects.for_vehicle(vehicle if vehicle is not None else nano_vehicle())
    out: Values = {}
    for name, c in CANDIDATES.items():
        value = c.nominal(effects, vehicle) if c.nominal is not None else None
        if value is not None:
            out[name] = np.array(value)
    return out


# A fit's numerical Jacobian moves one parameter at a time: the parts of the force that do
# not depend on it are those of the call before. Each part is kept per flight under the
# values it reads (a few of each: the point and its steps), and read-only.
_PARTS: dict[int, dict[tuple, np.ndarray]] = {}
_PARTS_PER_FLIGHT = 32
ROTOR_PARAMETERS = ("thrust_mass", "thrust_curve", "motor_lag", "spin_down")


def _part(
    d: FlightData,
    vehicle: Vehicle,
    what: str,
    names: tuple[str, ...],
    values: Values,
    compute: Callable[[], np.ndarray],
) -> np.ndarray:
    """`compute()`, or its earlier result for the same flight, vehicle and values of `names`."""
    parts = _PARTS.get(id(d))
    if parts is None:
        parts = _PARTS[id(d)] = {}
        weakref.finalize(d, _PARTS.pop, id(d), None)  # an id is reused once `d` is gone
    key = (what, vehicle, *((n, np.asarray(values[n]).tobytes()) for n in names if n in values))
    part = parts.get(key)
    if part is None:
        if len(parts) >= _PARTS_PER_FLIGHT:
            del parts[next(iter(parts))]  # the oldest
        part = parts[key] = compute()
        part.flags.writeable = False
    return part


def world_force(values: Values, d: FlightData, vehicle: Vehicle) -> np.ndarray:
    """(N, 3) world-frame force besides gravity that makes m a of the log (see module doc)."""
    f = _part(d, vehicle, "rotors", ROTOR_PARAMETERS, values,
              lambda: rotor_forces_n(values, d, vehicle))  # fmt: skip
    radius = vehicle.rotor_radius_m
    if "ceiling_effect" in values:
        p = CeilingEffectParams(rho=float(values["ceiling_effect"][0]))
        f = f * (1.0 + _part(d, vehicle, "ceiling", ("ceiling_effect",), values,
                             lambda: thrust_gain_array(d.rotor_ceilings_m, p.rho, radius,
                                                       p.cutoff_for(radius))))  # fmt: skip
    thrust = f.sum(axis=1)
    force = _thrust_axis(values, d) * thrust[:, None]
    if "ground_effect" in values:
        g = GroundEffectParams(rho=float(values["ground_effect"][0]))
        gain = _part(d, vehicle, "ground", ("ground_effect",), values,
                     lambda: thrust_gain_array(d.rotor_heights_m, g.rho, radius,
                                               g.cutoff_for(radius)))  # fmt: skip
        force[:, 2] += (f * gain).sum(axis=1)
    if "wall_effect" in values:
        wall = WallEffectParams(gain=float(values["wall_effect"][0]))
        force += wall_force_array(wall, thrust, radius, d.wall_distances_m)
    force += _part(d, vehicle, "drag", ("rotor_drag", "body_drag", "wind"), values,
                   lambda: _drag(values, d, vehicle))  # fmt: skip
    for name, c in registry.candidates().items():  # effects declared with a force over a log
        if c.log_force is not None and name in values:
            force += c.log_force(values[name], d, vehicle, f, thrust)
    if "sensor_latency" in values:
        # the accelerometer reports the body-frame specific force of `delay` ago; the log
        # turns it into the world frame with the current attitude
        delay = float(values["sensor_latency"][0])
        body = np.einsum("nji,nj->ni", d.rotation, force)
        t = d.time_s
        late = np.column_stack([np.interp(t - delay, t, body[:, i]) for i in range(3)])
        force = np.einsum("nij,nj->ni", d.rotation, late)
    if "sensor_bias" in values:
        force += vehicle.mass_kg * np.einsum("nij,j->ni", d.rotation, values["sensor_bias"])
    if not d.measured_acceleration:  # filtered as the log's acceleration was
        force = as_differentiated(force, d)
    return force


def _thrust_axis(values: Values, d: FlightData) -> np.ndarray:
    """(N, 3) the thrust's direction in the world: body z, or the leaning axis."""
    if "thrust_tilt" not in values:
        return d.rotation[:, :, 2]
    ax, ay, az = thrust_axis_body(*(float(a) for a in values["thrust_tilt"]))
    return np.einsum("nij,j->ni", d.rotation, np.array([ax, ay, az]))


def _drag(values: Values, d: FlightData, vehicle: Vehicle) -> np.ndarray:
    if "rotor_drag" not in values and "body_drag" not in values:
        return np.zeros((len(d.time_s), 3))
    wind = np.append(values.get("wind", np.zeros(2))[:2], 0.0)
    v_air = np.einsum("nji,nj->ni", d.rotation, d.velocity_m_s - wind)  # body frame
    comps = (v_air[:, 0], v_air[:, 1], v_air[:, 2])
    body = np.zeros_like(v_air)
    if "rotor_drag" in values:
        k = values["rotor_drag"]
        params = RotorDragParams(coefficient_n_s_m=(float(k[0]), float(k[0]), float(k[1])))
        body += np.column_stack(rotor_drag_n(params, d.commands_rad_s.sum(axis=1), comps))
    if "body_drag" in values:
        params = BodyDragParams(
            drag_coefficient=float(values["body_drag"][0]),
            area_m2=body_areas_m2(vehicle.body_size_m),
        )
        body += np.column_stack(body_drag_n(params, comps))
    return np.einsum("nij,nj->ni", d.rotation, body)


def to_world_effects(values: Values, vehicle: Vehicle | None = None) -> list[dict]:
    """Candidate values as world-YAML effect entries, each by its candidate's `to_world`
    (thrust_mass as a C_T scale: the same translational dynamics; body drag with
    `vehicle`'s areas, which the fit used)."""
    out: list[dict] = []
    for name, v in values.items():
        c = CANDIDATES.get(name)
        if c is not None and c.to_world is not None:
            out += c.to_world([float(a) for a in v], vehicle)
    return out
