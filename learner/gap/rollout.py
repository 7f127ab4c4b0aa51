"""How far a model is from the logged flights: open-loop rollouts (the logged state at one
row, the logged commands and attitude after it, the model's force integrated over a short
horizon) and the closed-loop tracking difference of replayed missions."""

from __future__ import annotations

import numpy as np

from learner.flightlogs.flightlog import FlightLog
from learner.gap.candidates import Values, world_force
from learner.gap.flightdata import FlightData
from simbridge.vehicle import GRAVITY_M_S2, Vehicle

HORIZON_S = 0.5
START_EVERY = 5  # rollout starts every 5th row


def rollout_errors(d: FlightData, values: Values, vehicle: Vehicle, horizon_s: float) -> np.ndarray:
    """Position error (m) at `horizon_s` of rollouts started along the flight."""
    h = max(1, round(horizon_s / d.dt_s))
    a = world_force(values, d, vehicle) / vehicle.mass_kg
    a[:, 2] -= GRAVITY_M_S2
    dt = d.dt_s
    weights = dt * dt * (h - np.arange(1, h + 1) + 0.5)  # row k+j's share of the displacement
    errors = []
    for s in np.unique(d.segment):
        idx = np.flatnonzero(d.segment == s)
        if len(idx) <= h:
            continue
        p, v, acc = d.position_m[idx], d.velocity_at_m_s[idx], a[idx]
        starts = np.arange(0, len(idx) - h, START_EVERY)
        windows = acc[starts[:, None] + np.arange(1, h + 1)[None, :]]  # (S, h, 3)
        shift = np.einsum("shk,h->sk", windows, weights)
        pred = p[starts] + v[starts] * h * dt + shift
        errors.append(np.linalg.norm(p[starts + h] - pred, axis=1))
    return np.concatenate(errors) if errors else np.zeros(0)


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else float("nan")


def tracking_difference_m(real: FlightLog, sim: FlightLog) -> float:
    """RMS distance between the replayed and the logged positions over their common time."""
    t0, t1 = max(real.time_s[0], sim.time_s[0]), min(real.time_s[-1], sim.time_s[-1])
    keep = (real.time_s >= t0) & (real.time_s <= t1)
    if keep.sum() < 2:
        return float("nan")
    t = real.time_s[keep]
    sim_p = np.column_stack([np.interp(t, sim.time_s, sim.position_m[:, i]) for i in range(3)])
    return rms(np.linalg.norm(real.position_m[keep] - sim_p, axis=1))


def shrink(before: float, after: float) -> float:
    """The share of the gap the correction removes (1: all of it; negative: it grew)."""
    return float(1.0 - after / before) if before > 0 else float("nan")
