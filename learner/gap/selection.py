"""The selection rule of one forward step of the gap diagnosis, and the tests it is made of:
a fitted candidate's departure from its null (Wald test on the fit's block-robust
covariance, size in catalogue magnitudes) and its parameters on the search's bounds.
`learner/gap/search.py` applies it to the fits of `learner/gap/fit.py`."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from learner.gap.candidates import CANDIDATES, Candidate, Values
from learner.gap.stats import wald_p

if TYPE_CHECKING:
    from learner.gap.fit import Fit

ALPHA = 0.001  # family-wise error of one forward step (Bonferroni over the candidates tried);
# strict because the block sandwich from ~20 one-second blocks a flight runs at about twice
# its nominal level (tests/test_gap_stats.py: 11% at 5%)
MIN_SIZE = 0.25  # an effect smaller than this share of its catalogue magnitude (`typical`, "a
# magnitude worth finding") is not reported: a large effect's slight misfit is absorbed by a
# significant but tiny companion (ground effect rho 2.5 leaves a 1 ms "latency", p 1e-37)


def null_values(name: str, nominal: Values) -> np.ndarray:
    """The candidate's parameters when it adds nothing: the nominal world's, else its null
    (zeros: no ground/ceiling gain, no wall gain, drag, wind, lag, scale error, bias or delay;
    a thrust curve's exponent 1)."""
    if name in nominal:
        return np.asarray(nominal[name], dtype=float)
    return CANDIDATES[name].null_values()


def added_p(f: Fit, name: str, nominal: Values) -> float:
    """Wald p-value of 'the candidate `name` added in fit `f` is at its null values', with the
    fit's block-robust covariance (correlated residuals, misspecification)."""
    i = 0
    for n in f.names:
        k = len(CANDIDATES[n].params)
        if n == name:
            idx = slice(i, i + k)
            return wald_p(f.values[name] - null_values(name, nominal), f.cov[idx, idx])
        i += k
    raise KeyError(name)


def effect_size(
    name: str, value: np.ndarray, nominal: Values, cat: dict[str, Candidate] | None = None
) -> float:
    """The added effect's largest parameter departure from its null, in catalogue magnitudes."""
    typical = np.abs(np.asarray((cat or CANDIDATES)[name].typical, dtype=float))
    return float(np.max(np.abs(np.asarray(value) - null_values(name, nominal)) / typical))


def bound_hits(name: str, value: np.ndarray, cat: dict[str, Candidate] | None = None) -> list[dict]:
    """The parameters sitting on a bound: a compensating, implausible solution (thrust scale
    0.5 against a 4.9 m/s^2 bias) on which the Wald test does not hold, or an effect stronger
    than the catalogue's range. A non-negative quantity's floor (no drag along z, the shortest
    lag) is no such bound; a lower bound below the null (a wind's, a thrust curve's) is."""
    c = (cat or CANDIDATES)[name]
    lo, hi, null = np.asarray(c.lo), np.asarray(c.hi), c.null_values()
    tol = 1e-3 * (hi - lo)
    v = np.asarray(value)
    out = []
    for i, p in enumerate(c.params):
        side = "low" if lo[i] < null[i] and v[i] - lo[i] <= tol[i] else None
        side = "high" if hi[i] - v[i] <= tol[i] else side
        if side:
            bound = float(lo[i] if side == "low" else hi[i])
            out.append({"parameter": p, "value": float(v[i]), "bound": bound, "side": side})
    return out


def at_bound(name: str, value: np.ndarray, cat: dict[str, Candidate] | None = None) -> bool:
    """Whether a parameter sits on a bound (`bound_hits`)."""
    return bool(bound_hits(name, value, cat))


def selected(
    bic_drop: float,
    p_value: float,
    tried: int,
    cv_gain: float,
    size: float = np.inf,
    interior: bool = True,
) -> bool:
    """The selection rule for one forward step, free of the residual's scale: the information
    criterion on the effective sample size falls; the added effect is significant (Wald test,
    block-robust covariance, family-wise ALPHA over the `tried` candidates: Bonferroni); the
    flights left out are predicted better (cross-validated explained variance rises: no
    overfit); the effect is of a relevant size (MIN_SIZE catalogue magnitudes); and no
    parameter sits on its bound (`interior`)."""
    return (
        interior
        and bic_drop > 0.0
        and p_value < ALPHA / max(tried, 1)
        and cv_gain > 0.0
        and size >= MIN_SIZE
    )
