"""Every option README.md and docs/ show on a `groundfx` command exists on that command."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from mission.cli.main import build_parser

REPO = Path(__file__).resolve().parents[1]
# the command reference is the parsers' own help (tests/test_docs.py holds it to them)
PAGES = [
    REPO / "README.md",
    *(p for p in sorted((REPO / "docs").glob("*.md")) if p.name != "cli.md"),
]


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _options(parser: argparse.ArgumentParser) -> set[str]:
    return {o for action in parser._actions for o in action.option_strings}


def _commands(text: str) -> list[str]:
    """`groundfx ...` as the pages write them: code spans, and lines of code blocks (a line
    ending in a backslash continues on the next)."""
    spans = re.findall(r"`(groundfx [^`]+)`", text)
    blocks = re.findall(r"```(?:sh|bash|console)?\n(.*?)```", text, flags=re.S)
    lines = [ln.strip() for b in blocks for ln in b.replace("\\\n", " ").splitlines()]
    return spans + [ln for ln in lines if ln.startswith("groundfx ")]


def _parsers(words: list[str]) -> list[argparse.ArgumentParser]:
    """The parsers a command's words name (`learn gather|train`: both)."""
    level = [build_parser()]
    for word in words:
        if word.startswith("-"):
            break
        nxt = []
        for parser in level:
            subs = _subcommands(parser)
            nxt += [subs[w] for w in word.split("|") if w in subs]
        if not nxt:
            break
        level = nxt
    return level


def test_every_option_the_pages_show_exists_on_its_command() -> None:
    commands = [c for page in PAGES for c in _commands(page.read_text())]
    assert len(commands) > 30  # the synopses and examples were found
    missing = []
    for command in commands:
        words = command.split()[1:]
        parsers = _parsers(words)
        shown = set(re.findall(r"(?<![\w-])--?[a-zA-Z][\w-]*", command))
        for option in shown:
            if not any(option in _options(p) for p in parsers):
                missing.append(f"{option} on `{command}`")
    assert not missing, "\n".join(missing)
