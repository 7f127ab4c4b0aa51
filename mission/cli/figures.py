"""`groundfx figures`: run the seeded commands the guide quotes and refresh its figures."""

from __future__ import annotations

import argparse
from typing import Any


def add_parser(sub: Any) -> None:
    from mission.campaigns.figures import SOURCES

    names = ",".join(s.name for s in SOURCES)
    p = sub.add_parser(
        "figures",
        help="regenerate docs/results/*.json and the figures README.md and docs/ quote",
    )
    p.add_argument("--only", help=f"comma-separated sources (default: all of {names})")
    p.add_argument(
        "--rewrite-only",
        action="store_true",
        help="fly nothing: fill the pages from the results files as they are",
    )
    p.set_defaults(func=cmd_figures)


def cmd_figures(args: argparse.Namespace) -> int:
    from mission.campaigns.figures import run_figures

    names = args.only.split(",") if args.only else None
    return run_figures(names, args.rewrite_only)
