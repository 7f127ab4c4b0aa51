"""The `groundfx` command line: one entry point, one subcommand per job; each family of
subcommands (its options and what it runs) is a module of `mission.cli`."""

from __future__ import annotations

import argparse
import sys

from mission.cli import (
    autopilot,
    bench,
    experiment,
    figures,
    flight,
    gap,
    learn,
    missions,
    plot,
    review,
)
from mission.cli import sim as sim_cli
from simbridge.config import ConfigError


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="groundfx",
        description="SITL autopilot for a nano quadrotor that learns the ground effect.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    sim_cli.add_parser(sub)
    bench.add_parser(sub)
    autopilot.add_parser(sub)
    flight.add_fly_parser(sub)
    review.add_review_parser(sub)
    flight.add_sitl_parser(sub)
    missions.add_mission_parser(sub)
    experiment.add_experiment_parser(sub)
    learn.add_parser(sub)
    plot.add_parser(sub)
    gap.add_parser(sub)
    flight.add_demo_parser(sub)
    figures.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ConfigError as err:
        print(f"groundfx {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"groundfx {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
