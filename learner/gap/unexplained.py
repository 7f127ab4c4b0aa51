"""What the catalogue cannot explain: the residual left after the chosen effects, learnt by a
small Lipschitz-bounded network on regime features both a log and the simulator have
(simbridge/effects/learned.py), with

- a test of whether anything systematic is left: the network trained on the fitting flights
  and scored on the held-out ones (without them: trained on some fitting flights and scored
  on the others, on alternate 5 s blocks with one fitting flight); what it removes there,
  by a clear margin, is structure outside the catalogue (learner/gap/structure.py), and the
  inputs that carry it are named;
- the unexplained share of the gap: the systematic force gap after the catalogue over the
  gap before it;
- its shape: partial dependence of the learnt force on height, time since take-off, speed
  and thrust;
- the model itself, which a corrected world carries as a `learned_residual` effect.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from learner.gap.candidates import Values
from learner.gap.fit import Problem
from learner.gap.flightdata import FlightData
from learner.gap.residual import SMOOTH_WINDOW_S, force_gap_ms, smooth_per_segment
from learner.gap.residual_net import STATE_INPUTS, train_model
from learner.gap.rollout import shrink
from learner.gap.rotor_forces import rotor_forces_n
from learner.gap.structure import (
    SHARE_MIN,
    STRUCTURE_GAIN,
    carried_by,
    has_structure,
    input_losses,
    noise_margin_n2,
    removed_n2,
    sentence,
)
from simbridge.effects.learned import (
    FEATURES,
    ResidualModel,
    headings,
    residual_features,
    to_heading,
)
from simbridge.vehicle import Vehicle

BLOCK_S = 5.0  # alternate blocks as folds when there is one fitting flight
PDP_POINTS = 25


def features(d: FlightData, values: Values, vehicle: Vehicle) -> np.ndarray:
    """The learnt residual's features of one flight in a world with `values`."""
    return residual_features(
        d.rotor_heights_m,
        d.rotation,
        d.position_m,
        d.velocity_m_s,
        rotor_forces_n(values, d, vehicle),
        d.time_s - d.time_s[0],
        vehicle.rotor_radius_m,
        vehicle.weight_n,
    )


@dataclass
class Unexplained:
    model: ResidualModel | None
    summary: dict[str, Any]


def _targets(problem: Problem, values: Values) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per flight: the features and the residual left by `values` in the heading frame,
    averaged over SMOOTH_WINDOW_S (the systematic part is what there is to learn)."""
    merged = {**problem.nominal, **values}
    xs, ys = [], []
    for d, r, p in zip(problem.flights, problem.residuals, problem.predicted(values), strict=True):
        w = max(1, round(SMOOTH_WINDOW_S / d.dt_s))
        xs.append(features(d, merged, problem.vehicle))
        ys.append(to_heading(smooth_per_segment(r - p, d.segment, w), headings(d.rotation)))
    return xs, ys


def _gap(flights: list[FlightData], residuals: list[np.ndarray], noise_var: float) -> float:
    parts = [
        force_gap_ms(r, d.segment, d.dt_s, noise_var) * len(r)
        for d, r in zip(flights, residuals, strict=True)
    ]
    return float(np.sqrt(sum(parts) / max(sum(len(r) for r in residuals), 1)))


def _folds(problem: Problem) -> list[tuple[list[np.ndarray], list[np.ndarray]]]:
    """(train, test) row masks per flight: flights left out in turn, or alternate blocks."""
    n = len(problem.flights)
    out = []
    if n >= 2:
        for k in range(n):
            train = [np.full(len(d.time_s), i != k) for i, d in enumerate(problem.flights)]
            out.append((train, [~m for m in train]))
        return out
    d = problem.flights[0]
    block = np.floor((d.time_s - d.time_s[0]) / BLOCK_S).astype(int) % 2
    for k in range(2):
        out.append(([block != k], [block == k]))
    return out


# the rows of one flight a network was not trained on: (flight, left, with the network)
Part = tuple[FlightData, np.ndarray, np.ndarray]


def _cross_validated_parts(
    problem: Problem,
    xs: list[np.ndarray],
    ys: list[np.ndarray],
    after: list[np.ndarray],
    inputs: tuple[str, ...],
) -> list[Part]:
    """Each fold's unseen rows, with a network trained on the rest (`_folds`)."""
    parts: list[Part] = []
    for train, test in _folds(problem):
        x = np.concatenate([a[m] for a, m in zip(xs, train, strict=True)])
        y = np.concatenate([a[m] for a, m in zip(ys, train, strict=True)])
        model = train_model(x, y, inputs=inputs)
        for d, a, xf, m in zip(problem.flights, after, xs, test, strict=True):
            if m.any():
                learnt = model.force_n(xf[m], headings(d.rotation[m]))
                parts.append((_masked(d, m), a[m], a[m] - learnt))
    return parts


def learn_unexplained(
    problem: Problem,
    values: Values,
    hold: Problem | None = None,
    inputs: tuple[str, ...] = STATE_INPUTS,
) -> Unexplained:
    """The residual `values` leave on the fitting flights: how large, whether it has structure
    outside the catalogue (learnt on the fitting flights, it shrinks on the `hold` flights;
    without them, on fitting flights left out in turn) and what carries it, and the model
    trained on all of it, with whether a world carrying it is offered."""
    xs, ys = _targets(problem, values)
    after = [r - p for r, p in zip(problem.residuals, problem.predicted(values), strict=True)]
    before_gap = _gap(problem.flights, problem.residuals, problem.noise_var)
    after_gap = _gap(problem.flights, after, problem.noise_var)
    share = after_gap / before_gap if before_gap > 0 else 0.0
    x_all, y_all = np.concatenate(xs), np.concatenate(ys)
    model = train_model(x_all, y_all, inputs=inputs)
    held = hold is not None and bool(hold.flights)
    if hold is not None and held:
        parts, x_test, y_test = _held_out_parts(hold, values, model)
        gain, where = _parts_gain(parts, hold.noise_var), "the held-out flights"
        margin = noise_margin_n2(parts, hold.noise_var)
    else:  # the fitting flights left out in turn (a network per fold) stand in for them
        parts = _cross_validated_parts(problem, xs, ys, after, inputs)
        first = _folds(problem)[0][1]
        x_test = np.concatenate([a[m] for a, m in zip(xs, first, strict=True)])
        y_test = np.concatenate([a[m] for a, m in zip(ys, first, strict=True)])
        x_all = np.concatenate([a[~m] for a, m in zip(xs, first, strict=True)])
        y_all = np.concatenate([a[~m] for a, m in zip(ys, first, strict=True)])
        gain, where = _parts_gain(parts, problem.noise_var), "fitting flights it was not trained on"
        margin = noise_margin_n2(parts, problem.noise_var)
    removed = removed_n2(parts)
    structure = has_structure(gain, removed, margin)
    carriers = input_losses(x_all, y_all, x_test, y_test, inputs) if structure else None
    groups = (carriers or {}).get("inputs", [])
    summary: dict[str, Any] = {
        "share": float(share),
        "gap_before_n": before_gap,
        "gap_after_catalogue_n": after_gap,
        "scored_on": "held_out" if held else "cross_validated",
        "learnt_gain": gain,
        "learnt_removed_n2": removed,
        "noise_margin_n2": margin,
        "structure": structure,
        "significant": bool(structure and share >= SHARE_MIN),
        "explained": not structure,
        "inputs": groups,
        "carried_by": carried_by(groups),
        "network_inputs": list(model.features),  # those that varied in training
        "sentence": sentence(share, gain, structure, groups if structure else None, where),
        "learned_world": learned_world(structure, gain, where),
        "shape": partial_dependence(model, np.concatenate(xs)),
    }
    return Unexplained(model, summary)


def learned_world(structure: bool, gain: float | None, where: str) -> dict[str, Any]:
    """Whether the corrected world with the learnt residual is offered, and why: only where
    the residual shrinks what the catalogue leaves on flights it was not trained on."""
    if structure:
        return {
            "offered": True,
            "why": f"the learnt residual removes {float(gain or 0.0) * 100:.0f}% of what the "
            f"catalogue leaves on {where}",
        }
    if gain is None or not np.isfinite(gain):
        how = "n/a, because the catalogue leaves no gap there above the noise to shrink"
    elif gain < 0.0:
        how = f"it leaves {-gain * 100:.0f}% more than the catalogue alone"
    elif gain < STRUCTURE_GAIN:
        how = f"it removes {gain * 100:.0f}%, under {STRUCTURE_GAIN * 100:.0f}%"
    else:
        how = f"it removes {gain * 100:.0f}%, within the noise"
    return {
        "offered": False,
        "why": f"the learnt residual does not shrink what the catalogue leaves on {where} ({how})",
    }


def _parts_gain(parts: list[Part], noise_var: float) -> float | None:
    """The share of the systematic gap left on unseen rows that the network removes; None
    where there is no gap above the noise to remove."""
    left = sum(force_gap_ms(a, d.segment, d.dt_s, noise_var) * len(a) for d, a, _ in parts)
    learnt = sum(force_gap_ms(b, d.segment, d.dt_s, noise_var) * len(b) for d, _, b in parts)
    if left <= 0.0:
        return None
    return float(shrink(np.sqrt(left), np.sqrt(learnt)))


def _held_out_parts(
    hold: Problem, values: Values, model: ResidualModel
) -> tuple[list[Part], np.ndarray, np.ndarray]:
    """The held-out flights' parts, and their features and smoothed residual left by
    `values` (the rows the leave-one-input-out networks are scored on)."""
    xs, ys = _targets(hold, values)
    after = [r - p for r, p in zip(hold.residuals, hold.predicted(values), strict=True)]
    parts = [
        (d, a, a - model.force_n(x, headings(d.rotation)))
        for d, a, x in zip(hold.flights, after, xs, strict=True)
    ]
    return parts, np.concatenate(xs), np.concatenate(ys)


def _masked(d: FlightData, m: np.ndarray) -> FlightData:
    """The rows `m` of a flight, with segments split where rows were dropped."""
    import dataclasses

    idx = np.flatnonzero(m)
    breaks = np.concatenate([[0], np.cumsum(np.diff(idx) > 1)])
    segment = d.segment[idx] * 10_000 + breaks
    return dataclasses.replace(d, time_s=d.time_s[idx], segment=segment)


def partial_dependence(model: ResidualModel, x: np.ndarray) -> dict[str, Any]:
    """The learnt force (N, heading frame: forward, left, up) against height (all rotors
    together), time since take-off, horizontal speed and total thrust, the other features as
    logged (averaged)."""
    if len(x) > 2000:
        x = x[np.linspace(0, len(x) - 1, 2000).astype(int)]
    out: dict[str, Any] = {}
    heights = [FEATURES.index(f"height_{i}") for i in range(4)]
    thrusts = [FEATURES.index(f"thrust_{i}") for i in range(4)]
    t_col = FEATURES.index("time_since_takeoff_s")
    speed = FEATURES.index("horizontal_speed_m_s")
    lo_h, hi_h = np.percentile(x[:, heights], [1, 99])
    grids = {
        "height_log1p_radii": (heights, np.linspace(lo_h, hi_h, PDP_POINTS)),
        "time_since_takeoff_s": ([t_col], np.linspace(0, x[:, t_col].max(), PDP_POINTS)),
        "horizontal_speed_m_s": (
            [speed],
            np.linspace(0.0, np.percentile(x[:, speed], 99), PDP_POINTS),
        ),
        "thrust_per_rotor_over_quarter_weight": (
            thrusts,
            np.linspace(*np.percentile(x[:, thrusts], [1, 99]), PDP_POINTS),
        ),
    }
    for name, (cols, grid) in grids.items():
        forces = []
        for g in grid:
            moved = x.copy()
            moved[:, cols] = g
            forces.append(model.heading_force_n(moved).mean(axis=0))
        out[name] = {"grid": grid.tolist(), "force_n": np.array(forces).tolist()}
    return out


def held_out_learned(
    hold: Problem, values: Values, model: ResidualModel | None
) -> dict[str, float] | None:
    """The held-out systematic force gap before, with the catalogue, and with the catalogue
    and the learnt residual."""
    if model is None or not hold.flights:
        return None
    merged = {**hold.nominal, **values}
    after = [r - p for r, p in zip(hold.residuals, hold.predicted(values), strict=True)]
    learnt = [
        a - model.force_n(features(d, merged, hold.vehicle), headings(d.rotation))
        for d, a in zip(hold.flights, after, strict=True)
    ]
    before = _gap(hold.flights, hold.residuals, hold.noise_var)
    cat = _gap(hold.flights, after, hold.noise_var)
    both = _gap(hold.flights, learnt, hold.noise_var)
    return {
        "before": before,
        "after_catalogue": cat,
        "after": both,
        "shrink": shrink(before, both),
        "shrink_catalogue": shrink(before, cat),
    }
