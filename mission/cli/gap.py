"""`groundfx gap diagnose|convert|bench`: the sim-to-real gap diagnosis on flight logs, any
flight log written in our format, and the diagnosis's blind check on "real" flights flown in
worlds holding effects the diagnosis is not told."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from learner.flightlogs.packaged import packaged_mappings
from learner.flightlogs.readers import known_formats
from mission.cli.options import add_campaign_options
from simbridge.config import ConfigError


def add_parser(sub: Any) -> None:
    g = sub.add_parser("gap", help="sim-to-real gap diagnosis").add_subparsers(
        dest="gap_command", required=True
    )
    d = g.add_parser("diagnose", help="residuals, effects and a corrected world from flight logs")
    d.add_argument(
        "logs", type=Path, nargs="+",
        help=f"flight logs: {known_formats()}",
    )  # fmt: skip
    d.add_argument("--world", required=True, help="the nominal world (YAML or packaged name)")
    d.add_argument("--holdout", type=Path, nargs="+", default=[], help="logs to score only")
    d.add_argument("--folds", type=int, default=3, help="cross-validation folds over flights")
    d.add_argument(
        "--columns",
        help=f"column mapping YAML or packaged name ({', '.join(packaged_mappings())})",
    )
    d.add_argument(
        "--vehicle",
        help="vehicle YAML or packaged name (default: the world's `vehicle:`, else nano; "
        "a vehicle other than the world's is refused)",
    )
    d.add_argument(
        "--mass", type=float, metavar="KG",
        help="the vehicle's mass, kg, over its file's (a packaged vehicle of another weight "
        "without a copy of its YAML); the replays fly it too",
    )  # fmt: skip
    d.add_argument(
        "--z-offset", type=float, metavar="M",
        help="subtract M from every log's z, m (the logs' frame puts the world's ground at "
        "z = M less the vehicle's resting height); default: found from where each flight "
        "rests on the ground, none for flights that never rest and no flight that does",
    )  # fmt: skip
    d.add_argument(
        "--candidates", metavar="NAME,...",
        help="comma-separated catalogue candidates the search may choose from (default: all; "
        "the others are reported as not tried), e.g. ground_effect,thrust_mass,motor_lag",
    )  # fmt: skip
    d.add_argument("--no-replay", action="store_true", help="skip the closed-loop re-flights")
    add_campaign_options(d, "replays' flights", progress=False)
    d.add_argument("--out", type=Path, required=True, help="output folder")
    d.set_defaults(func=cmd_diagnose)
    c = g.add_parser("convert", help="write any readable flight log in our format")
    c.add_argument(
        "log", type=Path,
        help=f"flight log: {known_formats()}",
    )  # fmt: skip
    c.add_argument("out", type=Path, help="our format: .csv (with a .json sidecar) or .parquet")
    c.add_argument(
        "--columns",
        help=f"column mapping YAML or packaged name ({', '.join(packaged_mappings())})",
    )
    c.add_argument("--vehicle", default="nano", help="vehicle YAML or packaged name")
    c.set_defaults(func=cmd_convert)
    b = g.add_parser("bench", help="the diagnosis, scored on flights with withheld effects")
    b.add_argument("--out", type=Path, required=True, help="output folder (flights are cached)")
    b.add_argument("--cases", help="comma-separated case names (default: all)")
    b.add_argument(
        "--replay", action="store_true",
        help="also fly each held-out mission again in the nominal and corrected worlds",
    )  # fmt: skip
    b.add_argument("--json", action="store_true", help="print the scores as one JSON object")
    add_campaign_options(b, "cases")
    b.set_defaults(func=cmd_bench)


def cmd_diagnose(args: argparse.Namespace) -> int:
    from mission.campaigns.gap_diagnosis import run_diagnosis

    result = run_diagnosis(
        args.logs, args.holdout, args.world, args.out, args.folds, args.columns, args.vehicle,
        not args.no_replay, args.z_offset,
        args.candidates.split(",") if args.candidates else None, progress=True,
        mass_kg=args.mass, workers=args.workers, ray_address=args.ray,
    )  # fmt: skip
    for effect, e in result["effects"].items():
        params = ", ".join(f"{p} {v['value']:.4g}" for p, v in (e.get("parameters") or {}).items())
        shown = f" ({params})" if params and e["status"] == "present" else ""
        why = f" ({e['why']})" if e["status"] in ("at bound", "implausible") else ""
        if e["status"] == "present" and not e.get("confident", True):
            why = f"; not confident: {e.get('confidence_note', '')}"
        print(f"{effect:20s} {e['status']}{shown}{why}")
    for note in result.get("notes") or []:
        print(f"note: {note}")
    world = result.get("corrected_world") or {}
    for m in world.get("written", []):
        print(f"corrected world: in: {m['why']}")
    for m in world.get("kept_out", []):
        print(f"corrected world: out: {m['why']}")
    if not world.get("written"):
        print("corrected world: nothing added (no effect named present)")
    g = result["gap"]
    m = g.get("force_rms_n_measured_floor")
    if m:
        print(f"against the measured noise floor ({_fig(m['floor'], 1e3, 'mN')}, white "
              f"{_fig(m['white_floor'], 1e3, 'mN')}): {_gap(m, 1e3, 'mN')}")  # fmt: skip
    learned = g.get("force_rms_n_learned")
    if learned:
        print(f"with the learnt residual: {_gap(learned, 1e3, 'mN')}")
    unexplained = result.get("unexplained") or {}
    if unexplained.get("sentence"):
        print(f"unexplained: {unexplained['sentence']}")
    rotors = (result.get("summaries") or {}).get("rotors") or {}
    if rotors.get("rule"):
        print(f"rotors: {rotors['rule']}")
    if unexplained.get("disagreement"):
        print(f"flights: {unexplained['disagreement']['sentence']}")
    offer = unexplained.get("learned_world")
    if offer:
        state = "corrected_world_learned.yaml" if offer["offered"] else "not written"
        print(f"learnt world: {state}: {offer['why']}")
    # the ending a reader looks for: the gaps before and after, what is left, where to read on
    line = closed_loop_line(result.get("closed_loop"))
    if line:
        print(line)
    print(f"force gap: {_gap(g['force_rms_n'], 1e3, 'mN')}")
    if g.get("torque_rms_n_m"):
        print(f"torque gap: {_gap(g['torque_rms_n_m'], 1e6, 'uN m')}")
    if unexplained.get("share") is not None:
        print(f"left unexplained by the catalogue: {_pct(unexplained['share'])} of the "
              "systematic force gap")  # fmt: skip
    print(f"report: {args.out / 'report.md'}")
    return 0


def closed_loop_line(closed: dict[str, Any] | None) -> str | None:
    """The replays' figure, where they flew, and a warning where the corrected world flies
    the held-out missions further from the logged flights than the nominal world does."""
    from learner.gap.report import closed_loop_sentence

    if not closed or closed.get("status") != "flown":
        return None  # skipped or failed: a note says why
    line = str(closed_loop_sentence(closed))
    if (closed.get("shrink") or 0.0) < 0.0:
        line += (
            "; the corrected world flies further from the logged flights than the nominal "
            "one: its effects do not carry into closed loop as fitted"
        )
    return line


def _pct(share: float | None) -> str:
    """A share as a percentage; never "nan%" (a share that could not be measured)."""
    from learner.gap.numbers import pct

    return pct(share)


def _fig(value: float | None, scale: float, unit: str) -> str:
    from learner.gap.numbers import fig

    return fig(value, ".2f", scale, unit)


def _gap(g: dict[str, float], scale: float, unit: str) -> str:
    """before -> after (shrink), in `unit`."""
    return (f"{_fig(g.get('before'), scale, unit)} -> {_fig(g.get('after'), scale, unit)} "
            f"(shrink {_pct(g.get('shrink'))})")  # fmt: skip


def cmd_convert(args: argparse.Namespace) -> int:
    from learner.flightlogs.flightlog import write_log
    from learner.flightlogs.readers import read_log
    from learner.flightlogs.summary import summarize, summary_lines
    from learner.flightlogs.tables import load_mapping
    from simbridge.vehicle import load_vehicle

    if args.out.suffix not in (".csv", ".parquet"):
        raise ConfigError(f"{args.out}: our format is written as .csv or .parquet")
    vehicle = load_vehicle(args.vehicle)
    mapping = load_mapping(args.columns) if args.columns else None
    log = read_log(args.log, mapping, vehicle)
    write_log(log, args.out)
    for line in summary_lines(summarize(log, vehicle), vehicle):
        print(line)
    print(f"wrote {args.out}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from mission.campaigns.gap_bench import run_bench, table
    from mission.campaigns.gap_bench_cases import CASES

    names = args.cases.split(",") if args.cases else list(CASES)
    unknown = [n for n in names if n not in CASES]
    if unknown:
        raise ConfigError(f"--cases: unknown case {unknown[0]!r}; known: {', '.join(CASES)}")
    wall0 = time.perf_counter()
    scores = run_bench(
        [CASES[n] for n in names], args.out, args.replay, args.workers, args.ray,
        progress=not args.no_progress and sys.stderr.isatty(),
    )  # fmt: skip
    scores["wall_s"] = time.perf_counter() - wall0
    (args.out / "bench.json").write_text(json.dumps(scores, indent=1))
    print(json.dumps(scores) if args.json else table(scores))
    return 0
