"""The packaged column mappings: where they are and their names (light: the command line
lists them in its help)."""

from __future__ import annotations

from pathlib import Path

MAPPINGS_DIR = Path(__file__).parent / "mappings"


def packaged_mappings() -> list[str]:
    """The names of the packaged column mappings (`--columns NAME`)."""
    return sorted(p.stem for p in MAPPINGS_DIR.glob("*.yaml"))
