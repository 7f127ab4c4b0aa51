"""The reports: one Markdown file with tables and a PNG per experiment, and one summary.
Statistics as thesis section 3.6 sets them out (learner/stats.py): mean and t-based 95%
confidence interval per condition, Welch t-tests with p-values and Hedges's g between them."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from learner.plot_axes import plain_log_axis
from learner.stats import compare, describe, verdict
from mission.campaigns.experiments.definitions import MEASURES, PRIMARY, Experiment, Trial


def condition_values(
    experiment: Experiment, trials: list[Trial], results: dict[str, dict[str, Any]]
) -> dict[str, dict[str, np.ndarray]]:
    """measure values per condition, over the finished trials (a measure a flight lacks, as
    the landing error of a flight that never touched down, is left out)."""
    out: dict[str, dict[str, np.ndarray]] = {}
    for c in experiment.conditions:
        records = [results[t.id] for t in trials if t.condition == c.name and t.id in results]
        out[c.name] = {
            m: np.array([r["metrics"][m] for r in records if r["metrics"].get(m) is not None])
            for m in MEASURES
        }
    return out


def _fmt(value: float, measure: str) -> str:
    scale = MEASURES[measure][2]
    return "n/a" if not np.isfinite(value) else f"{value * scale:.{_digits(measure)}f}"


def _digits(measure: str) -> int:
    digits = {"hold_z_rms_error_m": 2, "landing_error_m": 1, "touchdown_speed_m_s": 3}
    return digits.get(measure, 1)


def _cell(values: np.ndarray, measure: str) -> str:
    if len(values) == 0:
        return "n/a"
    d = describe(values)
    low, high = _fmt(d["ci_low"], measure), _fmt(d["ci_high"], measure)
    return f"{_fmt(d['mean'], measure)} [{low}, {high}]"


def _p(p: float) -> str:
    return "n/a" if not np.isfinite(p) else f"{p:.2g}"


def _g(g: float) -> str:
    if np.isnan(g):
        return "n/a"
    return ("inf" if g > 0 else "-inf") if np.isinf(g) else f"{g:.2f}"


def expectation_rows(
    experiment: Experiment, values: dict[str, dict[str, np.ndarray]]
) -> list[dict[str, Any]]:
    """Each expectation with its comparison on its measure and the verdict."""
    rows = []
    for e in experiment.expectations:
        a, b = values[e.a][e.measure], values[e.b][e.measure]
        nothing = {"diff": np.nan, "t": np.nan, "p": np.nan, "g": np.nan}
        cmp = compare(a, b) if len(a) and len(b) else nothing
        rows.append({"expectation": e, **cmp, "verdict": verdict(e.relation, cmp)})
    return rows


def verdict_line(key: str, row: dict[str, Any]) -> str:
    """One expectation's verdict in the summary: the difference in its measure's unit."""
    e = row["expectation"]
    _, unit, scale = MEASURES[e.measure]
    return (
        f"- {key} `{e.a}` vs `{e.b}` ({e.claim}): {row['verdict']} "
        f"(a - b = {row['diff'] * scale:.2f} {unit}, p = {row['p']:.2g})"
    )


def _conclusion(row: dict[str, Any], values: dict[str, dict[str, np.ndarray]]) -> str:
    e = row["expectation"]
    a, b = values[e.a][e.measure], values[e.b][e.measure]
    ma = _fmt(float(a.mean()) if len(a) else np.nan, e.measure)
    mb = _fmt(float(b.mean()) if len(b) else np.nan, e.measure)
    rel = "lower than" if e.relation == "lower" else "no different from"
    said = f"expected `{e.a}` {rel} `{e.b}` ({e.claim})"
    unit = MEASURES[e.measure][1]
    data = f"{ma} {unit} against {mb} {unit}, p = {_p(row['p'])}, g = {_g(row['g'])}"
    if row["verdict"] == "supported":
        return f"- The data support it: {said}: {data}."
    if row["verdict"] == "contradicted":
        found = "lower" if row["diff"] < 0 else "higher"
        return (
            f"- **The data differ from the expectation**: {said}, but `{e.a}` is "
            f"significantly {found}: {data}."
        )
    return f"- Not shown by these trials: {said}: {data}."


def plot_experiment(
    experiment: Experiment, values: dict[str, dict[str, np.ndarray]], path: Path
) -> Path:
    """Mean with 95% CI and each trial, per condition: hold error (log) and touchdown speed."""
    names = [c.name for c in experiment.conditions]
    fig, axes = plt.subplots(1, 2, figsize=(max(7.0, 0.7 * len(names) + 3), 4.2))
    for ax, measure, log in zip(axes, (PRIMARY, "touchdown_speed_m_s"), (True, False), strict=True):
        label, unit, scale = MEASURES[measure]
        for i, name in enumerate(names):
            v = values[name][measure] * scale
            if len(v) == 0:
                continue
            d = describe(v)
            ax.plot(np.full(len(v), i) + 0.12, v, ".", color="0.6", ms=4)
            ax.errorbar(i, d["mean"], yerr=[[d["mean"] - d["ci_low"]], [d["ci_high"] - d["mean"]]],
                        fmt="o", color="C0", capsize=3)  # fmt: skip
        ax.set_xticks(range(len(names)), names, rotation=45, ha="right", fontsize=8)
        ax.set_ylabel(f"{label} [{unit}]")
        if log:
            ax.set_yscale("log")
            plain_log_axis(ax.yaxis)
        ax.grid(alpha=0.3)
    fig.suptitle(f"{experiment.key} {experiment.title} (mean, 95% CI, trials)", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def experiment_report(
    experiment: Experiment,
    trials: list[Trial],
    results: dict[str, dict[str, Any]],
    folder: Path,
) -> tuple[Path, dict[str, dict[str, np.ndarray]], list[dict[str, Any]]]:
    """Write folder/report.md and folder/errors.png; returns them with the values and rows."""
    folder.mkdir(parents=True, exist_ok=True)
    lines = [f"# Experiment {experiment.key}: {experiment.title}", "", experiment.question, ""]
    values = condition_values(experiment, trials, results)
    missing = [t.id for t in trials if t.id not in results]
    seeds = sorted({t.seed for t in trials})
    lines += [
        f"Trials: {len(trials) - len(missing)} of {len(trials)} finished; seeds "
        f"{seeds[0]}-{seeds[-1]}, shared across conditions. Each trial is a real flight "
        "(simulator and autopilot processes in lockstep); mean [95% CI] per condition.",
        "",
        "| condition | what | n | "
        + " | ".join(f"{m[0]} [{m[1]}]" for m in MEASURES.values())
        + " |",
        "|---|---|---|" + "---|" * len(MEASURES),
    ]
    for c in experiment.conditions:
        v = values[c.name]
        cells = " | ".join(_cell(v[m], m) for m in MEASURES)
        lines.append(f"| `{c.name}` | {c.label} | {len(v[PRIMARY])} | {cells} |")
    plot = plot_experiment(experiment, values, folder / "errors.png")
    rows = expectation_rows(experiment, values)
    lines += [
        "",
        f"![errors]({plot.name})",
        "",
        "## Comparisons (Welch t-test, Hedges's g of a - b)",
        "",
        "| a | b | expected | measure | a - b | t | p | g | verdict |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        e = r["expectation"]
        t = "n/a" if not np.isfinite(r["t"]) else f"{r['t']:.2f}"
        label, unit, _ = MEASURES[e.measure]
        lines.append(
            f"| `{e.a}` | `{e.b}` | {e.relation}: {e.claim} | {label} | "
            f"{_fmt(r['diff'], e.measure)} {unit} | {t} | {_p(r['p'])} | {_g(r['g'])} | "
            f"{r['verdict']} |"
        )
    lines += ["", "## Conclusions", "", *(_conclusion(r, values) for r in rows)]
    if missing:
        lines += ["", f"Unfinished or failed trials ({len(missing)}): " + ", ".join(missing)]
    path = folder / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path, values, rows


def summary_table(
    experiments: list[Experiment], all_values: dict[str, dict[str, dict[str, np.ndarray]]]
) -> list[str]:
    """One row per condition: the primary measure, landing error, touchdown speed and the
    model's error over the hold (predicted minus true force, where a model flies)."""
    lines = [
        "| experiment | condition | n | hold z RMS [mm] | landing error [mm] | touchdown [m/s] "
        "| model error over the hold [mN] |",
        "|---|---|---|---|---|---|---|",
    ]
    model = "ge_z_hold_rms_error_n"
    for e in experiments:
        values = all_values.get(e.key)
        if not values:
            lines.append(f"| {e.key} | not run | | | | | |")
            continue
        for c in e.conditions:
            v = values[c.name]
            lines.append(
                f"| {e.key} | `{c.name}` | {len(v[PRIMARY])} | {_cell(v[PRIMARY], PRIMARY)} | "
                f"{_cell(v['landing_error_m'], 'landing_error_m')} | "
                f"{_cell(v['touchdown_speed_m_s'], 'touchdown_speed_m_s')} | "
                f"{_cell(v[model], model) if c.flights[-1].model != 'none' else 'n/a'} |"
            )
    return lines
