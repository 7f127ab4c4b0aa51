"""`groundfx experiment NAME|all [--trials N] [--workers K | --ray ADDRESS] --out DIR`."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from mission.cli.options import add_campaign_options, positive_int
from simbridge.config import ConfigError


def add_experiment_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "experiment",
        help="the thesis's experiments 4.1-4.7: seeded real flights, statistics, reports",
        description="Fly the thesis's experiments (chapter 4) as seeded trials; results are "
        "appended to DIR/results.jsonl as they finish (a rerun resumes), reports go to "
        "DIR/<experiment>/report.md and DIR/summary.md.",
    )
    p.add_argument("name", help="all, or an experiment: 4.1 ... 4.7 (or 1 ... 7)")
    p.add_argument(
        "--trials", type=positive_int, help="trials per condition (default: each condition's own)"
    )
    p.add_argument("--seed", type=int, default=0, help="first trial seed (default: 0)")
    add_campaign_options(p, "trials' flights")
    p.add_argument("--out", type=Path, required=True, help="folder of results and reports")
    p.add_argument(
        "--keep-recordings", action="store_true", help="record every flight to DIR/recordings"
    )
    p.set_defaults(func=cmd_experiment)


def cmd_experiment(args: argparse.Namespace) -> int:
    from mission.campaigns.experiments import campaign, definitions, report

    t0 = time.perf_counter()
    try:
        experiments = definitions.select(args.name)
    except KeyError as err:
        raise ConfigError(str(err.args[0])) from None
    plans = {e.key: definitions.plan(e, args.trials, args.seed) for e in experiments}
    artefacts = campaign.prepare_artefacts(experiments, args.out)
    trials = [t for e in experiments for t in plans[e.key]]
    results = campaign.run_trials(
        trials,
        args.out,
        artefacts,
        workers=args.workers,
        ray_address=args.ray,
        keep_recordings=args.keep_recordings,
        progress=not args.no_progress,
    )
    all_values = {}
    verdict_lines = []
    for e in experiments:
        _, values, rows = report.experiment_report(e, plans[e.key], results, args.out / e.key)
        all_values[e.key] = values
        verdict_lines += [report.verdict_line(e.key, r) for r in rows]
    unfinished = sum(1 for t in trials if t.id not in results)
    wall_s = time.perf_counter() - t0
    table = report.summary_table(experiments, all_values)
    lines = [
        "# Experiments: summary",
        "",
        f"{len(trials)} trials ({unfinished} unfinished) of {len(experiments)} experiments in "
        f"{wall_s / 60:.1f} min wall time (this run; finished trials of earlier runs were "
        "kept). Mean [95% CI].",
        "",
        *table,
        "",
        "## Expectations",
        "",
        *verdict_lines,
        "",
    ]
    (args.out / "summary.md").write_text("\n".join(lines))
    print("\n".join(table))
    print(
        f"groundfx experiment: {len(trials) - unfinished} of {len(trials)} trials in "
        f"{wall_s / 60:.1f} min; reports in {args.out}/<experiment>/report.md, summary in "
        f"{args.out / 'summary.md'}"
    )
    return 1 if unfinished else 0
