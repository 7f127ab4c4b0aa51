"""Missions and flying them as a ground station would; the command line (`mission.cli`) and
the campaigns (`mission.campaigns`) in sub-packages of their own."""

from pathlib import Path

EXAMPLES_DIR = Path(__file__).parent / "examples"  # the packaged example missions
