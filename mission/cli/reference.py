"""docs/cli.md, the command reference: every command's `--help`, generated from the parsers.

`python -m mission.cli.reference docs/cli.md` writes it (`groundfx figures` runs this)."""

from __future__ import annotations

import argparse
import functools
import sys
from pathlib import Path

from mission.cli.main import build_parser

# a fixed width, so that the page does not depend on the terminal it was made in
HELP_WIDTH = 100


def _parsers(
    parser: argparse.ArgumentParser, words: tuple[str, ...] = ()
) -> list[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """Every parser below this one, depth first, with the words that reach it."""
    found = [(words, parser)]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, child in action.choices.items():
                found += _parsers(child, (*words, name))
    return found


def cli_reference() -> str:
    parts = [
        "# Command reference",
        "",
        "Every `groundfx` command's `--help`, generated from the parsers by `groundfx figures`",
        "(a test checks that it is current).",
    ]
    for words, parser in _parsers(build_parser()):
        parser.formatter_class = functools.partial(parser.formatter_class, width=HELP_WIDTH)
        parts += ["", f"## `{' '.join(('groundfx', *words))}`", "", "```text"]
        parts += [parser.format_help().rstrip(), "```"]
    return "\n".join(parts) + "\n"


if __name__ == "__main__":
    Path(sys.argv[1]).write_text(cli_reference())
