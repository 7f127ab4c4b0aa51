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
    """(t statistic, two-sided p-value) of Welch's unequal-variance t-test.

    Two samples that agree to rounding are the same (t 0, p 1): without spread, the test
    would divide a rounding difference by zero and call it certain (two conditions that
    both sat the vehicle down, 16.99 mm each, came out p = 0)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    scale = max(float(np.max(np.abs(a))), float(np.max(np.abs(b))), 1e-300)
    if (
        np.ptp(a) <= 1e-12 * scale
        and np.ptp(b) <= 1e-12 * scale
        and abs(float(np.mean(a) - np.mean(b))) <= 1e-12 * scale
    ):
        return 0.0, 1.0
    result = stats.ttest_ind(a, b, equal_var=False)
    return float(result.statistic), float(result.pvalue)


def gap_closed(baseline: np.ndarray, expert: np.ndarray, candidate: np.ndarray) -> float:
    """The share of the baseline-to-expert gap in mean error that the candidate closes."""
    gap = float(np.mean(baseline) - np.mean(expert))
    return float((np.mean(baseline) - np.mean(candidate)) / gap) if gap != 0 else float("nan")


def hedges_g(a: np.ndarray, b: np.ndarray) -> float:
    """Effect size of mean(a) - mean(b) in pooled standard deviations, with Hedges's
    small-sample correction; nan when it is undefined (fewer than 3 values, or no spread and
    no difference), +-inf when the groups differ without any spread."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    na, nb = len(a), len(b)
    if na < 1 or nb < 1 or na + nb < 3:
        return float("nan")
    diff = float(a.mean() - b.mean())
    var_a = a.var(ddof=1) if na > 1 else 0.0
    var_b = b.var(ddof=1) if nb > 1 else 0.0
    pooled = float(np.sqrt(((na - 1) * var_a + (nb - 1) * var_b) / (na + nb - 2)))
    if pooled == 0.0:
        return float("nan") if diff == 0.0 else float(np.copysign(np.inf, diff))
    correction = 1.0 - 3.0 / (4.0 * (na + nb) - 9.0)
    return diff / pooled * correction


def describe(values: np.ndarray) -> dict[str, float]:
    """n, mean, 95% CI and sample standard deviation of one condition."""
    v = np.asarray(values, float)
    mean, lo, hi = mean_ci95(v)
    sd = float(v.std(ddof=1)) if len(v) > 1 else float("nan")
    return {"n": len(v), "mean": mean, "ci_low": lo, "ci_high": hi, "sd": sd}


def compare(a: np.ndarray, b: np.ndarray) -> dict[str, float]:
    """Condition a against condition b: the difference of means, Welch's t and two-sided p,
    Hedges's g. Without spread in either group Welch's test is undefined: then p is 0 for
    groups that differ and 1 for identical ones (deterministic results differ or do not)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if len(a) < 2 or len(b) < 2:
        t, p = float("nan"), float("nan")
    elif a.std() == 0.0 and b.std() == 0.0:
        equal = bool(a.mean() == b.mean())
        t, p = (0.0 if equal else float("inf")), (1.0 if equal else 0.0)
    else:
        t, p = welch(a, b)
    return {"diff": float(a.mean() - b.mean()), "t": t, "p": p, "g": hedges_g(a, b)}


def verdict(relation: str, comparison: dict[str, float], alpha: float = 0.05) -> str:
    """Whether a comparison supports an expectation that a is `lower` than b, or `similar`:
    'supported', 'contradicted' (significant the other way, or a significant difference where
    none was expected) or 'not shown' (no significant difference, or too few trials)."""
    p, diff = comparison["p"], comparison["diff"]
    if not np.isfinite(p):
        return "not shown"
    significant = p < alpha
    if relation == "lower":
        if significant:
            return "supported" if diff < 0 else "contradicted"
        return "not shown"
    if relation == "similar":
        return "contradicted" if significant else "supported"
    raise ValueError(f"relation {relation!r}: choose lower or similar")
