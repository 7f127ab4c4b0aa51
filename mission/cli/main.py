"""The `groundfx` command line: one entry point, one subcommand per job; each family of
subcommands (its options and what it runs) is a module of `mission.cli`."""

from __future__ import annotations

import argparse
import importlib
import sys

from simbridge.config import ConfigError

# each command, in the order `groundfx --help` lists them: the module of `mission.cli` and
# the function that adds its parser
COMMANDS = {
    "sim": ("sim", "add_parser"),
    "bench": ("bench", "add_parser"),
    "autopilot": ("autopilot", "add_parser"),
    "fly": ("flight", "add_fly_parser"),
    "review": ("review", "add_review_parser"),
    "sitl": ("flight", "add_sitl_parser"),
    "mission": ("missions", "add_mission_parser"),
    "experiment": ("experiment", "add_experiment_parser"),
    "learn": ("learn", "add_parser"),
    "plot": ("plot", "add_parser"),
    "gap": ("gap", "add_parser"),
    "demo": ("flight", "add_demo_parser"),
    "figures": ("figures", "add_parser"),
}


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """Every command's parser, or only the `only` command's: a simulator or an autopilot
    process (two for each flight) then imports none of the other commands' modules."""
    parser = argparse.ArgumentParser(
        prog="groundfx",
        description="SITL autopilot for a nano quadrotor that learns the ground effect.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (module, adder) in COMMANDS.items():
        if only is None or name == only:
            getattr(importlib.import_module(f"mission.cli.{module}"), adder)(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    only = argv[0] if argv and argv[0] in COMMANDS else None
    args = build_parser(only).parse_args(argv)
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
