"""`groundfx figures`: every figure README.md and docs/ quote, from the command that makes it.

Each source runs one seeded command and writes `docs/results/<name>.json` with the date, the
commit, the machine's load average and the command, so that a reader can run it again and
get the same numbers. The pages quote a figure between markers that are invisible on GitHub,
`<!--fig demo.neural.hold_rms_mm-->1.05<!--/fig-->`, and `rewrite_pages` fills them in from
the results files. Only seeded figures are quoted: speed depends on the machine and its load.
"""

from __future__ import annotations

import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
RESULTS_DIR = REPO / "docs" / "results"
DEMO_REPORT = "demo-neural.report.png"
MARKER = re.compile(r"<!--fig ([\w.-]+)-->(.*?)<!--/fig-->", flags=re.S)

Figures = dict[str, str]


@dataclass(frozen=True)
class Source:
    """One command whose output the pages quote."""

    name: str
    command: str
    run: Callable[[], Figures]


def _quiet(_text: str) -> None:
    pass


def _demo() -> Figures:
    from mission.campaigns.demo import fly_demo

    with tempfile.TemporaryDirectory() as logs:
        summaries = fly_demo("rho2", Path(logs), say=_quiet)
        # the learned model's flight on one page, as the README shows it
        shutil.copyfile(summaries["neural"]["report"], RESULTS_DIR / DEMO_REPORT)
    figures = {"neural.report": f"results/{DEMO_REPORT}"}
    for model, s in summaries.items():
        figures[f"{model}.landing_error_mm"] = f"{s['landing_error_m'] * 1000:.2f}"
        figures[f"{model}.hold_rms_mm"] = f"{s['hold_z_rms_error_m'] * 1000:.2f}"
        figures[f"{model}.touchdown_speed_m_s"] = f"{s['touchdown_speed_m_s']:.3f}"
    return figures


def _hold_errors_m(seeds: list[int], model: str, world: str) -> list[float]:
    """`groundfx learn evaluate`'s trials of one model. A flight whose link was cut (a process
    gone, or silent past the link timeout) has no hold: it is flown again, and being
    seeded and in lockstep it flies as it would have."""
    from mission.campaigns.trials import fly_landing_trials

    runs = fly_landing_trials(seeds, model, world)
    for i, run in enumerate(runs):
        for _ in range(2):
            if run.get("hold_z_rms_error_m") is not None:
                break
            run = runs[i] = fly_landing_trials([seeds[i]], model, world)[0]
    return [float(run["hold_z_rms_error_m"]) for run in runs]


def _evaluate() -> Figures:
    """As `groundfx learn evaluate` at its defaults: the rho2 world, the network nearest its rho,
    seeds 0-9."""
    import numpy as np

    from learner.stats import gap_closed, welch

    seeds = list(range(10))
    errors = {m: np.array(_hold_errors_m(seeds, m, "rho2")) for m in ("none", "analytic", "neural")}
    figures = {f"{m}.hold_rms_mm": f"{e.mean() * 1000:.2f}" for m, e in errors.items()}
    closed = gap_closed(errors["none"], errors["analytic"], errors["neural"])
    _, p = welch(errors["neural"], errors["none"])
    # as `groundfx learn evaluate` prints them
    figures["gap_closed_pct"] = f"{closed * 100:.1f}"
    figures["welch_p"] = f"{p:.2g}"
    figures["trials"] = str(len(seeds))
    return figures


def _lift() -> Figures:
    from simbridge.demo import run_demo

    lines: list[str] = []
    with tempfile.TemporaryDirectory() as logs:
        run_demo("default", Path(logs), say=lines.append)
    text = "\n".join(lines)
    predicted = re.search(r"predicts ([\d.]+) m/s\^2", text)
    first_row = re.search(r"^\s*0\.000\s+([\d.]+)\s+[-\d.]+\s+([-\d.]+)\s*$", text, flags=re.M)
    if predicted is None or first_row is None:
        raise RuntimeError(f"groundfx demo --lift printed no prediction and row:\n{text}")
    return {
        "predicted_m_s2": predicted.group(1),
        "measured_m_s2": first_row.group(2),
        "altitude_m": first_row.group(1),
    }


GAP_CASE = "rotor_drag_b"
GAP_COMMANDS = (
    f"groundfx gap bench --out logs/gap-bench --cases {GAP_CASE}; "
    f"groundfx gap diagnose logs/gap-bench/{GAP_CASE}/flight0.csv "
    f"logs/gap-bench/{GAP_CASE}/flight1.csv --holdout logs/gap-bench/{GAP_CASE}/flight100.csv "
    f"--world logs/gap-bench/{GAP_CASE}/nominal_world.yaml --folds 2 --out logs/gap-rotor-drag"
)


def _groundfx(*args: str) -> None:
    """One `groundfx` command in a process of its own, as a user runs it."""
    done = subprocess.run(
        [sys.executable, "-m", "mission.cli", *args], cwd=REPO, capture_output=True, text=True
    )
    if done.returncode != 0:
        raise RuntimeError(f"groundfx {' '.join(args)} exited with {done.returncode}:\n"
                           f"{done.stderr[-2000:]}")  # fmt: skip


def _gap() -> Figures:
    """The gap diagnosis's worked example: a bench case's flights, diagnosed by hand."""
    import yaml

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "gap-bench" / GAP_CASE
        _groundfx("gap", "bench", "--out", str(folder.parent), "--cases", GAP_CASE)
        logs = [str(folder / f"flight{seed}.csv") for seed in (0, 1, 100)]
        out = Path(tmp) / "gap-rotor-drag"
        world = str(folder / "nominal_world.yaml")
        _groundfx("gap", "diagnose", *logs[:2], "--holdout", logs[2], "--world", world,
                  "--folds", "2", "--out", str(out))  # fmt: skip
        result = json.loads((out / "gap.json").read_text())
        real = yaml.safe_load((folder / "real_world.yaml").read_text())
    drag = result["effects"]["rotor_drag"]
    kxy = drag["parameters"]["kxy"]
    true_kxy = next(e for e in real["effects"] if e["name"] == "rotor_drag")["coefficient_n_s_m"]
    force = result["gap"]["force_rms_n"]
    return {
        "rotor_drag.status": drag["status"],
        "rotor_drag.kxy": f"{kxy['value']:.3g}",
        "rotor_drag.kxy_low": f"{kxy['ci95'][0]:.3g}",
        "rotor_drag.kxy_high": f"{kxy['ci95'][1]:.3g}",
        "rotor_drag.true_kxy": f"{true_kxy[0]:.3g}",
        "chosen": ", ".join(result["chosen"]),
        "force_gap_before_mn": f"{force['before'] * 1000:.2f}",
        "force_gap_after_mn": f"{force['after'] * 1000:.2f}",
        "shrink_pct": f"{force['shrink'] * 100:.0f}",
    }


def _experiments() -> Figures:
    """`groundfx experiment all` at its defaults: the summary's table of conditions and its
    verdicts, as the run's summary.md writes them (its wall time left out)."""
    with tempfile.TemporaryDirectory() as tmp:
        _groundfx("experiment", "all", "--out", tmp, "--no-progress")
        summary = (Path(tmp) / "summary.md").read_text()
    table = [ln for ln in summary.splitlines() if ln.startswith("|")]
    verdicts = [ln for ln in summary.splitlines() if ln.startswith("- 4.")]
    if not table or not verdicts:
        raise RuntimeError(f"groundfx experiment all wrote no table or verdicts:\n{summary}")
    return {"table": "\n" + "\n".join(table) + "\n", "verdicts": "\n" + "\n".join(verdicts) + "\n"}


SOURCES = (
    Source("lift", "groundfx demo --lift", _lift),
    Source("demo", "groundfx demo", _demo),
    Source("evaluate", "groundfx learn evaluate", _evaluate),
    Source("gap", GAP_COMMANDS, _gap),
    Source("experiments", "groundfx experiment all --out logs/experiments", _experiments),
)


def _commit() -> str:
    def git(*args: str) -> str:
        return subprocess.run(
            ["git", *args], cwd=REPO, capture_output=True, text=True, check=False
        ).stdout.strip()

    sha = git("rev-parse", "--short=12", "HEAD") or "unknown"
    # the pages and results this run rewrites do not count: the code it ran does
    changed = git("status", "--porcelain", "--untracked-files=no", "--", ".", ":(exclude)docs",
                  ":(exclude)README.md")  # fmt: skip
    return sha + ("-dirty" if changed else "")


def produce(source: Source, results_dir: Path = RESULTS_DIR) -> Path:
    """Run one source's command and write its results file."""
    load_before = os.getloadavg()
    started = datetime.now(UTC)
    figures = source.run()
    record: dict[str, Any] = {
        "command": source.command,
        "date": started.strftime("%Y-%m-%d %H:%M UTC"),
        "commit": _commit(),
        "machine": f"{platform.machine()}, {os.cpu_count()} CPUs, {platform.python_version()}",
        "load_average_1min": [round(load_before[0], 1), round(os.getloadavg()[0], 1)],
        "figures": figures,
    }
    results_dir.mkdir(parents=True, exist_ok=True)
    path = results_dir / f"{source.name}.json"
    path.write_text(json.dumps(record, indent=2) + "\n")
    return path


def load_figures(results_dir: Path = RESULTS_DIR) -> Figures:
    """Every figure of every results file, named `<file>.<figure>`."""
    figures = {}
    for path in sorted(results_dir.glob("*.json")):
        for key, value in json.loads(path.read_text())["figures"].items():
            figures[f"{path.stem}.{key}"] = value
    return figures


def quoted(text: str) -> list[tuple[str, str]]:
    """The figures a page quotes: (name, the value written)."""
    return [(m.group(1), m.group(2)) for m in MARKER.finditer(text)]


def pages(repo: Path = REPO) -> list[Path]:
    return [repo / "README.md", *sorted((repo / "docs").glob("*.md"))]


def rewrite_pages(figures: Figures, paths: Iterable[Path]) -> list[str]:
    """Fill every marker from the figures; returns the names no results file holds."""
    unknown: list[str] = []

    def fill(match: re.Match[str]) -> str:
        name = match.group(1)
        if name not in figures:
            unknown.append(name)
            return match.group(0)
        return f"<!--fig {name}-->{figures[name]}<!--/fig-->"

    for path in paths:
        text = path.read_text()
        new = MARKER.sub(fill, text)
        if new != text:
            path.write_text(new)
    return unknown


CLI_PAGE = REPO / "docs" / "cli.md"


def _groundfx_module(module: str, *args: str) -> None:
    subprocess.run([sys.executable, "-m", module, *args], cwd=REPO, check=True)


def run_figures(names: list[str] | None, rewrite_only: bool, say=print) -> int:
    chosen = [s for s in SOURCES if names is None or s.name in names]
    if not rewrite_only:
        for source in chosen:
            say(f"groundfx figures: {source.command} ...")
            say(f"  wrote {produce(source).relative_to(REPO)}")
    _groundfx_module("mission.cli.reference", str(CLI_PAGE))
    unknown = rewrite_pages(load_figures(), pages())
    if unknown:
        say("groundfx figures: no results for " + ", ".join(sorted(set(unknown))))
        return 1
    say("groundfx figures: README.md and docs/*.md quote the results files")
    return 0
