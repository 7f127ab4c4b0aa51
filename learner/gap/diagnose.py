"""The diagnosis of flight logs against a nominal world: residuals, regimes, candidate
selection with identifiability, the corrected world's effects, and the gap on held-out
flights before and after (force, rollouts; overall and per region)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from learner.flightlogs.flightlog import FlightLog
from learner.gap import fit as gapfit
from learner.gap.candidates import CANDIDATES, Values, implausible_parameters, nominal_values
from learner.gap.flightdata import FlightData, describe_left_out, prepare
from learner.gap.plausibility import check as check_plausible
from learner.gap.regimes import REGIMES, RegimeBin, regime_table, regime_variables, rules
from learner.gap.residual import force_gap_ms, residual_n
from learner.gap.rollout import HORIZON_S, rms, rollout_errors, shrink
from learner.gap.search import forward_search
from learner.gap.stats import ess_ratio
from learner.gap.summaries import extra_rules, summaries
from learner.gap.torque import torque_gap
from learner.gap.unexplained import held_out_learned, learn_unexplained
from simbridge.effects.learned import ResidualModel
from simbridge.vehicle import Vehicle
from simbridge.world import World

Z_CRIT = 1.959964
ALTERNATIVE_BIC = 10.0  # a collinear alternative this much worse does not carry the effect
TRADE_OFF = 0.95  # unless, fitted beside it, some parameters of the two correlate this much


@dataclass
class Diagnosis:
    fitting: list[str]
    held_out: list[str]
    noise_sd_n: float
    ess_ratio: float
    excitation: dict[str, float]
    effects: dict[str, dict[str, Any]]  # catalogue effect -> status, parameters, group
    chosen: Values
    search: list[dict]
    regimes: list[RegimeBin]
    rules: list[str]
    gap: dict[str, Any]
    vehicle: Vehicle | None = None
    left_out: dict[str, Any] = field(default_factory=dict)  # rows left out, counted
    notes: list[str] = field(default_factory=list)  # every fallback taken, in words
    residuals: dict[str, np.ndarray] = field(default_factory=dict)  # flight -> (N, 3)
    corrected_residuals: dict[str, np.ndarray] = field(default_factory=dict)
    flights: dict[str, FlightData] = field(default_factory=dict)
    summaries: dict[str, Any] = field(default_factory=dict)  # whole-flight: force, trend, rotors
    unexplained: dict[str, Any] = field(default_factory=dict)  # what the catalogue leaves
    learned_model: ResidualModel | None = None  # that, learnt (a `learned_residual` effect)


def _problem(flights: list[FlightData], nominal: Values, vehicle: Vehicle) -> gapfit.Problem:
    res = [residual_n(d, nominal, vehicle) for d in flights]
    problem = gapfit.Problem(flights, res, nominal, vehicle)
    problem.noise_var = gapfit.noise_variance(res, flights)
    return problem


def effect_report(
    problem: gapfit.Problem,
    best: gapfit.Fit,
    excitation: dict[str, float],
    excited: list[str],
    trail: list[dict] | None = None,
    tried: list[str] | None = None,
) -> dict[str, dict[str, Any]]:
    """Each catalogue effect: present; implausible (the data want it, at a value outside its
    physical range: the value and what it would mean), at bound (its fit ended on a bound of
    the search), not identifiable (not excited, not a candidate for these logs, cancelling or
    indistinguishable from another: the group is named); else absent. With 95% CIs."""
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
            ruled_out = _alternatives_ruled_out(problem, best, name, group)
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
                    out[other] = {
                        **{k: v for k, v in o.items() if k != "parameters"},
                        "status": "not identifiable",
                        "group": entry["group"],
                        "why": f"indistinguishable from {name}, which carries the fitted "
                        "value: " + ", ".join(entry["group"]),
                    }
    return out


def _alternatives_ruled_out(
    problem: gapfit.Problem, best: gapfit.Fit, name: str, group: list[str]
) -> dict[str, str]:
    """Of the candidates the data cannot tell from `name`, those that could carry its share
    only at a value outside their physical range or on a bound (a 3.6 m/s wind read as an
    accelerometer bias of 1.3 m/s^2): physics tells them apart. Candidate -> why."""
    out = {}
    cat = problem.catalogue
    for other in group:
        if other in best.values:
            continue
        names = tuple(other if n == name else n for n in best.names)
        alt = gapfit.fit(problem, names, max_nfev=60, start=best.values)
        bad = implausible_parameters(other, alt.values[other], cat)
        if bad:
            h = bad[0]
            out[other] = (
                f"it would take {h['parameter']} {h['value']:.3g}, outside its physical range "
                f"[{h['range'][0]:.3g}, {h['range'][1]:.3g}]"
            )
        elif gapfit.at_bound(other, alt.values[other], cat):
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
    return out


def _trades_off(problem: gapfit.Problem, best: gapfit.Fit, name: str, other: str) -> float:
    """The largest correlation between a parameter of `name` and one of `other` when both are
    fitted beside the chosen set."""
    f = gapfit.fit(problem, (*best.names, other), max_nfev=60, start=best.values)
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


def left_out_counts(flights: list[FlightData]) -> dict[str, Any]:
    """Rows left out of every flight (contact, short stretches), summed and per flight."""
    keys = ("rows", "contact_rows", "short_stretches", "short_rows")
    total: dict[str, Any] = {k: sum(d.left_out.get(k, 0) for d in flights) for k in keys}
    total["min_stretch_s"] = flights[0].left_out.get("min_stretch_s") if flights else None
    total["per_flight"] = {d.name: d.left_out for d in flights}
    total["summary"] = describe_left_out(total)
    return total


def fallback_notes(fit: list[FlightData], hold: list[FlightData], folds: int) -> list[str]:
    """Every way the analysis departs from its full form, in words."""
    notes = []
    n = len(fit)
    if n < 2:
        where = "on the held-out flights" if hold else "in-sample, on the fitting flight itself"
        notes.append(
            f"cross-validation: --folds {folds} asked, but with one fitting flight there is no "
            "flight to leave out: each step of the effect search was judged without the "
            f"cross-validated explained variance (cv_ev), and the gap is measured {where}"
            + ("" if hold else " (optimistic: the same data fitted and scored)")
        )
    elif folds > n:
        notes.append(
            f"cross-validation: --folds {folds} asked with {n} fitting flights: {n} folds, "
            "one flight left out at a time"
        )
    derived = [d.name for d in fit + hold if not d.measured_acceleration]
    if derived:
        notes.append(
            "acceleration differentiated from the logged velocity (a Savitzky-Golay derivative "
            f"over 0.1 s): the logs carry none: {', '.join(derived)}"
        )
    return notes


def _thrust_mass_as(effect: str, c: dict[str, Any]) -> dict[str, Any]:
    """c = s / k - 1 read as a C_T scale s (k = 1) or a mass scale k (s = 1); a fit on a
    bound has no interval."""
    lo, hi = c["ci95"] or (np.nan, np.nan)
    if effect == "thrust_coefficient":
        ci = None if c["ci95"] is None else [1.0 + lo, 1.0 + hi]
        return {"scale": {"value": 1.0 + c["value"], "ci95": ci, "unit": "1"}}
    ci = None if c["ci95"] is None else [1.0 / (1.0 + hi), 1.0 / (1.0 + lo)]
    return {"scale": {"value": 1.0 / (1.0 + c["value"]), "ci95": ci, "unit": "1"}}


def diagnose(
    fitting: list[FlightLog],
    held_out: list[FlightLog],
    world: World,
    vehicle: Vehicle,
    folds: int = 3,
) -> Diagnosis:
    """The whole analysis; with no held-out logs the gap is measured by cross-validation."""
    nominal = nominal_values(world.effects, vehicle)
    fit_data = [prepare(log, world, vehicle) for log in fitting]
    hold_data = [prepare(log, world, vehicle) for log in held_out]
    problem = _problem(fit_data, nominal, vehicle)
    hold_res = [residual_n(d, nominal, vehicle) for d in hold_data]
    check_plausible([d.name for d in fit_data + hold_data], problem.residuals + hold_res, vehicle)
    excitation = {c: gapfit.excitation_z(problem, c) for c in CANDIDATES}
    excited = [c for c in CANDIDATES if excitation[c] >= gapfit.Z_EXCITE]
    # every candidate is tried (the excitation test only tells "absent" from "not excited");
    # those modelling the accelerometer only where every fitting log carries one
    measured = all(d.measured_acceleration for d in fit_data)
    tried = [c for c in CANDIDATES if measured or not CANDIDATES[c].needs_accelerometer]
    # the effective sample size of the residual once the excited effects are all fitted
    # (only an approximate fit: all excited candidates at once are ill-conditioned, and a
    # few rows more or less sent the bounded trust region from 11 to 532 evaluations)
    everything = gapfit.fit(
        problem, tuple(c for c in excited if c != "wind" and c in tried), max_nfev=100
    )
    after = problem.predicted(everything.values)
    problem.ess_ratio = ess_ratio(
        [(r - p)[:: gapfit.STRIDE] for r, p in zip(problem.residuals, after, strict=True)]
    )
    best, trail = forward_search(problem, tried, folds)
    effects = effect_report(problem, best, excitation, excited, trail, tried)
    all_data = fit_data + hold_data
    all_res = problem.residuals + hold_res
    table = regime_table(all_data, all_res, vehicle)
    whole = summaries(all_data, all_res, nominal, vehicle)
    hold_problem = _problem(hold_data, nominal, vehicle) if hold_data else None
    if hold_problem is not None:
        gap = held_out_gap(hold_problem, best.values)
    else:
        gap = cross_validated_gap(problem, best.names, folds)
    left = learn_unexplained(problem, best.values)
    corrected = [
        r - p
        for r, p in zip(
            all_res, _problem(all_data, nominal, vehicle).predicted(best.values), strict=True
        )
    ]
    unexplained = dict(left.summary)
    left_table = regime_table(all_data, corrected, vehicle)
    unexplained["where"] = where(left_table)
    unexplained["rules"] = rules(left_table)
    if hold_problem is not None:
        gap["force_rms_n_learned"] = held_out_learned(hold_problem, best.values, left.model)
    mark_confidence(effects, unexplained)
    per_flight_values(effects, all_data, nominal, vehicle, best)

    return Diagnosis(
        fitting=[d.name for d in fit_data],
        held_out=[d.name for d in hold_data],
        noise_sd_n=float(np.sqrt(problem.noise_var)),
        ess_ratio=problem.ess_ratio,
        excitation=excitation,
        effects=effects,
        chosen=best.values,
        search=trail,
        regimes=table,
        rules=rules(table) + extra_rules(whole),
        summaries=whole,
        gap=gap,
        vehicle=vehicle,
        left_out=left_out_counts(all_data),
        notes=fallback_notes(fit_data, hold_data, folds),
        residuals={d.name: r for d, r in zip(all_data, all_res, strict=True)},
        corrected_residuals={d.name: c for d, c in zip(all_data, corrected, strict=True)},
        flights={d.name: d for d in all_data},
        unexplained=unexplained,
        learned_model=left.model,
    )


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
    fits = [(d.name, gapfit.fit(_problem([d], nominal, vehicle), best.names,
                                max_nfev=60, start=best.values)) for d in flights]  # fmt: skip
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


def where(table: list[RegimeBin], limit: int = 8) -> list[dict[str, Any]]:
    """The significant regime bins of a residual, largest first, as plain records."""
    sig = sorted((b for b in table if b.significant), key=lambda b: -abs(b.mean))
    return [
        {"variable": b.variable, "low": b.low, "high": b.high, "component": b.component,
         "mean_share": b.mean, "ci95": [b.ci_low, b.ci_high], "rows": b.rows}
        for b in sig[:limit]
    ]  # fmt: skip


def mark_confidence(effects: dict[str, dict[str, Any]], unexplained: dict[str, Any]) -> None:
    """An effect is named with confidence only when nothing systematic is left beside it:
    otherwise it may stand in for an effect outside the catalogue."""
    for e in effects.values():
        if e["status"] != "present":
            continue
        e["confident"] = not unexplained["significant"]
        if unexplained["significant"]:
            e["confidence_note"] = (
                f"the catalogue leaves {unexplained['share'] * 100:.0f}% of the gap, "
                "systematic: this effect may stand in for one outside the catalogue"
            )


def held_out_gap(problem: gapfit.Problem, values: Values) -> dict[str, Any]:
    """Force gap and rollout error before and after the correction, overall and per region."""
    corrected = {**problem.nominal, **values}
    after = [r - p for r, p in zip(problem.residuals, problem.predicted(values), strict=True)]
    out: dict[str, Any] = {"flights": [d.name for d in problem.flights]}
    before_f = _pooled_gap(problem.flights, problem.residuals, problem.noise_var)
    after_f = _pooled_gap(problem.flights, after, problem.noise_var)
    out["force_rms_n"] = {"before": before_f, "after": after_f, "shrink": shrink(before_f, after_f)}
    rb = np.concatenate(
        [rollout_errors(d, problem.nominal, problem.vehicle, HORIZON_S) for d in problem.flights]
    )
    ra = np.concatenate(
        [rollout_errors(d, corrected, problem.vehicle, HORIZON_S) for d in problem.flights]
    )
    rb_rms, ra_rms = rms(rb), rms(ra)
    out["rollout_rms_m"] = {
        "horizon_s": HORIZON_S, "before": rb_rms, "after": ra_rms, "shrink": shrink(rb_rms, ra_rms)
    }  # fmt: skip
    out["one_step_force_rms_n"] = {
        "before": rms(np.concatenate(problem.residuals).ravel()) * np.sqrt(3),
        "after": rms(np.concatenate(after).ravel()) * np.sqrt(3),
    }
    out["torque_rms_n_m"] = torque_gap(problem.flights, problem.nominal, corrected, problem.vehicle)
    out["regions"] = _per_region(problem, after)
    return out


def _pooled_gap(flights: list[FlightData], residuals: list[np.ndarray], noise_var: float) -> float:
    """The systematic force gap (N) over flights: noise-corrected RMS of the smoothed residual."""
    parts = [
        force_gap_ms(r, d.segment, d.dt_s, noise_var) * len(r)
        for d, r in zip(flights, residuals, strict=True)
    ]
    return float(np.sqrt(sum(parts) / sum(len(r) for r in residuals)))


def _per_region(problem: gapfit.Problem, after: list[np.ndarray]) -> list[dict[str, Any]]:
    """Force gap before and after within each regime bin that holds enough samples."""
    from learner.gap.residual import SMOOTH_WINDOW_S, smooth_per_segment

    rows = []
    smooth_b, smooth_a, variables = [], [], []
    for d, r, a in zip(problem.flights, problem.residuals, after, strict=True):
        w = max(1, round(SMOOTH_WINDOW_S / d.dt_s))
        smooth_b.append(smooth_per_segment(r, d.segment, w))
        smooth_a.append(smooth_per_segment(a, d.segment, w))
        variables.append(regime_variables(d, problem.vehicle))
    sb, sa = np.concatenate(smooth_b), np.concatenate(smooth_a)
    for name, (_, _, edges) in REGIMES.items():
        v = np.concatenate([x[name] for x in variables])
        k = np.digitize(v, edges) - 1
        for b in range(len(edges) - 1):
            sel = k == b
            if sel.sum() < 50:
                continue
            floor = (
                3.0 * problem.noise_var / max(1, round(SMOOTH_WINDOW_S / problem.flights[0].dt_s))
            )
            before = float(np.sqrt(max(np.mean(np.sum(sb[sel] ** 2, axis=1)) - floor, 0.0)))
            after_ = float(np.sqrt(max(np.mean(np.sum(sa[sel] ** 2, axis=1)) - floor, 0.0)))
            rows.append(
                {"variable": name, "low": float(edges[b]), "high": float(edges[b + 1]),
                 "samples": int(sel.sum()), "before_n": before, "after_n": after_,
                 "shrink": shrink(before, after_)}
            )  # fmt: skip
    return rows


def cross_validated_gap(
    problem: gapfit.Problem, names: tuple[str, ...], folds: int
) -> dict[str, Any]:
    """With no held-out logs: each fold's flights scored with the model fitted on the others."""
    k = min(folds, len(problem.flights))  # one flight: scored in-sample (a note says so)
    before, after = [], []
    for fold in range(max(k, 1)):
        test = [i for i in range(len(problem.flights)) if k < 2 or i % k == fold]
        train = [i for i in range(len(problem.flights)) if k >= 2 and i % k != fold] or test
        fitted = gapfit.fit(problem.subset(train), names)
        held = problem.subset(test)
        g = held_out_gap(held, fitted.values)
        before.append(g["force_rms_n"]["before"])
        after.append(g["force_rms_n"]["after"])
    b, a = float(np.mean(before)), float(np.mean(after))
    return {
        "cross_validated": k >= 2,
        "in_sample": k < 2,
        "folds": k if k >= 2 else 0,
        "force_rms_n": {"before": b, "after": a, "shrink": shrink(b, a)},
    }
