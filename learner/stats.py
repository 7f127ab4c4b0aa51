"""Statistics over repeated trials (thesis 3.6): means with t-based 95% confidence intervals
and Welch's t-test between conditions."""

from __future__ import annotations

import numpy as np
from scipy import stats


def mean_ci95(values: np.ndarray) -> tuple[float, float, float]:
    """(mean, low, high) of a Student-t 95% confidence interval of the mean."""
    v = np.asarray(values, dtype=float)
    mean = float(v.mean())
    if len(v) < 2:
        return mean, mean, mean
    half = float(stats.t.ppf(0.975, len(v) - 1) * v.std(ddof=1) / np.sqrt(len(v)))
    return mean, mean - half, mean + half


def welch(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(t statistic, two-sided p-value) of Welch's unequal-variance t-test."""
    result = stats.ttest_ind(np.asarray(a, float), np.asarray(b, float), equal_var=False)
    return float(result.statistic), float(result.pvalue)


def gap_closed(baseline: np.ndarray, expert: np.ndarray, candidate: np.ndarray) -> float:
    """The share of the baseline-to-expert gap in mean error that the candidate closes."""
    gap = float(np.mean(baseline) - np.mean(expert))
    return float((np.mean(baseline) - np.mean(candidate)) / gap) if gap != 0 else float("nan")
