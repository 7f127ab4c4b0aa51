"""The noise floor a rule must clear, and the units a bootstrap resamples.

Residual samples are correlated (gusts, slow thermal and battery drifts, the smoothing of a
differentiated velocity), so a mean's uncertainty comes from resampling whole stretches, not
rows: whole flights when there are enough of them, else blocks of BLOCK_S within each flight
(with one or two flights a flight-level bootstrap has no spread at all and calls everything
significant). On top of the bootstrap, a rule must clear the residual's own noise: the
per-sample noise sd (the part faster than SLOW_S) averaged over the effective samples it
rests on, so that a bin or a summary never names what the sensors' noise alone could make.
"""

from __future__ import annotations

import numpy as np

from learner.gap.flightdata import FlightData
from learner.gap.residual import smooth_per_segment
from learner.gap.stats import effective_sample_size, trimmed_variance

# Blocks of this length are the bootstrap's units with fewer than MIN_FLIGHTS flights: long
# against the residual's correlation (a 0.1 s smoothing, gusts of a second or two), short
# enough that a 20 s flight still gives five of them.
BLOCK_S = 4.0
MIN_FLIGHTS = 8
SLOW_S = 1.0  # the residual's part faster than this is its noise
K_SE = 3.0  # a rule's effect must exceed this many standard errors (bootstrap and noise)
RESAMPLES = 2000


def bootstrap_units(flights: list[FlightData]) -> list[np.ndarray]:
    """Per flight, each row's resampling unit (integers distinct across flights): the flight
    itself with MIN_FLIGHTS flights or more, else its BLOCK_S blocks of time."""
    out, start = [], 0
    for d in flights:
        if len(flights) >= MIN_FLIGHTS:
            u = np.zeros(len(d.time_s), dtype=int)
        else:
            u = ((d.time_s - d.time_s[0]) // BLOCK_S).astype(int)
            u = np.unique(u, return_inverse=True)[1]  # no empty blocks (airborne gaps)
        out.append(u + start)
        start += int(u.max()) + 1 if len(u) else 0
    return out


def unit_sums(
    values: list[np.ndarray],
    units: list[np.ndarray],
    bins: list[np.ndarray] | None = None,
    nbins: int = 1,
) -> tuple[np.ndarray, np.ndarray]:
    """Sums of `values` (per flight (N,) or (N, k)) and row counts per unit and bin:
    (units, bins, k) and (units, bins). Rows with a bin outside [0, nbins) are skipped."""
    n_units = int(max(u.max() for u in units)) + 1 if units else 0
    k = values[0].reshape(len(values[0]), -1).shape[1] if values else 1
    sums = np.zeros((n_units, nbins, k))
    counts = np.zeros((n_units, nbins))
    for i, (v, u) in enumerate(zip(values, units, strict=True)):
        b = np.zeros(len(u), dtype=int) if bins is None else bins[i]
        ok = (b >= 0) & (b < nbins)
        np.add.at(sums, (u[ok], b[ok]), v.reshape(len(v), -1)[ok])
        np.add.at(counts, (u[ok], b[ok]), 1.0)
    return sums, counts


def noise_level(series: list[np.ndarray], flights: list[FlightData]) -> tuple[np.ndarray, float]:
    """Per column of the (N, k) `series`: the sd of its part faster than SLOW_S, and the
    effective samples per sample of that part (averaged over columns and flights)."""
    fast, ess, rows = [], 0.0, 0
    for s, d in zip(series, flights, strict=True):
        s2 = s.reshape(len(s), -1)
        window = max(1, round(SLOW_S / d.dt_s))
        f = s2 - smooth_per_segment(s2, d.segment, window)
        fast.append(f)
        ess += float(np.mean([effective_sample_size(f[:, j]) for j in range(f.shape[1])]))
        rows += len(f)
    all_fast = np.concatenate(fast)
    # the moving average takes 1/window of each sample's own noise out with it; rows of a
    # force that changes within a row or two are no noise (`trimmed_variance`)
    window = max(1, round(SLOW_S / flights[0].dt_s))
    spread = [np.sqrt(trimmed_variance(all_fast[:, j])) for j in range(all_fast.shape[1])]
    sd = np.array(spread) * np.sqrt(window / max(window - 1, 1))
    return sd, min(1.0, ess / rows) if rows else 1.0


def noise_se(sd: float | np.ndarray, rows: float | np.ndarray, ess_ratio: float) -> np.ndarray:
    """The noise's standard error of a mean over `rows` samples."""
    return np.asarray(sd) / np.sqrt(np.maximum(np.asarray(rows, dtype=float) * ess_ratio, 1.0))


def normal_p(mean: np.ndarray | float, se: np.ndarray | float) -> np.ndarray:
    """Two-sided p of 'mean = 0' for a normal estimate with standard error `se`: finer in the
    tail than a bootstrap's 1 / RESAMPLES, which many hundred bins' BH correction needs."""
    from scipy.stats import norm

    z = np.abs(np.asarray(mean, dtype=float)) / np.maximum(np.asarray(se, dtype=float), 1e-300)
    return 2.0 * norm.sf(z)


def ci95(draws: np.ndarray) -> tuple[float, float]:
    lo, hi = np.nanpercentile(draws, [2.5, 97.5])
    return float(lo), float(hi)


def se_of(draws: np.ndarray) -> float:
    """The bootstrap's standard error, from the 95% interval's width (robust to the odd
    resample whose unit has no row in a bin)."""
    lo, hi = ci95(draws)
    return (hi - lo) / (2.0 * 1.959964)
