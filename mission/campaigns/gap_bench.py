"""`groundfx gap bench`: "real" flights flown in worlds holding effects the diagnosis is not
told, the diagnosis run blind on them, and its scores: exact-set identification, per-effect F1
(credit where the truth is inside a group reported as not identifiable), parameter error and
95% interval coverage, held-out gap shrink, false alarms on null worlds."""

from __future__ import annotations

import hashlib
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from tqdm import tqdm

from learner.gap.numbers import finite
from mission.campaigns.gap_bench_cases import Case, real_effects
from mission.campaigns.gap_bench_ooc import summary as ooc_summary
from mission.campaigns.gap_bench_ooc import verdict, verdict_text
from mission.campaigns.gap_flights import (
    AUTOPILOT_PARAMS,
    BENCH_NOISE,
    bench_mission,
    cut_log,
    real_log,
)
from simbridge.vehicle import load_vehicle

FIT_SEEDS = (0, 1)
HOLD_SEEDS = (100,)
BASE: dict[str, Any] = {"vehicle": "nano", "physics_rate_hz": 1000, "control_period_s": 0.004}
PARAMETER_TARGET = 0.10  # relative parameter error of a catalogue case


def _world_file(path: Path, case: Case, effects: tuple[dict, ...]) -> Path:
    data = {**BASE, **case.world, "effects": [dict(e) for e in effects]}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _drop_stale_flights(folder: Path, key_text: str) -> None:
    """Cached flights are reused only for the same real world, missions and autopilot
    parameters."""
    key = hashlib.sha256(key_text.encode()).hexdigest()[:16]
    stamp = folder / "flights.key"
    if stamp.exists() and stamp.read_text() == key:
        return
    for old in folder.glob("flight*"):
        old.unlink()
    shutil.rmtree(folder / "diagnosis", ignore_errors=True)
    stamp.write_text(key)


def run_case(case: Case, out: Path, replay: bool = True, record: bool = False) -> dict[str, Any]:
    """Fly (or reuse) the case's flights, diagnose blind, score. `record`: the clean flights
    are also kept as rerun recordings (flight<seed>.truth.rrd)."""
    from mission.campaigns.gap_diagnosis import run_diagnosis

    folder = out / case.name
    real = _world_file(folder / "real_world.yaml", case, real_effects(case))
    nominal = _world_file(folder / "nominal_world.yaml", case, case.nominal)
    ceiling = case.world.get("ceiling_height_m")
    vehicle = load_vehicle({**BASE, **case.world}["vehicle"])
    missions = {s: bench_mission(case.kind, s, ceiling, vehicle) for s in FIT_SEEDS + HOLD_SEEDS}
    _drop_stale_flights(folder, real.read_text() + repr(missions) + repr(AUTOPILOT_PARAMS))
    logs = {
        seed: _log(case, folder, seed, mission, real, record) for seed, mission in missions.items()
    }
    started = time.perf_counter()
    try:
        result = run_diagnosis(
            [logs[s] for s in FIT_SEEDS],
            [logs[s] for s in HOLD_SEEDS],
            str(nominal),
            folder / "diagnosis",
            folds=len(FIT_SEEDS),
            replay=replay,
        )
    except ValueError as refusal:  # the diagnosis's refusal, saying what is missing
        if not case.refused:
            raise
        return refused(case, str(refusal))
    # what a user waits for: the diagnosis, its flights already flown
    return {**score(case, result), "diagnosis_wall_s": time.perf_counter() - started}


def _log(
    case: Case, folder: Path, seed: int, mission: dict[str, Any], real: Path, record: bool
) -> Path:
    """The log of one of the case's flights that the diagnosis reads: the noisy CSV, or
    groundfx's recording of the flight; cut where the case says."""
    path = folder / f"flight{seed}.csv"
    recording = path.with_suffix(".truth.rrd")
    if case.logs == "recording" and path.exists() and not recording.exists():
        path.unlink()  # flown before without its recording: fly it again, recorded
    log = real_log(mission, real, path, BENCH_NOISE, seed, record or case.logs == "recording")
    if case.logs == "recording":
        log = recording
    seconds = case.cut_s[0] if seed in FIT_SEEDS else case.cut_s[1]
    if seconds is None:
        return log
    return cut_log(log, seconds, folder / f"flight{seed}.cut{seconds:g}s.csv")


def refused(case: Case, message: str) -> dict[str, Any]:
    """A case whose logs are too short to fit: the diagnosis refused, saying what is
    missing (airborne seconds)."""
    return {
        "case": case.name, "truth": sorted(case.truth), "reported": [], "exact": None,
        "max_relative_error": None, "catalogue_target": None, "uncatalogued": None,
        "unexcited_reported_not_identifiable": None, "effects": {}, "force_shrink": None,
        "force_before_n": None, "rollout_shrink": None, "closed_loop": None,
        "false_alarm": None,
        "refusal": {"expected": True, "message": message,
                    "passed": "airborne" in message and "needed" in message},
    }  # fmt: skip


def score(case: Case, result: dict[str, Any]) -> dict[str, Any]:
    """Per effect: truth, what was reported, credit; parameter errors and coverage."""
    effects = result["effects"]
    present = {e for e, r in effects.items() if r["status"] == "present"}
    grouped = {
        e for e, r in effects.items() if r["status"] == "not identifiable" and "parameters" in r
    }
    # a group reported not identifiable (with fitted parameters) credits the true effects in
    # it, and counts against the case only when it holds none
    groups = [set(effects[e]["group"]) for e in grouped]
    per: dict[str, dict[str, Any]] = {}
    for effect, r in effects.items():
        truth = effect in case.truth
        if truth:
            reported = effect in present or any(effect in g for g in groups)
        else:
            reported = effect in present or (
                effect in grouped and not any(t in r["group"] for t in case.truth)
            )
        entry: dict[str, Any] = {"truth": truth, "reported": reported, "status": r["status"]}
        if truth and "parameters" in r:
            errs, covered = [], []
            for p, true_v in case.truth[effect].items():
                got = r["parameters"][p]
                scale = max(abs(true_v), _floor(effect, case.truth[effect]))
                errs.append(abs(got["value"] - true_v) / scale)
                ci = got.get("ci95")  # none for a value refused as implausible or at a bound
                covered.append(bool(ci) and ci[0] <= true_v <= ci[1])
            entry.update(relative_errors=errs, covered=covered)
        per[effect] = entry
    unexcited_ok = all(effects[e]["status"] == "not identifiable" for e in case.unexcited)
    reported_set = {e for e, v in per.items() if v["reported"]}
    expected = set(case.truth) - set(case.unexcited)
    gap = result["gap"]
    errors = [x for v in per.values() for x in v.get("relative_errors", [])]
    exact = reported_set == expected
    return {
        "case": case.name,
        "truth": sorted(case.truth),
        "reported": sorted(reported_set),
        # out of the catalogue there is no set to name: the verdict below scores it
        "exact": None if case.uncatalogued else exact,
        "max_relative_error": max(errors) if errors else None,
        # a catalogue case's target: the exact set, every parameter within 10%
        "catalogue_target": (
            exact and all(e <= PARAMETER_TARGET for e in errors)
            if case.truth and not case.uncatalogued
            else None
        ),
        "uncatalogued": verdict(case.expected_regime, result) if case.uncatalogued else None,
        "unexcited_reported_not_identifiable": unexcited_ok if case.unexcited else None,
        "effects": per,
        "force_shrink": gap["force_rms_n"]["shrink"],
        # the story: does the learnt residual find structure the catalogue leaves?
        "structure": (result.get("unexplained") or {}).get("structure"),
        "torque_shrink": (gap.get("torque_rms_n_m") or {}).get("shrink"),
        # with the learnt residual beside the catalogue's effects (offered or not)
        "learned_shrink": (gap.get("force_rms_n_learned") or {}).get("shrink"),
        "force_before_n": gap["force_rms_n"]["before"],
        "rollout_shrink": gap.get("rollout_rms_m", {}).get("shrink"),
        "closed_loop": result.get("closed_loop"),
        "false_alarm": bool(reported_set) if not case.truth and not case.uncatalogued else None,
        "own_recordings": read_exactly(result) if case.logs == "recording" else None,
        # expected a refusal, got a diagnosis
        "refusal": {"expected": True, "message": None, "passed": False} if case.refused else None,
    }


def _n(x: float | None, spec: str, scale: float = 1.0, unit: str = "") -> str:
    """`x * scale` formatted with its unit, or n/a where the selection of cases gives no such
    figure."""
    if not finite(x):
        return "n/a".rjust(int(spec.split(".")[0] or 0) + len(unit))
    return format(x * scale, spec) + unit


def _floor(effect: str, truth: dict[str, float]) -> float:
    """The scale of a vector parameter's error: its largest true component (a zero wind
    component is judged against the wind's size)."""
    return max(abs(v) for v in truth.values())


RESULTS_FILE = "results.jsonl"


def run_bench(
    cases: list[Case],
    out: Path,
    replay: bool = False,
    workers: int | None = None,
    ray_address: str | None = None,
    progress: bool = False,
) -> dict[str, Any]:
    """Every case, each a task of the campaign runner (`workers` local processes, or Ray
    tasks at `ray_address`); `replay`: with the closed-loop re-flights of the held-out
    missions (two more flights a case). A case already scored in out/results.jsonl with the
    same definition and source is not run again; a failed case is a figure of the bench,
    not its end."""
    from mission.campaigns.runner import Task, run_tasks, source_fingerprint

    source = source_fingerprint()
    tasks = [
        # its folder (flights already flown in it are reused) goes with it and comes back
        Task(case.name, _key(case, replay, source), run_case, (case, out, replay),
             outputs=(out / case.name,), input_folders=(out / case.name,),
             imports=("mission.campaigns.gap_diagnosis",))
        for case in cases
    ]  # fmt: skip

    def say(record: dict[str, Any]) -> None:
        tqdm.write(f"gap bench: {record['id']}: {_line(record)}")

    records = run_tasks(tasks, out / RESULTS_FILE, workers, ray_address, progress, "gap bench", say)
    results = [{**records[c.name], "case": c.name} for c in cases]
    for r in results:
        r.pop("id", None)
        r.pop("key", None)
    return {"cases": results, "summary": summarise(results, cases)}


def _key(case: Case, replay: bool, source: str) -> str:
    """What decides a case's scores: its definition, the bench's flights and the code."""
    text = repr((case, replay, AUTOPILOT_PARAMS, BENCH_NOISE, FIT_SEEDS, HOLD_SEEDS, source))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def read_exactly(result: dict[str, Any]) -> dict[str, Any]:
    """groundfx's own recordings carry their frame and ground: the diagnosis shifts none of
    them, and no trend over the flight is left once the named effects are in."""
    trend = (result.get("summaries") or {}).get("trend") or {}
    left = trend.get("after_catalogue_share_per_min")
    floor = trend.get("floor_share_per_min")
    shifted = sorted(result.get("z_offsets_m") or {})
    no_trend = not trend.get("significant") or (
        finite(left) and finite(floor) and abs(left) < floor
    )
    return {"shifted": shifted, "trend_left_share_per_min": left, "trend_floor": floor,
            "passed": bool(no_trend and not shifted)}  # fmt: skip


def refusal_text(refusal: dict[str, Any]) -> str:
    """One table cell: a case that had to be refused."""
    verdict_word = "PASS" if refusal["passed"] else "fail"
    return f"{verdict_word}: refused: {refusal['message'] or 'not refused'}"


def _line(r: dict[str, Any]) -> str:
    if "error" in r:
        return r["error"]
    if r.get("refusal"):
        return refusal_text(r["refusal"])
    if r.get("uncatalogued"):
        wall = _n(r.get("diagnosis_wall_s"), ".0f")
        return f"out of the catalogue: {verdict_text(r['uncatalogued'])}; diagnosis {wall} s"
    return (
        f"truth {r['truth']} reported {r['reported']} exact {r['exact']} "
        f"force shrink {r['force_shrink'] * 100:.0f}%; diagnosis "
        f"{_n(r.get('diagnosis_wall_s'), '.0f')} s"
    )


def _mark(flag: bool | None) -> str:
    return "-" if flag is None else "yes" if flag else "no"


def summarise(results: list[dict[str, Any]], cases: list[Case]) -> dict[str, Any]:
    refusals = [r["refusal"]["passed"] for r in results if r.get("refusal")]
    ok = [r for r in results if "error" not in r and not r.get("refusal")]
    by_case = {c.name: c for c in cases}
    exact = [r["exact"] for r in ok if r.get("exact") is not None]
    target = [r["catalogue_target"] for r in ok if r.get("catalogue_target") is not None]
    singles = [
        r for r in ok if len(by_case[r["case"]].truth) == 1 and not by_case[r["case"]].unexcited
    ]
    f1: dict[str, Any] = {}
    effects = sorted({e for r in ok for e in r["effects"]})
    for e in effects:
        tp = sum(1 for r in singles if r["effects"][e]["truth"] and r["effects"][e]["reported"])
        fp = sum(1 for r in singles if not r["effects"][e]["truth"] and r["effects"][e]["reported"])
        fn = sum(1 for r in singles if r["effects"][e]["truth"] and not r["effects"][e]["reported"])
        f1[e] = {"tp": tp, "fp": fp, "fn": fn, "f1": 2 * tp / (2 * tp + fp + fn) if tp else 0.0}
    errs = [x for r in ok for v in r["effects"].values() for x in v.get("relative_errors", [])]
    cov = [x for r in ok for v in r["effects"].values() for x in v.get("covered", [])]
    per_param: dict[str, Any] = {}
    for e in effects:
        ee = [x for r in ok for x in r["effects"].get(e, {}).get("relative_errors", [])]
        cc = [x for r in ok for x in r["effects"].get(e, {}).get("covered", [])]
        if ee:
            per_param[e] = {"median_error": float(np.median(ee)), "coverage": float(np.mean(cc))}
    shrinks = [r["force_shrink"] for r in ok if r["truth"] and not by_case[r["case"]].unexcited]
    nulls = [r for r in ok if r["false_alarm"] is not None]
    closed = [
        r["closed_loop"]["shrink"]
        for r in ok
        if r["truth"] and (r.get("closed_loop") or {}).get("status") == "flown"
    ]
    return {
        "cases": len(results),
        "failed": len(results) - len(ok),
        "exact_set_rate": float(np.mean(exact)) if exact else float("nan"),
        "catalogue_target_rate": float(np.mean(target)) if target else float("nan"),
        "uncatalogued": ooc_summary([r["uncatalogued"] for r in ok if r.get("uncatalogued")]),
        "f1_single": f1,
        "median_relative_parameter_error": float(np.median(errs)) if errs else float("nan"),
        "coverage95": float(np.mean(cov)) if cov else float("nan"),
        "per_effect_parameters": per_param,
        "median_force_shrink": float(np.median(shrinks)) if shrinks else float("nan"),
        "median_closed_loop_shrink": float(np.median(closed)) if closed else float("nan"),
        "false_alarm_rate": float(np.mean([r["false_alarm"] for r in nulls])) if nulls else None,
        "unexcited_not_identifiable": [
            r["unexcited_reported_not_identifiable"] for r in ok if by_case[r["case"]].unexcited
        ],
        "refused_as_expected": refusals,
    }


def table(scores: dict[str, Any]) -> str:
    s = scores["summary"]
    lines = ["case                      exact  <=10%  force shrink  reported / out-of-catalogue"]
    for r in scores["cases"]:
        if "error" in r:
            lines.append(f"{r['case']:25s} ERROR {r['error']}")
            continue
        ooc = r.get("uncatalogued")
        what = verdict_text(ooc) if ooc else ", ".join(r["reported"]) or "-"
        if r.get("refusal"):
            what = refusal_text(r["refusal"])
        own = r.get("own_recordings")
        if own:
            verdict_word = "PASS" if own["passed"] else "fail"
            what += f" ({verdict_word}: shifted {own['shifted'] or '-'}, trend left "
            what += f"{_n(own['trend_left_share_per_min'], '.1f', 100, '%/min')})"
        lines.append(
            f"{r['case']:25s} {_mark(r['exact']):5s}  {_mark(r.get('catalogue_target')):5s}"
            f"  {_n(r['force_shrink'], '8.0f', 100, '%')}     {what}"
        )
    effects = ["", "effect               F1 (single)  median param error  coverage95"]
    for e, f in s["f1_single"].items():
        if f["tp"] + f["fp"] + f["fn"] == 0 and e not in s["per_effect_parameters"]:
            continue  # no case of this selection holds or names it
        p = s["per_effect_parameters"].get(e, {})
        effects.append(
            f"{e:20s} {f['f1']:6.2f} ({f['tp']}/{f['fp']}/{f['fn']})"
            f"  {_n(p.get('median_error'), '10.1f', 100, '%')}  {_n(p.get('coverage'), '8.2f')}"
        )
    lines += effects if len(effects) > 2 else []
    lines += [
        "",
        f"exact-set rate {_n(s['exact_set_rate'], '.2f')}; median parameter error "
        f"{_n(s['median_relative_parameter_error'], '.1f', 100, '%')}; coverage "
        f"{_n(s['coverage95'], '.2f')}; median held-out force shrink "
        f"{_n(s['median_force_shrink'], '.0f', 100, '%')}; closed-loop "
        f"{_n(s['median_closed_loop_shrink'], '.0f', 100, '%')}; false alarms "
        f"{s['false_alarm_rate']}; unexcited reported not identifiable "
        f"{s['unexcited_not_identifiable']}; wall {_n(scores.get('wall_s'), '.0f')} s",
    ]
    if s.get("refused_as_expected"):
        lines.append(f"refused as they had to be: {s['refused_as_expected']}")
    t, u = s.get("catalogue_target_rate"), s.get("uncatalogued") or {}
    lines.append(
        f"catalogue cases with the exact set and every parameter within 10%: {_n(t, '.2f')}"
    )
    if u.get("cases"):
        lines.append(
            f"out of the catalogue ({u['cases']} cases): located {u['located']:.2f}; no "
            f"catalogue effect named with confidence {u['no_confident_catalogue']:.2f}; "
            f"unexplained share reported {u['share_reported']:.2f}; learnt shrink >= 60% "
            f"{u['learned_shrink_ok']:.2f}; all four {u['passed']:.2f}"
        )
    return "\n".join(lines)
