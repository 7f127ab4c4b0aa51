"""The rotors' thrust as the diagnosis models it, from a log's commands: motor lag and a
rotor coasting down (spin_down) at the physics step, the thrust curve, the C_T scale; the
array form of `simbridge.rotor_dynamics` for the catalogue's candidates."""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from learner.gap.flightdata import FlightData
from simbridge.effects.actuators import spin_down_envelope, thrust_curve_array
from simbridge.vehicle import Vehicle

Values = dict[str, np.ndarray]  # candidate name -> its parameters


def rotor_forces_n(values: Values, d: FlightData, vehicle: Vehicle) -> np.ndarray:
    """(N, 4) mean rotor thrusts over each period, through motor lag and a rotor's coasting
    down (spin_down), the thrust curve about a quarter of the weight and the C_T scale (after
    the curve, as the simulator applies it). At the physics step where the dynamics need it;
    a lag alone in its closed form per row, coasting alone on the rows where a rotor coasts."""
    n = d.commands_rad_s
    c_t = vehicle.thrust_coefficient_n_s2
    scale = 1.0 + float(values["thrust_mass"][0]) if "thrust_mass" in values else 1.0
    gamma = float(values["thrust_curve"][0]) if "thrust_curve" in values else None
    pivot_n = 0.25 * vehicle.weight_n
    if "motor_lag" not in values and "spin_down" not in values:
        f = c_t * n * n
        return scale * (f if gamma is None else thrust_curve_array(f, gamma, pivot_n))
    rate = (
        1.0 / (vehicle.hover_rotor_speed_rad_s * float(values["spin_down"][0]))
        if "spin_down" in values
        else None
    )
    if "motor_lag" not in values:  # coasting alone: computed on the rows where a rotor coasts
        assert rate is not None
        return scale * _coasting_forces_n(n, d, rate, c_t, gamma, pivot_n)
    sub = d.substeps
    a = float(np.exp(-(d.dt_s / sub) / values["motor_lag"][0]))  # the lag's pole per step
    if rate is None and gamma is None:  # a lag alone: its closed form per row
        return scale * c_t * _lagged_square_means(n, a, sub)
    # the exact first-order lag of commands held over each period, at the physics step
    y = lfilter([1.0 - a], [1.0, -a], np.repeat(n, sub, axis=0), axis=0, zi=(a * n[:1]))[0]
    if rate is not None:
        t = (d.time_s[:, None] + (d.dt_s / sub) * np.arange(sub)).ravel()
        y = spin_down_envelope(y, t, np.repeat(d.segment, sub), rate)
    f = c_t * y * y
    if gamma is not None:
        f = thrust_curve_array(f, gamma, pivot_n)
    return scale * f.reshape(len(n), sub, 4).mean(axis=1)


def _lagged_square_means(n: np.ndarray, a: float, sub: int) -> np.ndarray:
    """(N, 4) the mean of y^2 over each period's `sub` physics steps, y the exact
    first-order lag (pole `a` per step, from y = n[0]) of the commands `n` held over each
    period: what the physics-step filter gives, at the row rate. Within a period
    y_j = n + (y_start - n) a^j (j = 1..sub), so the mean of y^2 takes two geometric sums."""
    per_row = a**sub
    end = lfilter([1.0 - per_row], [1.0, -per_row], n, axis=0, zi=per_row * n[:1])[0]
    start = np.vstack([n[:1], end[:-1]])
    powers = a ** np.arange(1, sub + 1)
    s1, s2 = float(powers.mean()), float((powers * powers).mean())
    e = start - n
    return n * n + 2.0 * s1 * n * e + s2 * e * e


def _coasting_forces_n(
    n: np.ndarray, d: FlightData, rate: float, c_t: float, gamma: float | None, pivot_n: float
) -> np.ndarray:
    """(N, 4) mean thrusts over each period of held commands `n` with unbraked rotors: what
    the physics-step envelope gives (`rotor_forces_n` with a lag), on the few rows where a
    rotor coasts. The envelope at each row's last physics step is exact at the row rate
    (coasting composes, and within a period it stops at the held command); a period's steps
    coast on from the row before's last step."""
    sub = d.substeps
    step_s = d.dt_s / sub
    last = spin_down_envelope(n, d.time_s, d.segment, rate)
    prev = np.vstack([n[:1], last[:-1]])
    new = np.concatenate([[True], d.segment[1:] != d.segment[:-1]])
    # from the row before's last step (t_prev + (sub - 1) step) to this row's step j
    since = np.diff(d.time_s, prepend=d.time_s[0]) - (sub - 1) * step_s
    first = prev / (1.0 + prev * rate * since[:, None])  # at this row's first step
    rows = np.flatnonzero((first > n).any(axis=1) & ~new)
    f = c_t * n * n
    if gamma is not None:
        f = thrust_curve_array(f, gamma, pivot_n)
    if len(rows):
        p = prev[rows][:, None, :]
        elapsed = (since[rows][:, None] + step_s * np.arange(sub))[:, :, None]
        w = np.maximum(n[rows][:, None, :], p / (1.0 + p * rate * elapsed))
        fr = c_t * w * w
        f[rows] = (fr if gamma is None else thrust_curve_array(fr, gamma, pivot_n)).mean(axis=1)
    return f
