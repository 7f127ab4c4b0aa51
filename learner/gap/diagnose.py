"""The diagnosis of flight logs against a nominal world: residuals, regimes, candidate
selection with identifiability, the corrected world's effects, and the gap on held-out
flights before and after (force, rollouts; overall and per region)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from learner.flightlogs.flightlog import FlightLog
from learner.gap import fit as gapfit
from learner.gap.candidates import CANDIDATES, Values, nominal_values
from learner.gap.corrected import corrected_members, is_sensor
from learner.gap.disagreement import flights_disagree
from learner.gap.flightdata import FlightData, describe_left_out, prepare
from learner.gap.ground_level import level_logs
from learner.gap.overall import trend_summary
from learner.gap.plausibility import check as check_plausible
from learner.gap.regimes import REGIMES, RegimeBin, regime_table, regime_variables, rules
from learner.gap.residual import (
    force_gap_ms,
    gap_over_floor_ms,
    measured_floor_ms,
    residual_n,
    white_floor_ms,
)
from learner.gap.residual_net import STATE_INPUTS
from learner.gap.rollout import HORIZON_S, rms, rollout_errors, shrink
from learner.gap.search import forward_search
from learner.gap.stats import ess_ratio
from learner.gap.summaries import explain_trend, extra_rules, summaries
from learner.gap.torque import torque_gap
from learner.gap.unexplained import held_out_learned, learn_unexplained
from learner.gap.verdicts import effect_report, mark_confidence, per_flight_values
from simbridge.effects.learned import POSITION, ResidualModel
from simbridge.vehicle import Vehicle
from simbridge.world import World


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
    z_offsets_m: dict[str, float] = field(default_factory=dict)  # log -> z shifted by (m)
    # what the corrected world gains (`corrected.corrected_members`): written, kept out, why
    corrected: dict[str, Any] = field(default_factory=dict)


# Enough flight before any fit: the intervals rest on blocks of 1 s (and 5 s) of flight
MIN_FLIGHT_S = 1.0  # a flight's airborne, usable time; a shorter one is left out with a note
MIN_TOTAL_S = 4.0  # the fitting flights' together; less is refused, saying what is missing
# What a diagnosis does, in the order it does it (`diagnose`'s `on_stage`)
STAGES = (
    "levelling and preparing the logs",
    "searching the catalogue",
    "final fit, intervals, regimes and gaps",
    "learning what the catalogue leaves",
)


def _problem(flights: list[FlightData], nominal: Values, vehicle: Vehicle) -> gapfit.Problem:
    return gapfit.problem_for(flights, nominal, vehicle)


def left_out_counts(flights: list[FlightData]) -> dict[str, Any]:
    """Rows left out of every flight (contact, crashes, standing, short stretches), summed and per
    flight."""
    keys = ("rows", "contact_rows", "crash_rows", "held_rows", "short_stretches", "short_rows")
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
            "cross-validation: with one fitting flight there is no flight to leave out: each "
            "step of the effect search was judged without the "
            f"cross-validated explained variance (cv_ev), and the gap is measured {where}"
            + ("" if hold else " (optimistic: the same data fitted and scored)")
        )
    elif folds > n:
        notes.append(
            f"cross-validation: {n} fitting flights, so {n} folds (of {folds}), one flight left "
            "out at a time"
        )
    for d in fit + hold:  # rows the reader dropped (non-finite values, repeated stamps)
        dropped = [c for c in d.meta.get("conversions", []) if c.startswith("rows: ")]
        if dropped:
            notes.append(f"{d.name}: " + "; ".join(c.removeprefix("rows: ") for c in dropped))
    clamped = {d.name: d.left_out.get("clamped_rows", 0) for d in fit + hold}
    if any(clamped.values()):
        per = ", ".join(f"{name} {rows}" for name, rows in clamped.items() if rows)
        notes.append(
            "rotor commands beyond the vehicle's max_rotor_speed_rad_s clamped there, as the "
            f"simulator clamps them (rows with a rotor beyond it: {per}): a vehicle whose "
            "rotors give more would show a residual where a rotor saturates"
        )
    derived = [d.name for d in fit + hold if not d.measured_acceleration]
    if derived:
        notes.append(
            "acceleration differentiated from the logged velocity (a Savitzky-Golay derivative "
            f"over 0.1 s): the logs carry none: {', '.join(derived)}"
        )
    return notes


def check_candidates(names: list[str] | None) -> None:
    """A ValueError naming an unknown candidate and the known ones."""
    unknown = [c for c in names or [] if c not in CANDIDATES]
    if unknown:
        raise ValueError(
            f"--candidates: unknown candidate {unknown[0]!r}; known: {', '.join(CANDIDATES)}"
        )


def diagnose(
    fitting: list[FlightLog],
    held_out: list[FlightLog],
    world: World,
    vehicle: Vehicle,
    folds: int = 3,
    z_offset_m: float | None = None,
    candidates: list[str] | None = None,
    on_stage: Callable[[str], None] = lambda stage: None,
) -> Diagnosis:
    """The whole analysis; with no held-out logs the gap is measured by cross-validation.
    The logs' z is first put on the world's ground (`ground_level.level_logs`: from where
    the vehicle rests, or `z_offset_m`). `candidates`: the catalogue candidates the search
    may choose from (default: all; an unknown name is a ValueError naming the known ones).
    `on_stage` hears each of STAGES as it begins (a progress bar)."""
    check_candidates(candidates)
    on_stage(STAGES[0])
    nominal = nominal_values(world.effects, vehicle)
    leveled, level_notes, z_offsets = level_logs(fitting + held_out, world, vehicle, z_offset_m)
    fitting, held_out = leveled[: len(fitting)], leveled[len(fitting) :]
    fit_data, fit_dropped = usable_flights(fitting, world, vehicle)
    hold_data, hold_dropped = usable_flights(held_out, world, vehicle)
    enough_data(fit_data, fit_dropped)
    level_notes = level_notes + [f"left out: {why}" for why in fit_dropped + hold_dropped]
    problem = _problem(fit_data, nominal, vehicle)
    hold_res = [residual_n(d, nominal, vehicle) for d in hold_data]
    check_plausible([d.name for d in fit_data + hold_data], problem.residuals + hold_res, vehicle)
    excitation = {c: gapfit.excitation_z(problem, c) for c in CANDIDATES}
    excited = [c for c in CANDIDATES if excitation[c] >= gapfit.Z_EXCITE]
    # every candidate is tried (the excitation test only tells "absent" from "not excited");
    # those modelling the accelerometer only where every fitting log carries one
    measured = all(d.measured_acceleration for d in fit_data)
    tried = [c for c in CANDIDATES if measured or not CANDIDATES[c].needs_accelerometer]
    if candidates is not None:
        tried = [c for c in tried if c in candidates]
    # the effective sample size of the residual once the excited effects are all fitted:
    # an approximate fit from one start, as all excited candidates at once are
    # ill-conditioned and a few rows more or less change the bounded trust region's work
    # many times over; the best of the candidates' multi-starts gives the same ratio to 1e-4
    # on the bench's cases at six times the cost
    on_stage(STAGES[1])
    everything = gapfit.fit(
        problem,
        tuple(c for c in excited if c != "wind" and c in tried),
        max_nfev=100,
        multi_start=False,
    )
    after = problem.predicted(everything.values)
    problem.ess_ratio = ess_ratio(
        [(r - p)[:: gapfit.STRIDE] for r, p in zip(problem.residuals, after, strict=True)]
    )
    best, trail = forward_search(problem, tried, folds)
    on_stage(STAGES[2])
    best = gapfit.final_fit(problem, best)  # the reported values and intervals: every row
    effects = effect_report(problem, best, excitation, excited, trail, tried, candidates)
    all_data = fit_data + hold_data
    all_res = problem.residuals + hold_res
    table = regime_table(all_data, all_res, vehicle)
    whole = summaries(all_data, all_res, nominal, vehicle)
    hold_problem = _problem(hold_data, nominal, vehicle) if hold_data else None
    if hold_problem is not None:
        gap = held_out_gap(hold_problem, best.values)
    else:
        gap = cross_validated_gap(problem, best.names, folds)
    on_stage(STAGES[3])
    fit_left = [
        r - p for r, p in zip(problem.residuals, problem.predicted(best.values), strict=True)
    ]
    disagree = flights_disagree(fit_data, fit_left, vehicle)
    inputs = STATE_INPUTS + POSITION if disagree else STATE_INPUTS
    left = learn_unexplained(problem, best.values, hold_problem, inputs)
    corrected = [
        r - p
        for r, p in zip(
            all_res, _problem(all_data, nominal, vehicle).predicted(best.values), strict=True
        )
    ]
    explain_trend(whole, trend_summary(all_data, corrected, vehicle))
    unexplained = dict(left.summary)
    left_table = regime_table(all_data, corrected, vehicle)
    unexplained["where"] = where(left_table)
    unexplained["rules"] = rules(left_table)
    unexplained["disagreement"] = disagree
    if hold_problem is not None:
        gap["force_rms_n_learned"] = held_out_learned(hold_problem, best.values, left.model)
    within = force_within_floor(gap)
    if within:  # nothing to tell structure from noise in: say so, not "no structure"
        unexplained.update(structure=False, significant=False, explained=True, sentence=within)
    mark_confidence(effects, unexplained)
    per_flight_values(effects, all_data, nominal, vehicle, best)
    members = corrected_members(effects, best.values, vehicle)

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
        rules=rules(table) + extra_rules(whole) + ([disagree["sentence"]] if disagree else []),
        summaries=whole,
        gap=gap,
        vehicle=vehicle,
        left_out=left_out_counts(all_data),
        notes=level_notes + fallback_notes(fit_data, hold_data, folds),
        residuals={d.name: r for d, r in zip(all_data, all_res, strict=True)},
        corrected_residuals={d.name: c for d, c in zip(all_data, corrected, strict=True)},
        flights={d.name: d for d in all_data},
        unexplained=unexplained,
        learned_model=left.model,
        z_offsets_m=z_offsets,
        corrected=members,
    )


def airborne_s(d: FlightData) -> float:
    """The usable airborne time of a prepared flight (its rows at its median period)."""
    return len(d.time_s) * d.dt_s


def usable_flights(
    logs: list[FlightLog], world: World, vehicle: Vehicle
) -> tuple[list[FlightData], list[str]]:
    """The logs prepared, those with at least MIN_FLIGHT_S airborne and usable; a sentence for
    each one left out (a flight too short to carry a block of evidence is no flight)."""
    kept, dropped = [], []
    for log in logs:
        try:
            d = prepare(log, world, vehicle)
        except ValueError as err:
            dropped.append(str(err))
            continue
        if airborne_s(d) < MIN_FLIGHT_S:
            dropped.append(
                f"{d.name}: {airborne_s(d):.2f} s airborne and usable, under the "
                f"{MIN_FLIGHT_S:g} s a flight needs"
            )
            continue
        kept.append(d)
    return kept, dropped


def enough_data(fit: list[FlightData], dropped: list[str]) -> None:
    """Refuse, saying what is missing, before any fit on too little: the intervals rest on
    blocks of a second or more of flight, so fewer than MIN_TOTAL_S of them mean nothing."""
    total = sum(airborne_s(d) for d in fit)
    if total >= MIN_TOTAL_S:
        return
    have = ", ".join(f"{d.name} {airborne_s(d):.2f} s" for d in fit) or "none usable"
    raise ValueError(
        f"too little flight to fit: the fitting logs hold {total:.2f} s airborne and usable "
        f"({have}); at least {MIN_TOTAL_S:g} s in all is needed, each flight at least "
        f"{MIN_FLIGHT_S:g} s" + (f"; left out: {'; '.join(dropped)}" if dropped else "")
    )


def where(table: list[RegimeBin], limit: int = 8) -> list[dict[str, Any]]:
    """The significant regime bins of a residual, largest first, as plain records."""
    sig = sorted((b for b in table if b.significant), key=lambda b: -abs(b.mean))
    return [
        {"variable": b.variable, "low": b.low, "high": b.high, "component": b.component,
         "mean_share": b.mean, "ci95": [b.ci_low, b.ci_high], "rows": b.rows}
        for b in sig[:limit]
    ]  # fmt: skip


def held_out_gap(problem: gapfit.Problem, values: Values) -> dict[str, Any]:
    """Force gap and rollout error before and after the correction, overall and per region.
    The force gap is the logs' (a sensor effect corrects what they measure); the rollouts
    and the torque fly the corrected world's forces, which hold no sensor effect."""
    corrected = {**problem.nominal, **{k: v for k, v in values.items() if not is_sensor(k)}}
    after = [r - p for r, p in zip(problem.residuals, problem.predicted(values), strict=True)]
    out: dict[str, Any] = {"flights": [d.name for d in problem.flights]}
    before_f = _pooled_gap(problem.flights, problem.residuals, problem.noise_var)
    after_f = _pooled_gap(problem.flights, after, problem.noise_var)
    out["force_rms_n"] = {"before": before_f, "after": after_f, "shrink": shrink(before_f, after_f)}
    measured = measured_floor_gap(problem.flights, problem.residuals, after)
    white = white_floor_ms(problem.noise_var, problem.flights[0].dt_s)
    measured["white_floor"] = float(np.sqrt(white))
    out["force_rms_n_measured_floor"] = measured
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


def force_within_floor(gap: dict[str, Any]) -> str | None:
    """A sentence where the nominal world's force gap on the held-out flights is within their
    measured noise floor: there is no force left to explain (a torque may still be: the
    rotors' rule says)."""
    measured = gap.get("force_rms_n_measured_floor") or {}
    if measured.get("before") is None or measured["before"] > 0.0:
        return None
    before = gap["force_rms_n"]["before"]
    return (
        f"the force gap ({before * 1e3:.2f} mN) is within the held-out flights' measured noise "
        f"floor ({measured['floor'] * 1e3:.2f} mN): no force is left for the catalogue or a "
        "network to explain"
    )


def measured_floor_gap(
    flights: list[FlightData], before: list[np.ndarray], after: list[np.ndarray]
) -> dict[str, float]:
    """The force gap before and after against the noise floor measured on each flight's
    corrected residual (`measured_floor_ms`) instead of the white-noise one: what is left
    of a gap whose sensors' noise is coloured. Reported beside the white-floor figure."""
    floors = [measured_floor_ms(a, d.segment, d.dt_s) for d, a in zip(flights, after, strict=True)]
    rows = sum(len(r) for r in before)

    def pooled(res: list[np.ndarray]) -> float:
        parts = [
            gap_over_floor_ms(r, d.segment, d.dt_s, f) * len(r)
            for d, r, f in zip(flights, res, floors, strict=True)
        ]
        return float(np.sqrt(sum(parts) / rows))

    b, a = pooled(before), pooled(after)
    floor = float(np.sqrt(sum(f * len(r) for f, r in zip(floors, before, strict=True)) / rows))
    return {"before": b, "after": a, "shrink": shrink(b, a), "floor": floor}


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
            floor = white_floor_ms(problem.noise_var, problem.flights[0].dt_s)
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
