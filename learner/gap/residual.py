"""The residual: per sample, the force the nominal model does not explain,
r = m a - m g - (R f_rotors + the nominal world's modelled effects), g pointing down."""

from __future__ import annotations

import numpy as np

from learner.gap.candidates import Values, world_force
from learner.gap.flightdata import FlightData
from simbridge.vehicle import GRAVITY_M_S2, Vehicle

SMOOTH_WINDOW_S = 0.1  # the "force gap" averages white sensor noise over this window


def residual_n(d: FlightData, nominal: Values, vehicle: Vehicle) -> np.ndarray:
    """(N, 3) world-frame residual force of one flight against the nominal world."""
    m = vehicle.mass_kg
    ma = m * d.acceleration_m_s2
    ma[:, 2] += m * GRAVITY_M_S2
    return ma - world_force(nominal, d, vehicle)


def smooth_per_segment(x: np.ndarray, segment: np.ndarray, window: int) -> np.ndarray:
    """A centred moving average within each segment (edges average what they have)."""
    out = np.empty_like(x, dtype=float)
    kernel = np.ones(window)
    start = (window - 1) // 2  # the centred part of the full convolution: numpy's "same"
    # returns the longer of the two, which for a segment shorter than the window is not it

    def centred(a: np.ndarray) -> np.ndarray:
        return np.convolve(a, kernel, mode="full")[start : start + len(a)]

    for s in np.unique(segment):
        idx = np.flatnonzero(segment == s)
        part = x[idx].reshape(len(idx), -1)
        counts = centred(np.ones(len(idx)))
        out[idx] = np.column_stack(
            [centred(part[:, j]) / counts for j in range(part.shape[1])]
        ).reshape(x[idx].shape)
    return out


def force_gap_ms(
    residual: np.ndarray, segment: np.ndarray, dt_s: float, noise_var: float = 0.0
) -> float:
    """Mean square of the residual's systematic part (N^2): the residual averaged over
    SMOOTH_WINDOW_S per segment, less what white noise of per-component variance
    `noise_var` leaves in such an average."""
    window = max(1, round(SMOOTH_WINDOW_S / dt_s))
    smooth = smooth_per_segment(residual, segment, window)
    return max(float(np.mean(np.sum(smooth**2, axis=1))) - white_floor_ms(noise_var, dt_s), 0.0)


def white_floor_ms(noise_var: float, dt_s: float) -> float:
    """What white noise of per-component variance `noise_var` leaves in a SMOOTH_WINDOW_S
    average of samples `dt_s` apart (N^2, summed over the three components)."""
    return 3.0 * noise_var / max(1, round(SMOOTH_WINDOW_S / dt_s))


def measured_floor_ms(residual: np.ndarray, segment: np.ndarray, dt_s: float) -> float:
    """The noise a SMOOTH_WINDOW_S average keeps (N^2, summed over components), measured
    instead of assumed white: the Allan variance at that window, half the mean square step
    between adjacent non-overlapping window means within each segment. White noise of
    per-component variance v gives 3 v / window, the floor `force_gap_ms` takes off;
    coloured noise (an IMU's flicker, frame vibration, the smoothing of a differentiated
    velocity) keeps more. A systematic force that changes within 0.2 s counts here too, so
    it is taken from the residual left after the correction."""
    window = max(1, round(SMOOTH_WINDOW_S / dt_s))
    steps = []
    for s in np.unique(segment):
        x = residual[segment == s]
        n = len(x) // window
        if n >= 2:
            means = x[: n * window].reshape(n, window, -1).mean(axis=1)
            steps.append(np.diff(means, axis=0))
    if not steps:
        return 0.0
    d = np.concatenate(steps)
    return float(0.5 * np.mean(np.sum(d * d, axis=1)))


def gap_over_floor_ms(
    residual: np.ndarray, segment: np.ndarray, dt_s: float, floor_ms: float
) -> float:
    """Mean square of the residual's SMOOTH_WINDOW_S averages (N^2) less `floor_ms`."""
    window = max(1, round(SMOOTH_WINDOW_S / dt_s))
    smooth = smooth_per_segment(residual, segment, window)
    return max(float(np.mean(np.sum(smooth**2, axis=1))) - floor_ms, 0.0)
