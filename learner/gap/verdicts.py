"""The verdict on each catalogue effect: present (with its 95% CI, refitted on each flight),
implausible, at bound, not identifiable (not excited, not a candidate, cancelling another or
collinear with one; an alternative that could carry the effect only at an implausible value,
or that fits worse and does not trade off against it, is ruled out by name) or absent; and
whether a present effect is named with confidence."""

from __future__ import annotations

from typing import Any

import numpy as np

from learner.gap import bias_or_tilt
from learner.gap import fit as gapfit
from learner.gap.candidates import CANDIDATES, Values, implausible_parameters
from learner.gap.flightdata import FlightData
from learner.gap.selection import at_bound
from simbridge.vehicle import Vehicle

Z_CRIT = 1.959964
ALTERNATIVE_BIC = 10.0  # a collinear alternative this much worse does not carry the effect
TRADE_OFF = 0.95  # unless, fitted beside it, some parameters of the two correlate this much


def effect_report(
    problem: gapfit.Problem,
    best: gapfit.Fit,
    excitation: dict[str, float],
    excited: list[str],
    trail: list[dict] | None = None,
    tried: list[str] | None = None,
    asked: list[str] | None = None,
) -> dict[str, dict[str, Any]]:
    """Each catalogue effect: present; implausible (the data want it, at a value outside its
    physical range: the value and what it would mean), at bound (its fit ended on a bound of
    the search), not identifiable (not excited, not a candidate for these logs, cancelling or
    indistinguishable from another: the group is named); not tried (left out by `asked`, the
    user's --candidates); else absent. With 95% CIs."""
    tried = list(CANDIDATES) if tried is None else tried
    refused = _refused(trail or [])
    sens = {c: gapfit.sensitivities(problem, c, {**best.values}) for c in excited if c in tried}
    out: dict[str, dict[str, Any]] = {}
    for name, cand in CANDIDATES.items():
        entry: dict[str, Any] = {"candidate": name, "excitation_z": excitation[name]}
        if name in best.values:
            group = sorted(
                other
                for other in excited
                if other != name
                and other in sens
                and name in sens
                and max(
                    gapfit.collinearity_r2(sens[name], sens[other]),
                    gapfit.collinearity_r2(sens[other], sens[name]),
                )
                >= gapfit.COLLINEAR_R2
            )
            carried: dict[str, dict[str, float]] = {}
            ruled_out = _alternatives_ruled_out(problem, best, name, group, carried)
            if carried:  # what each alternative left in the group would take
                entry["alternatives_carry"] = carried
            if ruled_out:
                entry["alternatives_ruled_out"] = ruled_out
                group = [g for g in group if g not in ruled_out]
            v, se = best.values[name], best.stderr[name]
            entry["parameters"] = {
                p: {
                    "value": float(v[i]),
                    "ci95": [float(v[i] - Z_CRIT * se[i]), float(v[i] + Z_CRIT * se[i])],
                    "unit": cand.units[i],
                }
                for i, p in enumerate(cand.params)
            }
            if len(cand.effects) > 1 or group:
                entry["status"] = "not identifiable"
                members = sorted(
                    {*cand.effects, *(e for g in group for e in CANDIDATES[g].effects)}
                )
                entry["group"] = members
                entry["why"] = "indistinguishable in the data: " + ", ".join(members)
            else:
                entry["status"] = "present"
        elif asked is not None and name not in asked:
            entry["status"] = "not tried"
            entry["why"] = "left out of the search (--candidates)"
        elif name not in tried:
            entry["status"] = "not identifiable"
            entry["why"] = (
                "not a candidate for these logs: it models the accelerometer, and the logs' "
                "acceleration is differentiated from their velocity"
            )
            entry["group"] = list(cand.effects)
        elif name in refused:
            entry.update(_refusal(name, refused[name], problem))
        elif name not in excited:
            entry["status"] = "not identifiable"
            entry["why"] = f"not excited by the flights (z = {excitation[name]:.1f})"
            entry["group"] = list(cand.effects)
        else:
            entry["status"] = "absent"
        for effect in cand.effects:
            e = dict(entry)
            if name == "thrust_mass" and "parameters" in entry:
                c = entry["parameters"]["c"]
                e["parameters"] = _thrust_mass_as(effect, c)
            out[effect] = e
    # an effect indistinguishable from a fitted one is not absent: it shares that one's group
    for name in best.values:
        for effect in CANDIDATES[name].effects:
            entry = out[effect]
            for other in entry.get("group", []):
                o = out[other]
                if o["status"] == "absent" or o.get("why", "").startswith("cancels"):
                    carry = entry.get("alternatives_carry", {}).get(_candidate_of(other))
                    out[other] = {
                        **{k: v for k, v in o.items() if k != "parameters"},
                        "status": "not identifiable",
                        "group": entry["group"],
                        "why": f"indistinguishable from {name}, which carries the fitted "
                        "value: " + ", ".join(entry["group"]) + _carry_text(other, carry),
                    }
                    if carry:
                        out[other]["carried_as"] = carry
    return out


def _candidate_of(effect: str) -> str:
    """The candidate standing for a catalogue effect (mass_error: thrust_mass)."""
    return next(n for n, c in CANDIDATES.items() if effect in c.effects)


def _carry_text(effect: str, carry: dict[str, float] | None) -> str:
    """'; in its place it would take ax 2.4 deg, ay -0.8 deg' (nothing without a value)."""
    if not carry:
        return ""
    cand = CANDIDATES[_candidate_of(effect)]
    units = dict(zip(cand.params, cand.units, strict=True))
    parts = ", ".join(
        f"{p} {v:.3g}" + ("" if units[p] == "1" else f" {units[p]}") for p, v in carry.items()
    )
    return f"; in its place it would take {parts}"


def _alternatives_ruled_out(
    problem: gapfit.Problem,
    best: gapfit.Fit,
    name: str,
    group: list[str],
    carried: dict[str, dict[str, float]] | None = None,
) -> dict[str, str]:
    """Of the candidates the data cannot tell from `name`, those that could carry its share
    only at a value outside their physical range or on a bound (a 3.6 m/s wind read as an
    accelerometer bias of 1.3 m/s^2): physics tells them apart. Candidate -> why. The others'
    values, swapped in for `name`, go into `carried` (candidate -> parameter -> value: a wind
    of 1.9 m/s or a lean of 2.4 deg)."""
    out = {}
    cat = problem.catalogue
    for other in group:
        if bias_or_tilt.told_apart(problem, best.values, frozenset({name, other})):
            force = "lean" if "thrust_tilt" in (name, other) else "wind"
            out[other] = (
                "both fitted, and the logged acceleration's mean departs from the velocity's "
                f"change by the bias's share alone: the {force} is a force, the bias the sensor's"
            )
            continue
        if other in best.values:
            continue
        if {name, other} == bias_or_tilt.BIAS_OR_TILT:
            why = _bias_or_tilt(problem, best, name, other)
            if why:
                out[other] = why
                continue
        names = tuple(other if n == name else n for n in best.names)
        # on the rows `best` was fitted on: its criterion is compared with this one's
        alt = gapfit.fit(problem, names, max_nfev=60, start=best.values, every_row=best.every_row)
        bad = implausible_parameters(other, alt.values[other], cat, alt.stderr.get(other))
        if bad:
            h = bad[0]
            out[other] = (
                f"it would take {h['parameter']} {h['value']:.3g}, outside its physical range "
                f"[{h['range'][0]:.3g}, {h['range'][1]:.3g}]"
            )
        elif at_bound(other, alt.values[other], cat):
            out[other] = "it would sit on a bound of the search"
        # worse as a whole, it may still trade off against part of the effect (an
        # accelerometer's z bias against a thrust scale, beside an x bias)
        elif (
            alt.bic - best.bic > ALTERNATIVE_BIC
            and _trades_off(problem, best, name, other) < TRADE_OFF
        ):
            out[other] = (
                f"swapped in for {name}, it fits the flights worse (BIC "
                f"+{alt.bic - best.bic:.0f}), and beside it the two do not trade off"
            )
        elif carried is not None:
            params = CANDIDATES[other].params
            carried[other] = {p: float(v) for p, v in zip(params, alt.values[other], strict=True)}
    return out


def _bias_or_tilt(problem: gapfit.Problem, best: gapfit.Fit, name: str, other: str) -> str | None:
    """An accelerometer bias against a leaning thrust axis, told apart by the logged
    acceleration's mean against the velocity's change (learner/gap/bias_or_tilt.py)."""
    logged = bias_or_tilt.logged_offset_m_s2(problem.flights)
    if logged is None:
        return None
    member = bias_or_tilt.fitted_offset_m_s2(problem, best.values, name)
    return bias_or_tilt.ruled_out(other, member, logged)


def _trades_off(problem: gapfit.Problem, best: gapfit.Fit, name: str, other: str) -> float:
    """The largest correlation between a parameter of `name` and one of `other` when both are
    fitted beside the chosen set."""
    f = gapfit.fit(
        problem, (*best.names, other), max_nfev=60, start=best.values, every_row=best.every_row
    )
    sd = np.sqrt(np.maximum(np.diag(f.cov), 1e-300))
    corr = f.cov / np.outer(sd, sd)
    index, i = {}, 0
    for n in f.names:
        k = len(f.values[n])
        index[n] = slice(i, i + k)
        i += k
    return float(np.max(np.abs(corr[index[name], index[other]])))


def _refused(trail: list[dict]) -> dict[str, dict]:
    """Candidates the data asked for (criterion down, significant) in a move refused as
    unphysical, and not chosen later: the last such step of each."""
    last: dict[str, dict] = {}
    for step in trail:
        if "added" not in step or step.get("selected") or not step.get("significant"):
            continue
        if step["implausible"] or step["at_bound"] or step["cancelling"]:
            for name in [*step.get("with", []), step["added"]]:
                last[name] = step
    return last


def _refusal(name: str, step: dict, problem: gapfit.Problem) -> dict[str, Any]:
    """The report entry of a candidate refused as unphysical (`_refused`)."""
    cand = CANDIDATES[name]
    value = step["values"].get(name, step["value"])
    params = {
        p: {"value": v, "ci95": None, "unit": cand.units[i]}
        for i, (p, v) in enumerate(zip(cand.params, value, strict=True))
    }
    pairs = [c for c in step["cancelling"] if name in c["members"]]
    if pairs:
        members = sorted({e for c in pairs for m in c["members"] for e in CANDIDATES[m].effects})
        others = sorted({m for c in pairs for m in c["members"]} - {name})
        return {
            "status": "not identifiable",
            "group": members,
            "parameters": params,
            "why": (
                f"cancels {', '.join(others)}: their contributions oppose each other (cosine "
                f"{pairs[0]['cosine']:.2f}, parameter correlation {pairs[0]['correlation']:.2f})"
                ", so the data fix only their sum; not written into the corrected world"
            ),
        }
    own = step["implausible"].get(name) or []
    if own:
        parts = [
            f"{h['parameter']} {h['value']:.4g} outside its physical range "
            f"[{h['range'][0]:.4g}, {h['range'][1]:.4g}]"
            for h in own
        ]
        return {
            "status": "implausible",
            "implausible": own,
            "parameters": params,
            "why": "; ".join(parts) + f": it would mean {own[0]['meaning']}; not written "
            "into the corrected world",
        }
    hits = step.get("at_bound_members", {}).get(name) or []
    if hits:
        return {"status": "at bound", "at_bound": hits, "parameters": params,
                "why": bound_sentence(hits)}  # fmt: skip
    # refused for another member's sake: what the data asked for is in that member's entry
    blame = sorted(set(step["implausible"]) | set(step.get("at_bound_members", {})))
    return {
        "status": "absent",
        "why": f"asked for only beside {', '.join(blame)}, which was refused as unphysical",
    }


def bound_sentence(hits: list[dict]) -> str:
    """'rho reached its bound 25: the effect is stronger than the catalogue's range'."""
    parts = [f"{h['parameter']} reached its bound {h['bound']:.4g}" for h in hits]
    return (
        ", ".join(parts) + ": the effect is stronger than the catalogue's range, or the fit "
        "leans on it to make up for another; not added to the corrected world"
    )


def _thrust_mass_as(effect: str, c: dict[str, Any]) -> dict[str, Any]:
    """c = s / k - 1 read as a C_T scale s (k = 1) or a mass scale k (s = 1); a fit on a
    bound has no interval."""
    lo, hi = c["ci95"] or (np.nan, np.nan)
    if effect == "thrust_coefficient":
        ci = None if c["ci95"] is None else [1.0 + lo, 1.0 + hi]
        return {"scale": {"value": 1.0 + c["value"], "ci95": ci, "unit": "1"}}
    ci = None if c["ci95"] is None else [1.0 / (1.0 + hi), 1.0 / (1.0 + lo)]
    return {"scale": {"value": 1.0 / (1.0 + c["value"]), "ci95": ci, "unit": "1"}}


def per_flight_values(
    effects: dict[str, dict[str, Any]],
    flights: list[FlightData],
    nominal: Values,
    vehicle: Vehicle,
    best: gapfit.Fit,
) -> None:
    """The chosen set refitted on each flight alone (fitting and held out): whether a present
    effect is the same on every flight (a wind's speed and direction within one condition).
    A wind's direction is the one it blows towards, counterclockwise from world x (east)."""
    if not best.names:
        return
    problems = [(d.name, gapfit.problem_for([d], nominal, vehicle)) for d in flights]
    fits = [
        (n, gapfit.fit(p, best.names, max_nfev=60, start=best.values, every_row=best.every_row))
        for n, p in problems
    ]
    cat = problems[0][1].catalogue
    for name in best.names:
        for effect in CANDIDATES[name].effects:
            e = effects[effect]
            if e["status"] != "present":
                continue
            rows = []
            for flight, f in fits:
                v = f.values[name]
                row: dict[str, Any] = {"flight": flight, "values": [float(x) for x in v]}
                if name == "wind":
                    row["speed_m_s"] = float(np.hypot(v[0], v[1]))
                    row["towards_deg"] = float(np.degrees(np.arctan2(v[1], v[0])) % 360.0)
                rows.append(row)
            e["per_flight"] = rows
            _mark_disagreeing_flights(e, name, fits, cat)


def _mark_disagreeing_flights(
    e: dict[str, Any], name: str, fits: list[tuple[str, gapfit.Fit]], cat: dict
) -> None:
    """A property of the vehicle or its world holds on every flight: refitted on one flight
    alone outside its physical range, the effect carries something that differs between
    flights (an effect outside the catalogue: a neighbour's downwash, a gust), so it is not
    named with confidence."""
    outside = [
        (flight, bad)
        for flight, f in fits
        for bad in implausible_parameters(name, f.values[name], cat, f.stderr.get(name))
    ]
    if not outside:
        return
    e["confident"] = False
    shown = ", ".join(f"{b['parameter']} {b['value']:.4g} on {flight}" for flight, b in outside)
    lo, hi = outside[0][1]["range"]
    note = (
        f"refitted on each flight alone it leaves its physical range [{lo:g}, {hi:g}] ({shown}): "
        "the flights disagree beyond the vehicle's physics, so it may stand in for an effect "
        "outside the catalogue that differs between them"
    )
    e["confidence_note"] = "; ".join(filter(None, [e.get("confidence_note"), note]))


# Left with at least this share of the gap, the catalogue explains less than it leaves: an
# effect it names may stand in for what it misses, learnable from the state or not (a
# neighbour's wake differs from flight to flight and no network carries it over)
MOSTLY_UNEXPLAINED = 0.5


def mark_confidence(effects: dict[str, dict[str, Any]], unexplained: dict[str, Any]) -> None:
    """An effect is named with confidence only when nothing systematic is left beside it, and
    the catalogue explains at least half of the gap: otherwise it may stand in for an effect
    outside the catalogue."""
    share = unexplained["share"]
    doubtful = unexplained["significant"] or share >= MOSTLY_UNEXPLAINED
    for e in effects.values():
        if e["status"] != "present":
            continue
        e["confident"] = not doubtful
        if unexplained["significant"]:
            e["confidence_note"] = (
                f"the catalogue leaves {share * 100:.0f}% of the gap, "
                "systematic: this effect may stand in for one outside the catalogue"
            )
        elif doubtful:
            e["confidence_note"] = (
                f"the catalogue leaves {share * 100:.0f}% of the gap, more than it explains: "
                "this effect may stand in for one outside the catalogue"
            )
