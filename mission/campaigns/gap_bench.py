"""`groundfx gap bench`: "real" flights flown in worlds holding effects the diagnosis is not
told, the diagnosis run blind on them, and its scores: exact-set identification, per-effect F1
(credit where the truth is inside a group reported as not identifiable), parameter error and
95% interval coverage, held-out gap shrink, false alarms on null worlds."""

from __future__ import annotations

import hashlib
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from mission.campaigns.gap_bench_ooc import summary as ooc_summary
from mission.campaigns.gap_bench_ooc import verdict, verdict_text
from mission.campaigns.gap_flights import BENCH_NOISE, bench_mission, real_log

FIT_SEEDS = (0, 1)
HOLD_SEEDS = (100,)
BASE: dict[str, Any] = {"vehicle": "nano", "physics_rate_hz": 1000, "control_period_s": 0.004}
GE = {"name": "ground_effect", "rho": 1.0}
DRAG = {"name": "rotor_drag"}
PARAMETER_TARGET = 0.10  # relative parameter error of a catalogue case (issue 16)
WALL = [{"kind": "wall", "start_m": [-2.0, 0.6], "end_m": [2.0, 0.6], "height_m": 2.0}]


@dataclass(frozen=True)
class Case:
    name: str
    hidden: tuple[dict, ...]  # effects in the real world, not in the nominal one
    truth: dict[str, dict[str, float]]  # catalogue effect -> parameter -> true value
    kind: str = "mixed"
    nominal: tuple[dict, ...] = (GE,)
    world: dict[str, Any] = field(default_factory=dict)  # geometry shared by both worlds
    unexcited: tuple[str, ...] = ()  # effects the flights cannot excite
    # nominal effects the real world lacks (its hidden effect replaces them)
    replaced: tuple[str, ...] = ()
    # the hidden effects are outside the diagnosis's catalogue (simbridge/effects/
    # uncatalogued.py): scored on locating them, not naming them
    uncatalogued: bool = False
    # where an out-of-catalogue effect should be located: (regime variable, residual
    # component, upper bound of the bin's low edge or None), as the diagnosis's
    # `unexplained.where` entries read, or ("rotor", i) for a rotor whose thrust is low
    expected_regime: tuple[Any, ...] = ()


def _cases() -> list[Case]:
    k = (2.2e-5, 2.2e-5, 1.0e-5)
    c: list[Case] = []
    for tag, rho in (("a", 1.6), ("b", 2.5)):
        c.append(
            Case(
                f"ground_effect_{tag}",
                ({"name": "ground_effect", "rho": rho},),
                {"ground_effect": {"rho": rho}},
                nominal=(),
            )
        )
    for tag, m in (("a", 1.5), ("b", 3.0)):
        kk = [m * x for x in k]
        c.append(
            Case(
                f"rotor_drag_{tag}",
                ({"name": "rotor_drag", "coefficient_n_s_m": kk},),
                {"rotor_drag": {"kxy": kk[0], "kz": kk[2]}},
            )
        )
    # b at the top of the physical range (learner/gap/candidates.py PHYSICAL: 2.5)
    for tag, cd in (("a", 1.5), ("b", 2.4)):
        # quadratic in speed: at the mixed flights' 1.5 m/s a C_d of 1 is 3 mN on a 0.55 N
        # vehicle, below the excitation threshold (z = 5); at 3 m/s four times that
        c.append(
            Case(
                f"body_drag_{tag}",
                ({"name": "body_drag", "drag_coefficient": cd},),
                {"body_drag": {"drag_coefficient": cd}},
                kind="aggressive",
            )
        )
    for tag, w in (("a", [0.8, 0.0, 0.0]), ("b", [1.2, -0.8, 0.0])):
        c.append(
            Case(
                f"wind_{tag}",
                ({"name": "wind", "mean_m_s": w},),
                {"wind": dict(zip(("wx", "wy"), w[:2], strict=True))},  # horizontal
                nominal=(GE, DRAG),
            )
        )
    for tag, tau in (("a", 0.03), ("b", 0.08)):
        c.append(
            Case(
                f"motor_lag_{tag}",
                ({"name": "motor_lag", "time_constant_s": tau},),
                {"motor_lag": {"tau": tau}},
                kind="aggressive",
            )
        )
    # more thrust, less mass: the position loop has no integral action (thesis: a PD with
    # a0 = 1), so a thrust deficit of x g takes x g / a0 of height error: 0.7 m for 7%, and
    # such a vehicle never leaves the ground cushion of a 0.3 m take-off
    for tag, s in (("a", 1.05), ("b", 1.1)):
        c.append(
            Case(
                f"thrust_coefficient_{tag}",
                ({"name": "thrust_coefficient", "scale": s},),
                {"thrust_coefficient": {"scale": s}},
            )
        )
    # lighter by more than ~9%, it hovers a metre above its setpoints, which the commander's
    # 1 m setpoint lead then never brings down to a low waypoint
    for tag, s in (("a", 0.96), ("b", 0.92)):
        c.append(
            Case(
                f"mass_error_{tag}",
                ({"name": "mass_error", "scale": s},),
                {"mass_error": {"scale": s}},
            )
        )
    for tag, b in (("a", [0.2, -0.1, 0.15]), ("b", [0.5, 0.3, -0.4])):
        c.append(
            Case(
                f"sensor_bias_{tag}",
                ({"name": "sensor_bias", "accel_bias_m_s2": b},),
                {"sensor_bias": dict(zip(("bx", "by", "bz"), b, strict=True))},
            )
        )
    for tag, d in (("a", 0.008), ("b", 0.02)):
        c.append(
            Case(
                f"sensor_latency_{tag}",
                ({"name": "sensor_latency", "imu_delay_s": d},),
                {"sensor_latency": {"imu_delay": d}},
                kind="aggressive",
            )
        )
    for tag, g in (("a", 0.5), ("b", 1.5)):
        c.append(
            Case(
                f"wall_effect_{tag}",
                ({"name": "wall_effect", "gain": g},),
                {"wall_effect": {"gain": g}},
                kind="wall",
                world={"obstacles": WALL},
            )
        )
    for tag, rho in (("a", 1.0), ("b", 2.0)):
        c.append(
            Case(
                f"ceiling_effect_{tag}",
                ({"name": "ceiling_effect", "rho": rho},),
                {"ceiling_effect": {"rho": rho}},
                world={"ceiling_height_m": 0.85},
            )
        )
    c.append(
        Case(
            "ceiling_unexcited",
            ({"name": "ceiling_effect", "rho": 2.0},),
            {"ceiling_effect": {"rho": 2.0}},
            world={"ceiling_height_m": 3.0},
            unexcited=("ceiling_effect",),
        )
    )
    kk = [2 * x for x in k]
    c.append(
        Case(
            "pair_drag_ground",
            (
                {"name": "rotor_drag", "coefficient_n_s_m": kk},
                {"name": "ground_effect", "rho": 2.0},
            ),
            {
                "rotor_drag": {"kxy": kk[0], "kz": kk[2]},
                "ground_effect": {"rho": 2.0},
            },
            nominal=(),
        )
    )
    c.append(
        Case(
            "pair_wind_mass",
            ({"name": "wind", "mean_m_s": [1.0, 0.0, 0.0]}, {"name": "mass_error", "scale": 0.93}),
            {"wind": {"wx": 1.0, "wy": 0.0}, "mass_error": {"scale": 0.93}},
            nominal=(GE, DRAG),
        )
    )
    # a hover's small motions (a 0.9 mN gap) still identify twice the default drag: since
    # every candidate is tried, the case is scored as found (kxy within 5% in the bench of
    # issue 16), no longer as "not excited" by the excitation probe's conservative z
    for kind in ("hover", "aggressive"):
        c.append(
            Case(
                f"rotor_drag_{kind}",
                ({"name": "rotor_drag", "coefficient_n_s_m": kk},),
                {"rotor_drag": {"kxy": kk[0], "kz": kk[2]}},
                kind=kind,
            )
        )
    c += _hard_cases(kk)
    c.append(Case("null_mixed", (), {}))
    c.append(Case("null_aggressive", (), {}, kind="aggressive"))
    c.append(Case("null_hover", (), {}, kind="hover"))
    return c


def _hard_cases(drag: list[float]) -> list[Case]:
    """Issue 16: catalogue effects far from nominal beside a second one, three at once, and
    effects outside the catalogue. Magnitudes: clear in the residual in their regime (several
    % of the weight), yet flown and landed by the autopilot, which knows none of them."""
    return [
        # rho 3 against the nominal 1 (cut-off 0.03 m): 35% more thrust at the 4 cm pass,
        # against the autopilot's 9%; a lag the aggressive legs excite
        Case(
            "far_ground_effect_lag",
            ({"name": "ground_effect", "rho": 3.0}, {"name": "motor_lag", "time_constant_s": 0.04}),
            {"ground_effect": {"rho": 3.0}, "motor_lag": {"tau": 0.04}},
            kind="aggressive",
        ),
        Case(
            "three_effects",
            (
                {"name": "ground_effect", "rho": 2.0},
                {"name": "rotor_drag", "coefficient_n_s_m": drag},
                {"name": "thrust_coefficient", "scale": 1.05},
            ),
            {
                "ground_effect": {"rho": 2.0},
                "rotor_drag": {"kxy": drag[0], "kz": drag[2]},
                "thrust_coefficient": {"scale": 1.05},
            },
            nominal=(),
        ),
        # the real ground effect has another shape than the nominal thesis law (rho 1), which
        # it replaces: as strong at rest (53% of a rotor's thrust; less and the autopilot,
        # subtracting the law's 53%, never leaves the ground), 30% at 4 cm (the law: 9%), 8%
        # at 10 cm (1.4%), nothing beyond about 5 rotor radii
        Case(
            "ooc_ground_shape",
            ({"name": "ground_effect_exponential", "gain": 0.7, "decay_radii": 1.0},),
            {},
            replaced=("ground_effect",),
            uncatalogued=True,
            expected_regime=("height_r", "vertical", 6.0),
        ),
        # 0.3% of the thrust per second: 6% of the weight after a 20 s flight; without
        # integral action the vehicle sags (about 0.1 m per % of thrust lost)
        Case(
            "ooc_thrust_decay",
            ({"name": "thrust_decay", "rate_per_s": 0.003},),
            {},
            uncatalogued=True,
            expected_regime=("time_since_takeoff_s", "vertical", None),
        ),
        # the back-right rotor gives 90% of its modelled thrust: 2.5% of the weight missing
        # and a steady torque the attitude loop holds. At 85% the vehicle, sagging 0.4 m
        # below its setpoints, hardly leaves the ground (9 cm at most)
        Case(
            "ooc_weak_rotor",
            ({"name": "rotor_asymmetry", "scales": [1.0, 1.0, 0.9, 1.0]},),
            {},
            uncatalogued=True,
            expected_regime=("rotor", 2),
        ),
        # 8% of the thrust toward +x at the surface, 5% at the 4 cm pass, 1% at 0.15 m
        Case(
            "ooc_outwash",
            ({"name": "ground_outwash", "gain": 0.08, "decay_radii": 2.0, "direction_deg": 0.0},),
            {},
            uncatalogued=True,
            expected_regime=("height_r", "world_x", 6.0),
        ),
    ]


CASES: dict[str, Case] = {c.name: c for c in _cases()}


def real_effects(case: Case) -> tuple[dict, ...]:
    """The real world's effects: the nominal ones the hidden ones neither replace nor
    override, then the hidden ones."""
    dropped = {e["name"] for e in case.hidden} | set(case.replaced)
    return tuple(e for e in case.nominal if e["name"] not in dropped) + case.hidden


def _world_file(path: Path, case: Case, effects: tuple[dict, ...]) -> Path:
    data = {**BASE, **case.world, "effects": [dict(e) for e in effects]}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _drop_stale_flights(folder: Path, key_text: str) -> None:
    """Cached flights are reused only for the same real world and mission kind."""
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
    _drop_stale_flights(folder, real.read_text() + case.kind)
    logs = {}
    for seed in FIT_SEEDS + HOLD_SEEDS:
        mission = bench_mission(case.kind, seed)
        path = folder / f"flight{seed}.csv"
        logs[seed] = real_log(mission, real, path, BENCH_NOISE, seed, record)
    result = run_diagnosis(
        [logs[s] for s in FIT_SEEDS],
        [logs[s] for s in HOLD_SEEDS],
        str(nominal),
        folder / "diagnosis",
        folds=len(FIT_SEEDS),
        replay=replay,
    )
    return score(case, result)


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
        # issue 16's catalogue target: the exact set, every parameter within 10%
        "catalogue_target": (
            exact and all(e <= PARAMETER_TARGET for e in errors)
            if case.truth and not case.uncatalogued
            else None
        ),
        "uncatalogued": verdict(case.expected_regime, result) if case.uncatalogued else None,
        "unexcited_reported_not_identifiable": unexcited_ok if case.unexcited else None,
        "effects": per,
        "force_shrink": gap["force_rms_n"]["shrink"],
        "force_before_n": gap["force_rms_n"]["before"],
        "rollout_shrink": gap.get("rollout_rms_m", {}).get("shrink"),
        "closed_loop": result.get("closed_loop"),
        "false_alarm": bool(reported_set) if not case.truth and not case.uncatalogued else None,
    }


def _floor(effect: str, truth: dict[str, float]) -> float:
    """The scale of a vector parameter's error: its largest true component (a zero wind
    component is judged against the wind's size)."""
    return max(abs(v) for v in truth.values())


def run_bench(cases: list[Case], out: Path, replay: bool = False) -> dict[str, Any]:
    """Every case; `replay`: with the closed-loop re-flights of the held-out missions (two
    more flights a case)."""
    results = []
    for case in cases:
        try:
            results.append(run_case(case, out, replay=replay))
        except Exception as err:  # a failed case is a figure of the bench, not its end
            results.append({"case": case.name, "error": f"{type(err).__name__}: {err}"})
        print(f"gap bench: {case.name}: {_line(results[-1])}", flush=True)
    return {"cases": results, "summary": summarise(results, cases)}


def _line(r: dict[str, Any]) -> str:
    if "error" in r:
        return r["error"]
    if r.get("uncatalogued"):
        return f"out of the catalogue: {verdict_text(r['uncatalogued'])}"
    return (
        f"truth {r['truth']} reported {r['reported']} exact {r['exact']} "
        f"force shrink {r['force_shrink'] * 100:.0f}%"
    )


def _mark(flag: bool | None) -> str:
    return "-" if flag is None else "yes" if flag else "no"


def summarise(results: list[dict[str, Any]], cases: list[Case]) -> dict[str, Any]:
    ok = [r for r in results if "error" not in r]
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
        lines.append(
            f"{r['case']:25s} {_mark(r['exact']):5s}  {_mark(r.get('catalogue_target')):5s}"
            f"  {r['force_shrink'] * 100:8.0f}%     {what}"
        )
    nan = float("nan")
    lines += ["", "effect               F1 (single)  median param error  coverage95"]
    for e, f in s["f1_single"].items():
        p = s["per_effect_parameters"].get(e, {})
        lines.append(
            f"{e:20s} {f['f1']:6.2f} ({f['tp']}/{f['fp']}/{f['fn']})"
            f"  {p.get('median_error', nan) * 100:10.1f}%  {p.get('coverage', nan):8.2f}"
        )
    lines += [
        "",
        f"exact-set rate {s['exact_set_rate']:.2f}; median parameter error "
        f"{s['median_relative_parameter_error'] * 100:.1f}%; coverage {s['coverage95']:.2f}; "
        f"median held-out force shrink {s['median_force_shrink'] * 100:.0f}%; closed-loop "
        f"{s['median_closed_loop_shrink'] * 100:.0f}%; false alarms {s['false_alarm_rate']}; "
        f"unexcited reported not identifiable {s['unexcited_not_identifiable']}; "
        f"wall {scores.get('wall_s', float('nan')):.0f} s",
    ]
    t, u = s.get("catalogue_target_rate", nan), s.get("uncatalogued") or {}
    lines.append(f"catalogue cases with the exact set and every parameter within 10%: {t:.2f}")
    if u.get("cases"):
        lines.append(
            f"out of the catalogue ({u['cases']} cases): located {u['located']:.2f}; no "
            f"catalogue effect named with confidence {u['no_confident_catalogue']:.2f}; "
            f"unexplained share reported {u['share_reported']:.2f}; learnt shrink >= 60% "
            f"{u['learned_shrink_ok']:.2f}; all four {u['passed']:.2f}"
        )
    return "\n".join(lines)
