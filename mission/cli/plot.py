"""`groundfx plot ground-effect`: figures."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from mission.cli.options import DEFAULT_LOGS
from simbridge.config import ConfigError


def add_parser(sub: Any) -> None:
    p = sub.add_parser("plot", help="figures")
    plot_sub = p.add_subparsers(dest="figure", required=True, metavar="FIGURE")
    g = plot_sub.add_parser(
        "ground-effect", help="ground-effect force against altitude (thesis fig. 3.2)"
    )
    g.add_argument(
        "--rho", default="0.5,1,2,4", help="comma-separated rho values (default: 0.5,1,2,4)"
    )
    g.add_argument("--vehicle", default="nano")
    g.add_argument("--out", type=Path, default=DEFAULT_LOGS / "ground_effect.png")
    g.set_defaults(func=cmd_plot)


def cmd_plot(args: argparse.Namespace) -> int:
    from simbridge.plots import plot_ground_effect
    from simbridge.vehicle import load_vehicle

    rhos = []
    for part in args.rho.split(","):
        try:
            rho = float(part)
        except ValueError:
            raise ConfigError(
                f"--rho: expected numbers > 0 separated by commas, got {args.rho!r}"
            ) from None
        if not 0 < rho <= 50:
            raise ConfigError(f"--rho: each rho must be in (0, 50], got {part}")
        rhos.append(rho)
    out = plot_ground_effect(load_vehicle(args.vehicle), rhos, args.out)
    print(out)
    return 0
