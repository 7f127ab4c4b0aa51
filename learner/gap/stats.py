"""Statistics for correlated flight data: effective sample size from autocorrelation,
flight-level bootstrap of a weighted mean, multiple-comparison corrections (Holm,
Benjamini-Hochberg). Pure numpy."""

from __future__ import annotations

import numpy as np


def effective_sample_size(x: np.ndarray) -> float:
    """N / (1 + 2 sum of autocorrelations), the sum cut at the first non-positive lag (Geyer's
    initial positive sequence, simplified)."""
    x = np.asarray(x, dtype=float)
    n = len(x)
    if n < 3:
        return float(n)
    x = x - x.mean()
    var = float(np.dot(x, x)) / n
    if var == 0.0:
        return float(n)
    f = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(f * np.conj(f))[:n] / (n * var)
    total = 0.0
    for k in range(1, n):
        if acf[k] <= 0.0:
            break
        total += acf[k]
    return float(n / (1.0 + 2.0 * total))


def ess_ratio(series: list[np.ndarray]) -> float:
    """Effective samples per sample over several flights' (N, k) residual series."""
    n = sum(len(s) for s in series)
    ess = 0.0
    for s in series:
        s2 = s.reshape(len(s), -1)
        ess += float(np.mean([effective_sample_size(s2[:, j]) for j in range(s2.shape[1])]))
    return min(1.0, ess / n) if n else 1.0


def bootstrap_mean(
    sums: np.ndarray, counts: np.ndarray, resamples: int, rng: np.random.Generator
) -> np.ndarray:
    """Bootstrap distribution of sum(sums) / sum(counts) with flights resampled with
    replacement. `sums`, `counts`: (flights, bins); returns (resamples, bins)."""
    flights = sums.shape[0]
    pick = rng.integers(0, flights, size=(resamples, flights))
    w = np.zeros((resamples, flights))
    np.add.at(w, (np.repeat(np.arange(resamples), flights), pick.ravel()), 1.0)
    total, n = w @ sums, w @ counts
    with np.errstate(invalid="ignore", divide="ignore"):
        return total / n


def bootstrap_p(draws: np.ndarray) -> np.ndarray:
    """Two-sided bootstrap p-value of 'mean = 0' per column (with the +1 correction)."""
    finite = np.isfinite(draws)
    b = finite.sum(axis=0)
    below = ((draws <= 0) & finite).sum(axis=0)
    above = ((draws >= 0) & finite).sum(axis=0)
    return np.minimum(1.0, 2.0 * (np.minimum(below, above) + 1) / (b + 1))


def holm(p: np.ndarray) -> np.ndarray:
    """Holm-adjusted p-values (family-wise error)."""
    p = np.asarray(p, dtype=float)
    order = np.argsort(p)
    m = len(p)
    adj = np.maximum.accumulate((m - np.arange(m)) * p[order])
    out = np.empty(m)
    out[order] = np.minimum(adj, 1.0)
    return out


def benjamini_hochberg(p: np.ndarray) -> np.ndarray:
    """Benjamini-Hochberg adjusted p-values (false discovery rate)."""
    p = np.asarray(p, dtype=float)
    m = len(p)
    order = np.argsort(p)
    ranked = p[order] * m / np.arange(1, m + 1)
    adj = np.minimum.accumulate(ranked[::-1])[::-1]
    out = np.empty(m)
    out[order] = np.minimum(adj, 1.0)
    return out


def wald_p(delta: np.ndarray, cov: np.ndarray) -> float:
    """p-value of 'delta = 0' from an estimate `delta` with covariance `cov`: the Wald
    statistic delta' cov^-1 delta against a chi-squared law with len(delta) degrees of freedom."""
    from scipy.stats import chi2

    delta = np.atleast_1d(np.asarray(delta, dtype=float))
    stat = float(delta @ np.linalg.pinv(np.atleast_2d(cov)) @ delta)
    return float(chi2.sf(stat, len(delta))) if np.isfinite(stat) else 1.0


# Beyond this many robust standard deviations a value is not noise (`trimmed_variance`).
TRIM_SDS = 8.0


def trimmed_variance(values: np.ndarray) -> float:
    """The variance of `values` (all elements) without those beyond TRIM_SDS robust standard
    deviations (1.4826 times the median absolute deviation) of their median. Noise does not
    reach so far (for normal noise the variance is the plain one to 1e-12); a few rows of a
    systematic force that changes within a row or two do (an impact, a take-off off a steep
    ground effect): two rows of 18.7 and 2.8 N on a nano once took the residual's noise
    from 5.6 to 84 mN and every candidate to 'not excited'."""
    flat = np.ravel(values)
    centre = float(np.median(flat))
    spread = 1.4826 * float(np.median(np.abs(flat - centre)))
    if spread <= 0.0:
        return float(np.var(flat))
    return float(np.var(flat[np.abs(flat - centre) <= TRIM_SDS * spread]))
