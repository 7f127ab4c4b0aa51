"""What the catalogue cannot explain: the residual left after the chosen effects, learnt by a
small Lipschitz-bounded network on regime features both a log and the simulator have
(simbridge/effects/learned.py), with

- a test of whether anything systematic is left: the network is trained on some fitting
  flights and scored on the others (on alternate 5 s blocks with one fitting flight); what it
  removes there is structure, not noise;
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
import torch

from learner.gap.candidates import Values
from learner.gap.fit import Problem
from learner.gap.flightdata import FlightData
from learner.gap.residual import SMOOTH_WINDOW_S, force_gap_ms, smooth_per_segment
from learner.gap.rollout import shrink
from learner.gap.rotor_forces import rotor_forces_n
from learner.network import Adam, linear_layers, project_lipschitz
from simbridge.effects.learned import FEATURES, ResidualModel, residual_features
from simbridge.vehicle import Vehicle

HIDDEN = (32, 32)
LAYER_BOUND = 3.0  # per-layer spectral norm in standardised units: a smooth force field
EPOCHS = 400
MAX_ROWS = 8_000  # rows a training run uses (evenly spaced): enough for 15 inputs
LEARNABLE_MIN = 0.25  # the network removes at least this share of the unseen flights' gap
SHARE_MIN = 0.10  # and the catalogue leaves at least this share of the gap
BLOCK_S = 5.0  # alternate blocks as folds when there is one fitting flight
PDP_POINTS = 25


def features(d: FlightData, values: Values, vehicle: Vehicle) -> np.ndarray:
    """The learnt residual's features of one flight in a world with `values`."""
    return residual_features(
        d.rotor_heights_m,
        d.rotation[:, :, 2],
        d.velocity_m_s,
        rotor_forces_n(values, d, vehicle),
        d.time_s - d.time_s[0],
        vehicle.rotor_radius_m,
        vehicle.weight_n,
    )


def train_model(x: np.ndarray, y: np.ndarray, seed: int = 0) -> ResidualModel:
    """A ReLU network x -> y (N) with spectral-norm bounded layers, full-batch Adam."""
    if len(x) > MAX_ROWS:
        keep = np.linspace(0, len(x) - 1, MAX_ROWS).astype(int)
        x, y = x[keep], y[keep]
    mean = x.mean(axis=0)
    std = np.maximum(x.std(axis=0), 1e-6)
    scale = float(max(np.sqrt(np.mean(y**2)), 1e-9))
    torch.manual_seed(seed)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # a tiny network: threads only contend (25 ms a step on 2 cores)
    try:
        return _train(x, y, mean, std, scale)
    finally:
        torch.set_num_threads(threads)


def _train(
    x: np.ndarray, y: np.ndarray, mean: np.ndarray, std: np.ndarray, scale: float
) -> ResidualModel:
    sizes = (x.shape[1], *HIDDEN, 3)
    layers: list[torch.nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(torch.nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(torch.nn.ReLU())
    net = torch.nn.Sequential(*layers)
    xt = torch.tensor((x - mean) / std, dtype=torch.float32)
    yt = torch.tensor(y / scale, dtype=torch.float32)
    opt = Adam(net.parameters(), lr=3e-3, weight_decay=1e-4)
    for _ in range(EPOCHS):
        opt.zero_grad()
        loss = torch.mean((net(xt) - yt) ** 2)
        loss.backward()
        opt.step()
        project_lipschitz(net, LAYER_BOUND)
    lin = linear_layers(net)
    return ResidualModel(
        tuple(layer.weight.detach().double().numpy().copy() for layer in lin),
        tuple(layer.bias.detach().double().numpy().copy() for layer in lin),
        mean,
        std,
        scale,
        FEATURES,
    )


@dataclass
class Unexplained:
    model: ResidualModel | None
    summary: dict[str, Any]


def _targets(problem: Problem, values: Values) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per flight: the features and the residual left by `values`, averaged over
    SMOOTH_WINDOW_S (the systematic part is what there is to learn)."""
    merged = {**problem.nominal, **values}
    xs, ys = [], []
    for d, r, p in zip(problem.flights, problem.residuals, problem.predicted(values), strict=True):
        w = max(1, round(SMOOTH_WINDOW_S / d.dt_s))
        xs.append(features(d, merged, problem.vehicle))
        ys.append(smooth_per_segment(r - p, d.segment, w))
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


def learn_unexplained(problem: Problem, values: Values) -> Unexplained:
    """The residual `values` leave on the fitting flights: is it systematic (learnable on
    flights not trained on), how large, and the model trained on all of it."""
    xs, ys = _targets(problem, values)
    after = [r - p for r, p in zip(problem.residuals, problem.predicted(values), strict=True)]
    before_gap = _gap(problem.flights, problem.residuals, problem.noise_var)
    after_gap = _gap(problem.flights, after, problem.noise_var)
    cv_before, cv_after = 0.0, 0.0
    for train, test in _folds(problem):
        x = np.concatenate([a[m] for a, m in zip(xs, train, strict=True)])
        y = np.concatenate([a[m] for a, m in zip(ys, train, strict=True)])
        model = train_model(x, y)
        for d, a, xf, m in zip(problem.flights, after, xs, test, strict=True):
            if not m.any():
                continue
            part = _masked(d, m)
            left = a[m]
            learnt = left - model.force_n(xf[m])
            cv_before += force_gap_ms(left, part.segment, d.dt_s, problem.noise_var) * m.sum()
            cv_after += force_gap_ms(learnt, part.segment, d.dt_s, problem.noise_var) * m.sum()
    learnable = shrink(np.sqrt(cv_before), np.sqrt(cv_after)) if cv_before > 0 else 0.0
    share = after_gap / before_gap if before_gap > 0 else 0.0
    significant = bool(learnable >= LEARNABLE_MIN and share >= SHARE_MIN)
    model = train_model(np.concatenate(xs), np.concatenate(ys))
    summary: dict[str, Any] = {
        "share": float(share),
        "gap_before_n": before_gap,
        "gap_after_catalogue_n": after_gap,
        "learnable_share": float(learnable),
        "significant": significant,
        "explained": not significant,
        "sentence": sentence(share, learnable, significant),
        "shape": partial_dependence(model, np.concatenate(xs)),
    }
    return Unexplained(model, summary)


def _masked(d: FlightData, m: np.ndarray) -> FlightData:
    """The rows `m` of a flight, with segments split where rows were dropped."""
    import dataclasses

    idx = np.flatnonzero(m)
    breaks = np.concatenate([[0], np.cumsum(np.diff(idx) > 1)])
    segment = d.segment[idx] * 10_000 + breaks
    return dataclasses.replace(d, time_s=d.time_s[idx], segment=segment)


def _carried(learnable: float) -> str:
    """What a network on the regime features does on flights it was not trained on, in words:
    a share removed, never a negative or undefined one."""
    if not np.isfinite(learnable):
        return (
            "a network on the regime features could not be scored on flights it was not trained on"
        )
    if learnable < 0.0:
        return (
            "a network on the regime features does not carry over to flights it was not "
            f"trained on (it leaves {-learnable * 100:.0f}% more than it was given)"
        )
    return (
        f"a network on the regime features removes {learnable * 100:.0f}% of that on flights "
        "it was not trained on"
    )


def sentence(share: float, learnable: float, significant: bool) -> str:
    if significant:
        return (
            f"the catalogue leaves {share * 100:.0f}% of the systematic force gap unexplained, "
            f"and it is structure, not noise: a network on the regime features removes "
            f"{learnable * 100:.0f}% of it on flights it was not trained on. No catalogue "
            "effect explains it; the effects named may stand in for one outside the catalogue"
        )
    head = f"the catalogue leaves {share * 100:.0f}% of the systematic force gap; " + _carried(
        learnable
    )
    if share < SHARE_MIN:
        return head + ": nothing systematic is left that the catalogue misses"
    # a large share no function of the state carries from flight to flight: real, but not
    # the vehicle's (a neighbour's wake, gusts), and no effect of the simulator would give it
    return head + (
        ": what is left is no function of the vehicle's state that holds from flight to "
        "flight (it differs between them: another vehicle's wake, gusts, the logs "
        "themselves; or, where the gap is near the noise floor, noise), so no effect of the "
        "simulator's would reproduce it"
    )


def partial_dependence(model: ResidualModel, x: np.ndarray) -> dict[str, Any]:
    """The learnt force (N, world x y z) against height (all rotors together), time since
    take-off, horizontal speed and total thrust, the other features as logged (averaged)."""
    if len(x) > 2000:
        x = x[np.linspace(0, len(x) - 1, 2000).astype(int)]
    out: dict[str, Any] = {}
    heights = [FEATURES.index(f"height_{i}") for i in range(4)]
    thrusts = [FEATURES.index(f"thrust_{i}") for i in range(4)]
    t_col = FEATURES.index("time_since_takeoff_s")
    vx, vy = FEATURES.index("vx_m_s"), FEATURES.index("vy_m_s")
    lo_h, hi_h = np.percentile(x[:, heights], [1, 99])
    grids = {
        "height_log1p_radii": (heights, np.linspace(lo_h, hi_h, PDP_POINTS)),
        "time_since_takeoff_s": ([t_col], np.linspace(0, x[:, t_col].max(), PDP_POINTS)),
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
            forces.append(model.force_n(moved).mean(axis=0))
        out[name] = {"grid": grid.tolist(), "force_n": np.array(forces).tolist()}
    speed = np.hypot(x[:, vx], x[:, vy])
    grid = np.linspace(0.0, np.percentile(speed, 99), PDP_POINTS)
    forces = []
    for g in grid:
        moved = x.copy()
        scale = np.where(speed > 1e-6, g / np.maximum(speed, 1e-6), 0.0)
        moved[:, vx] *= scale
        moved[:, vy] *= scale
        forces.append(model.force_n(moved).mean(axis=0))
    out["horizontal_speed_m_s"] = {"grid": grid.tolist(), "force_n": np.array(forces).tolist()}
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
        a - model.force_n(features(d, merged, hold.vehicle))
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
