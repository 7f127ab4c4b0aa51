"""The diagnosis's outputs: the corrected world file, a JSON of every figure, a Markdown
report with PNG plots, and a rerun recording of the residuals over the flights."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from learner.gap.corrected import world_column, world_entries
from learner.gap.diagnose import Diagnosis
from learner.gap.numbers import NO_GAP, fig, json_safe, pct
from learner.gap.regimes import describe_range
from learner.gap.report_unexplained import WORLD_FILE, markdown_section, write_learned
from learner.gap.summaries import markdown_section as summaries_section
from learner.plot_axes import plain_log_axis


def corrected_world_yaml(nominal_yaml: str, diagnosis: Diagnosis) -> str:
    """The nominal world with the effects the diagnosis writes (`corrected.corrected_members`:
    those named present, a group through one member, no sensor effect) added or replaced."""
    data = yaml.safe_load(nominal_yaml)
    chosen = world_entries(diagnosis.corrected)
    names = {e["name"] for e in chosen}
    kept = [e for e in data.get("effects") or [] if e.get("name") not in names]
    data["effects"] = kept + chosen
    header = "# Corrected by `groundfx gap diagnose`: the nominal world plus the effects found.\n"
    return header + yaml.safe_dump(data, sort_keys=False)


def figures(diagnosis: Diagnosis, closed_loop: dict[str, Any] | None) -> dict[str, Any]:
    """Every figure of the run as plain data (a figure that could not be measured: None)."""
    return json_safe(
        {
            "vehicle": diagnosis.vehicle.name if diagnosis.vehicle else None,
            "left_out": diagnosis.left_out,
            "z_offsets_m": diagnosis.z_offsets_m,
            "notes": all_notes(diagnosis, closed_loop),
            "fitting_flights": diagnosis.fitting,
            "held_out_flights": diagnosis.held_out,
            "noise_sd_n": diagnosis.noise_sd_n,
            "ess_ratio": diagnosis.ess_ratio,
            "excitation_z": diagnosis.excitation,
            "effects": diagnosis.effects,
            "chosen": {k: [float(x) for x in v] for k, v in diagnosis.chosen.items()},
            "corrected_world": corrected_world_figures(diagnosis),
            "search": diagnosis.search,
            "regimes": [dict(b.__dict__, significant=b.significant) for b in diagnosis.regimes],
            "rules": diagnosis.rules,
            "gap": diagnosis.gap,
            "unexplained": diagnosis.unexplained,
            "closed_loop": closed_loop,
            "summaries": diagnosis.summaries,
        }
    )


def corrected_world_figures(diagnosis: Diagnosis) -> dict[str, Any]:
    """Exactly what corrected_world.yaml gains (`effects`: its entries), each chosen
    candidate's fate with why, and whether the learnt world is offered."""
    members = diagnosis.corrected
    return {
        "effects": world_entries(members),
        "written": [{k: v for k, v in m.items() if k != "entries"} for m in members["written"]],
        "kept_out": members["kept_out"],
        "learned_world": diagnosis.unexplained.get("learned_world"),
    }


def corrected_world_lines(diagnosis: Diagnosis) -> list[str]:
    """The corrected world in sentences: what went in and why, what was kept out and why."""
    members = diagnosis.corrected
    lines = [f"- written: {m['why']}" for m in members["written"]]
    lines += [f"- kept out: {m['why']}" for m in members["kept_out"]]
    if not lines:
        lines = ["- nothing added: no effect was named present"]
    learned = diagnosis.unexplained.get("learned_world")
    if learned:
        state = "offered" if learned["offered"] else "not written"
        lines.append(f"- the world with the learnt residual ({WORLD_FILE}): {state}: "
                     f"{learned['why']}")  # fmt: skip
    return lines


def closed_loop_sentence(closed_loop: dict[str, Any] | None) -> str | None:
    """The closed-loop replays in words: what was flown, skipped or failed, and why."""
    if not closed_loop:
        return None
    status = closed_loop.get("status")
    if status == "skipped":
        return f"closed-loop replay skipped: {closed_loop['why']}"
    failed = closed_loop.get("failed") or []
    failures = "; ".join(f"{f['flight']} in the {f['world']} world: {f['reason']}" for f in failed)
    if status == "failed":
        return f"closed-loop replay failed, no figure: {failures}"
    why = "the replays share no time with the logged flights"
    text = (
        f"closed-loop tracking difference to the logged flights: "
        f"{fig(closed_loop['before_m'], '.1f', 1000, 'mm', why)} -> "
        f"{fig(closed_loop['after_m'], '.1f', 1000, 'mm', why)}, "
        f"shrink {pct(closed_loop['shrink'], why)} ({closed_loop['flights']} flights)"
    )
    return text + (f"; not flown: {failures}" if failures else "")


def all_notes(diagnosis: Diagnosis, closed_loop: dict[str, Any] | None) -> list[str]:
    """The diagnosis's fallbacks, the rows left out and the replays' fate, as sentences."""
    notes = list(diagnosis.notes)
    summary = diagnosis.left_out.get("summary")
    if summary and summary != "left out: nothing":
        notes.insert(0, summary)
    sentence = closed_loop_sentence(closed_loop)
    if sentence and closed_loop and (closed_loop["status"] != "flown" or closed_loop["failed"]):
        notes.append(sentence)
    for effect, e in diagnosis.effects.items():
        if e["status"] in ("at bound", "implausible"):
            notes.append(f"{effect}: {e['why']}")
    return notes


def write_outputs(
    diagnosis: Diagnosis,
    out: Path,
    nominal_world: Path,
    closed_loop: dict[str, Any] | None = None,
    recording: bool = True,
) -> dict[str, Path]:
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "world": out / "corrected_world.yaml",
        "json": out / "gap.json",
        "report": out / "report.md",
    }
    corrected = corrected_world_yaml(nominal_world.read_text(), diagnosis)
    paths["world"].write_text(corrected)
    paths.update(write_learned(diagnosis, corrected, out))
    data = figures(diagnosis, closed_loop)
    paths["json"].write_text(json.dumps(data, indent=1, default=_plain, allow_nan=False))
    paths.update(_plots(diagnosis, out))
    if recording:
        paths["recording"] = _recording(diagnosis, out / "residuals.rrd")
    paths["report"].write_text(_markdown(diagnosis, closed_loop, nominal_world, paths))
    return paths


def _plain(x: Any) -> Any:
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"not JSON: {type(x)}")


def _plots(diagnosis: Diagnosis, out: Path) -> dict[str, Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = {}
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for name, d in diagnosis.flights.items():
        r = diagnosis.residuals[name]
        c = diagnosis.corrected_residuals[name]
        h = np.where(np.isfinite(d.height_m), d.height_m, np.nan)
        axes[0].plot(h[::5], r[::5, 2] * 1000, ".", ms=1, alpha=0.4, color="tab:red")
        axes[0].plot(h[::5], c[::5, 2] * 1000, ".", ms=1, alpha=0.4, color="tab:blue")
        speed = np.linalg.norm(d.velocity_m_s[:, :2], axis=1)
        along = np.sum(r[:, :2] * d.velocity_m_s[:, :2], axis=1) / np.maximum(speed, 1e-6)
        along_c = np.sum(c[:, :2] * d.velocity_m_s[:, :2], axis=1) / np.maximum(speed, 1e-6)
        axes[1].plot(speed[::5], along[::5] * 1000, ".", ms=1, alpha=0.4, color="tab:red")
        axes[1].plot(speed[::5], along_c[::5] * 1000, ".", ms=1, alpha=0.4, color="tab:blue")
    axes[0].set(
        xscale="log", xlabel="height above the surface (m)", ylabel="vertical residual (mN)"
    )
    plain_log_axis(axes[0].xaxis, subs=(1.0, 2.0, 5.0))  # 0.01, 0.02, 0.05, 0.1 m, ...
    axes[1].set(xlabel="horizontal speed (m/s)", ylabel="residual along the velocity (mN)")
    axes[0].set_title("red: nominal world, blue: corrected")
    fig.tight_layout()
    paths["plot_residuals"] = out / "residuals.png"
    fig.savefig(paths["plot_residuals"], dpi=110)
    plt.close(fig)

    sig = [b for b in diagnosis.regimes if b.significant][:20]
    if sig:
        fig, ax = plt.subplots(figsize=(9, 0.3 * len(sig) + 1.5))
        labels = [f"{describe_range(b.variable, b.low, b.high)} ({b.component[:4]})" for b in sig]
        means = np.array([b.mean for b in sig]) * 100
        err = np.array([[b.mean - b.ci_low, b.ci_high - b.mean] for b in sig]).T * 100
        ax.barh(range(len(sig)), means, xerr=err, color="tab:orange")
        ax.set_yticks(range(len(sig)), labels, fontsize=7)
        ax.set_xlabel("mean residual, % of the weight (95% flight-bootstrap CI)")
        fig.tight_layout()
        paths["plot_regimes"] = out / "regimes.png"
        fig.savefig(paths["plot_regimes"], dpi=110)
        plt.close(fig)
    return paths


def _recording(diagnosis: Diagnosis, path: Path) -> Path:
    """Residuals before and after the correction per flight, on the `sim_time` timeline."""
    import rerun as rr

    rec = rr.RecordingStream("groundfx_gap")
    rec.save(path)
    for name, d in diagnosis.flights.items():
        t = rr.TimeColumn("sim_time", duration=d.time_s)
        for label, r in (("nominal", diagnosis.residuals[name]), ("corrected",
                         diagnosis.corrected_residuals[name])):  # fmt: skip
            rec.send_columns(
                f"gap/{name}/residual_{label}_n",
                indexes=[t],
                columns=rr.Scalars.columns(scalars=r),
            )
        rec.send_columns(
            f"gap/{name}/position_m",
            indexes=[t],
            columns=rr.Points3D.columns(positions=d.position_m),
        )
    rec.flush()
    rr.disconnect(recording=rec)
    return path


def _parameter(name: str, v: dict[str, Any]) -> str:
    """'rho 3.01 (2.95 to 3.07) 1', or the value without an interval, and why."""
    value = fig(v["value"], ".4g", why="the fit gave none")
    if not v.get("ci95"):
        return f"{name} {value} {v['unit']} (refused: no interval)"
    lo, hi = (fig(x, ".4g", why="its standard error could not be computed") for x in v["ci95"])
    return f"{name} {value} ({lo} to {hi}) {v['unit']}"


def _change(g: dict[str, Any], scale: float, unit: str, spec: str = ".2f", why: str = "") -> str:
    """'14.20 mN -> 0.69 mN, shrink 95%', a figure that could not be measured as n/a and why."""
    return (
        f"{fig(g.get('before'), spec, scale, unit, why)} -> "
        f"{fig(g.get('after'), spec, scale, unit, why)}, "
        f"shrink {pct(g.get('shrink'), why or NO_GAP)}"
    )


def _scored_on(gap: dict[str, Any]) -> str:
    if gap.get("in_sample"):
        return "in-sample: one fitting flight, none held out"
    if gap.get("cross_validated"):
        return f"cross-validated over {gap['folds']} folds of the fitting flights"
    return "on the held-out flights"


def _markdown(
    diagnosis: Diagnosis,
    closed_loop: dict[str, Any] | None,
    world: Path,
    paths: dict[str, Path],
) -> str:
    lines = [
        "# Sim-to-real gap diagnosis",
        "",
        f"Nominal world `{world}`; fitting flights {', '.join(diagnosis.fitting)}; "
        f"held out {', '.join(diagnosis.held_out) or 'none (cross-validated)'}. Residual "
        f"noise {fig(diagnosis.noise_sd_n, '.2f', 1000, 'mN')} per component; effective "
        f"samples {fig(diagnosis.ess_ratio, '.2f')} per sample. Vehicle "
        f"`{diagnosis.vehicle.name if diagnosis.vehicle else '?'}`; "
        f"{diagnosis.left_out.get('summary', 'left out: nothing')}.",
        "",
    ]
    notes = all_notes(diagnosis, closed_loop)
    if notes:
        lines += ["## Notes", ""] + [f"- {n}" for n in notes] + [""]
    lines += [
        "## Where",
        "",
    ]
    lines += [f"- {r}" for r in diagnosis.rules] or ["- no regime with a significant residual"]
    if "plot_regimes" in paths:
        lines += ["", "![regimes](regimes.png)"]
    lines += summaries_section(diagnosis.summaries)
    lines += [
        "",
        "## Which",
        "",
        "| effect | status | parameters (95% CI) | corrected world | note |",
        "|---|---|---|---|---|",
    ]
    column = world_column(diagnosis.effects, diagnosis.corrected)
    for effect, e in diagnosis.effects.items():
        params = "; ".join(_parameter(p, v) for p, v in (e.get("parameters") or {}).items())
        note = e.get("why", "")
        if e["status"] == "present" and not e.get("confident", True):
            note = f"not named with confidence: {e.get('confidence_note', '')}"
        lines.append(f"| {effect} | {e['status']} | {params} | {column.get(effect, '')} | {note} |")
    lines += ["", "## The corrected world", "", *corrected_world_lines(diagnosis)]
    g = diagnosis.gap
    lines += ["", "## How far", ""]
    lines.append(f"- force gap (systematic RMS, noise removed; {_scored_on(g)}): "
                 + _change(g["force_rms_n"], 1000, "mN"))  # fmt: skip
    if "force_rms_n_measured_floor" in g:
        m = g["force_rms_n_measured_floor"]
        lines.append(
            f"- the same against the noise floor measured at 0.1 s (Allan variance of the "
            f"corrected residual: {fig(m['floor'], '.2f', 1000, 'mN')}, white noise would "
            f"leave {fig(m['white_floor'], '.2f', 1000)}): " + _change(m, 1000, "mN")
        )
    if "torque_rms_n_m" in g:
        lines.append(
            "- torque gap (body frame, RMS of 0.1 s means; holds the rate noise's floor): "
            + _change(g["torque_rms_n_m"], 1e6, "uN m")
        )
    if "rollout_rms_m" in g:
        r = g["rollout_rms_m"]
        lines.append(
            f"- open-loop rollout error at {r['horizon_s']:g} s: "
            + _change(r, 1000, "mm", ".1f", "no rollout fits in the flights' stretches")
            + " (includes the noise of the logged start states)"
        )
    sentence = closed_loop_sentence(closed_loop)
    if sentence:
        lines.append(f"- {sentence}")
    regions = g.get("regions") or []
    if regions:
        lines += [
            "",
            "| region | samples | before (mN) | after (mN) | shrink |",
            "|---|---|---|---|---|",
        ]
        for r in regions:
            if r["before_n"] < 1e-3:
                continue
            lines.append(
                f"| {describe_range(r['variable'], r['low'], r['high'])} | {r['samples']} | "
                f"{fig(r['before_n'], '.2f', 1000)} | {fig(r['after_n'], '.2f', 1000)} | "
                f"{pct(r['shrink'])} |"
            )
    lines += markdown_section(diagnosis)
    lines += ["", "![residuals](residuals.png)", "", "Outputs: " + ", ".join(
        f"`{p.name}`" for p in paths.values())]  # fmt: skip
    return "\n".join(lines) + "\n"
