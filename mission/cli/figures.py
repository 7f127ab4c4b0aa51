"""`groundfx figures`: run the seeded commands the guide quotes and refresh its figures."""

from __future__ import annotations

import argparse
from typing import Any


def add_parser(sub: Any) -> None:
    from mission.campaigns.figures import SOURCES

    names = ",".join(s.name for s in SOURCES)

    def sources(text: str) -> list[str]:
        asked = text.split(",")
        unknown = [n for n in asked if n not in names.split(",")]
        if unknown:
            raise argparse.ArgumentTypeError(f"{','.join(unknown)}: choose from {names}")
        return asked

    p = sub.add_parser(
        "figures",
        help="regenerate docs/results/*.json and the figures README.md and docs/ quote",
    )
    p.add_argument(
        "--only", type=sources, help=f"comma-separated sources (default: all of {names})"
    )
    p.add_argument(
        "--rewrite-only",
        action="store_true",
        help="fly nothing: fill the pages from the results files as they are",
    )
    p.set_defaults(func=cmd_figures)


def cmd_figures(args: argparse.Namespace) -> int:
    from mission.campaigns.figures import run_figures

    return run_figures(args.only, args.rewrite_only)
