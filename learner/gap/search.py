"""The forward search over catalogue effects: at every step every remaining candidate is fitted
with the effects already chosen (the catalogue is small), and the candidates are tried in
order of the information criterion until one passes the selection rule (`selection.selected`) and
leaves a set that is physical as a whole: no parameter of any member on a bound of the fit or
outside its physical range (a later effect can push an earlier one there), and no two members
cancelling each other (a thrust scale of 0.5 against a 5 m/s^2 accelerometer bias fits any
residual linear in thrust). Wind acts only through drag: without a drag in the set it enters
together with one (a move of two candidates).
"""

from __future__ import annotations

import numpy as np

from learner.gap import bias_or_tilt
from learner.gap.candidates import implausible_parameters
from learner.gap.fit import (
    COLLINEAR_R2,
    DRAGS,
    STRIDE,
    Fit,
    Problem,
    collinearity_r2,
    cross_validated_ev,
    fit,
    sensitivities,
)
from learner.gap.selection import ALPHA, MIN_SIZE, added_p, bound_hits, effect_size, selected

CANCEL_COSINE = -0.7  # two members' contributions this opposed ...
CANCEL_CORRELATION = 0.9  # ... with parameters this correlated: one unidentifiable group
CANCEL_SIZE = 2.0  # and each contribution this many times what the two explain together
CV_SKIPPED = (
    "not computed: one fitting flight, none to leave out; the step was judged without the "
    "cross-validated check"
)


def moves(problem: Problem, chosen: tuple[str, ...], candidates: list[str]) -> list[tuple]:
    """What one step may add: each remaining candidate; wind with a drag when none is there."""
    has_drag = any(d in chosen or d in problem.nominal for d in DRAGS)
    out: list[tuple[str, ...]] = []
    for c in candidates:
        if c in chosen:
            continue
        if c == "wind" and not has_drag:
            out += [(d, "wind") for d in DRAGS if d in candidates and d not in chosen]
        else:
            out.append((c,))
    return out


def contributions(problem: Problem, f: Fit) -> dict[str, np.ndarray]:
    """Each member's share of the fitted prediction: the prediction with it less the one
    without it (the others at their fitted values), over the fitted rows."""
    full = _stacked(problem, f.values)
    out = {}
    for name in f.names:
        rest = {k: v for k, v in f.values.items() if k != name}
        out[name] = full - _stacked(problem, rest)
    return out


def _stacked(problem: Problem, values: dict) -> np.ndarray:
    return np.concatenate([p[::STRIDE].ravel() for p in problem.predicted(values)])


def cancelling_pairs(problem: Problem, f: Fit) -> list[dict]:
    """Members that cancel each other: opposed contributions (cosine below CANCEL_COSINE),
    each much larger than their sum, with strongly correlated parameters."""
    if len(f.names) < 2:
        return []
    parts = contributions(problem, f)
    index, i = {}, 0
    for name in f.names:
        k = len(f.values[name])
        index[name] = slice(i, i + k)
        i += k
    sd = np.sqrt(np.maximum(np.diag(f.cov), 1e-300))
    corr = f.cov / np.outer(sd, sd)
    out = []
    for a_i, a in enumerate(f.names):
        for b in f.names[a_i + 1 :]:
            ca, cb = parts[a], parts[b]
            na, nb = float(np.linalg.norm(ca)), float(np.linalg.norm(cb))
            if na == 0.0 or nb == 0.0:
                continue
            cosine = float(ca @ cb / (na * nb))
            together = float(np.linalg.norm(ca + cb))
            r = float(np.max(np.abs(corr[index[a], index[b]])))
            if (
                cosine < CANCEL_COSINE
                and min(na, nb) > CANCEL_SIZE * together
                and r > CANCEL_CORRELATION
            ):
                out.append({"members": [a, b], "cosine": cosine, "correlation": r,
                            "sizes_n": [na, nb], "together_n": together})  # fmt: skip
    return out


def collinear_with_chosen(problem: Problem, f: Fit, added: tuple[str, ...]) -> list[list[str]]:
    """Pairs of an added candidate and a member already chosen whose effects on the residual
    the data cannot tell apart (at the fitted values): adding it would make both
    unidentifiable (a body drag beside a wind: in a strong wind C_d and the wind speed trade
    off)."""
    before = [n for n in f.names if n not in added]
    if not before:
        return []
    sens = {n: sensitivities(problem, n, f.values) for n in (*before, *added)}
    out = []
    for a in added:
        for b in before:
            if bias_or_tilt.told_apart(problem, f.values, frozenset({a, b})):
                continue
            r2 = max(collinearity_r2(sens[a], sens[b]), collinearity_r2(sens[b], sens[a]))
            if r2 >= COLLINEAR_R2:
                out.append([a, b])
    return out


def set_problems(problem: Problem, f: Fit) -> dict:
    """What makes a fitted set unphysical: members on a bound of the fit, members outside
    their physical range, cancelling pairs, an accelerometer bias or a leaning thrust the
    logged acceleration contradicts (learner/gap/bias_or_tilt.py)."""
    cat = problem.catalogue
    hits = {n: bound_hits(n, f.values[n], cat) for n in f.names}
    implausible = {n: implausible_parameters(n, f.values[n], cat, f.stderr.get(n)) for n in f.names}
    return {
        "at_bound": {n: h for n, h in hits.items() if h},
        "implausible": {n: v for n, v in implausible.items() if v},
        "cancelling": cancelling_pairs(problem, f),
        "contradicted": _contradicted(problem, f),
    }


def _contradicted(problem: Problem, f: Fit) -> dict[str, str]:
    members = [n for n in f.names if n in bias_or_tilt.BIAS_OR_TILT]
    if not members:
        return {}
    logged = bias_or_tilt.logged_offset_m_s2(problem.flights)
    if logged is None:
        return {}
    parts = contributions(problem, f)
    out = {}
    for n in members:
        why = bias_or_tilt.contradicted(n, parts[n], logged, problem.vehicle.mass_kg)
        if why:
            out[n] = why
    return out


def forward_search(problem: Problem, candidates: list[str], folds: int) -> tuple[Fit, list[dict]]:
    """Add, one move at a time, the best candidate by the information criterion that passes
    the selection rule and leaves a physical set (module doc); every move is tried at every
    step, in the criterion's order, until one passes."""
    chosen: tuple[str, ...] = ()
    current = fit(problem, chosen)
    current_cv = 0.0
    trail: list[dict] = [{"set": [], "bic": current.bic, "cv_ev": 0.0}]
    while True:
        pool = moves(problem, chosen, candidates)
        if not pool:
            break
        fits = sorted(
            (fit(problem, (*chosen, *m), start=current.values) for m in pool), key=lambda f: f.bic
        )
        accepted = None
        for f in fits:
            if f.bic >= current.bic:
                break
            added = f.names[len(chosen) :]
            step = _judge(problem, f, added, current, current_cv, len(pool), folds)
            trail.append(step)
            if step["selected"]:
                accepted = (f, step["cv_ev"] if step["cv_ev"] is not None else current_cv)
                break
        if accepted is None:
            break
        current, current_cv = accepted
        chosen = current.names
        # the set refitted from fresh starts: a member fitted before a later one joined may
        # sit in a local minimum the warm starts keep (a ground effect's rho walled off by its
        # cut-off step)
        fresh = fit(problem, chosen)
        if fresh.bic < current.bic - 1e-6 and not any(set_problems(problem, fresh).values()):
            current = fresh
        current = _prune(problem, current, trail)
        chosen = current.names
    return current, trail


def _prune(problem: Problem, current: Fit, trail: list[dict]) -> Fit:
    """Members a later one has made redundant, removed: a member whose value has fallen below
    MIN_SIZE catalogue magnitudes (what the rule would no longer admit) leaves the set when
    the set fits as well without it. Forward selection alone keeps them: a sensor latency of
    23 ms chosen first in a motor lag's place fell to 0.2 us once the lag joined, and stayed
    'present'."""
    while len(current.names) > 1:
        small = [
            n
            for n in current.names
            if effect_size(n, current.values[n], problem.nominal, problem.catalogue) < MIN_SIZE
        ]
        for name in small:
            rest = tuple(n for n in current.names if n != name)
            pruned = fit(problem, rest, start={n: current.values[n] for n in rest})
            if pruned.bic <= current.bic:
                trail.append({
                    "set": list(rest), "removed": name, "bic": pruned.bic,
                    "bic_drop": current.bic - pruned.bic,
                    "value": [float(x) for x in current.values[name]],
                    "why": "fell below the size the rule admits after later members joined",
                })  # fmt: skip
                current = pruned
                break
        else:
            return current
    return current


def _judge(
    problem: Problem,
    f: Fit,
    added: tuple[str, ...],
    current: Fit,
    current_cv: float,
    tried: int,
    folds: int,
) -> dict:
    """One move's trail entry: its tests and whether it is kept (cross-validation, the
    costly part, only when the rest holds)."""
    p_value = max(added_p(f, a, problem.nominal) for a in added)
    size = min(effect_size(a, f.values[a], problem.nominal, problem.catalogue) for a in added)
    issues = set_problems(problem, f)
    issues["collinear"] = collinear_with_chosen(problem, f, added)
    physical = not (
        issues["at_bound"]
        or issues["implausible"]
        or issues["cancelling"]
        or issues["collinear"]
        or issues["contradicted"]
    )
    # the rest of the rule first: cross-validation is the costly part
    cheap_ok = selected(current.bic - f.bic, p_value, tried, np.inf, size, physical)
    cv = cross_validated_ev(problem, f.names, folds) if cheap_ok else float("nan")
    gain = float("inf") if np.isnan(cv) else cv - current_cv
    ok = cheap_ok and selected(current.bic - f.bic, p_value, tried, gain, size, physical)
    name = added[-1]
    step = {
        "set": list(f.names),
        "added": name,
        "with": list(added[:-1]),
        "value": [float(x) for x in f.values[name]],
        "values": {a: [float(x) for x in f.values[a]] for a in f.names},
        "bic": f.bic,
        "bic_drop": current.bic - f.bic,
        "cv_ev": None if np.isnan(cv) else cv,
        "wald_p": p_value,
        "tried": tried,
        "size_typical": size,
        "interior": not issues["at_bound"],
        "at_bound": [h for hits in issues["at_bound"].values() for h in hits],
        "at_bound_members": issues["at_bound"],
        "implausible": issues["implausible"],
        "cancelling": issues["cancelling"],
        "collinear": issues["collinear"],
        "contradicted": issues["contradicted"],
        "significant": bool(current.bic - f.bic > 0 and p_value < _alpha(tried)),
        "selected": bool(ok),
    }
    if len(problem.flights) < 2:  # one fitting flight: none to leave out
        step["cv_ev_note"] = CV_SKIPPED
    elif not cheap_ok:
        step["cv_ev_note"] = "not computed: the move failed the other tests"
    return step


def _alpha(tried: int) -> float:
    return ALPHA / max(tried, 1)
