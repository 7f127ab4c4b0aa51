"""What and where a flight records, and how often it flushes: shared by the recorder's
front (`autopilot.recording.recorder`) and its rerun writer
(`autopilot.recording.flight_recorder`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from simbridge.world import World

FLUSH_EVERY_S = 4.0  # simulated seconds between flushes, at most (what a SIGKILL may lose)
FLUSH_WALL_S = 0.5  # ... and wall seconds: when the simulator runs slower than 8x real time


@dataclass(frozen=True)
class RecordOptions:
    """Where and what to record: the file, and the world drawn in it (the autopilot does not
    know the simulator's world; the world file is passed for the picture only)."""

    path: Path
    world: World | None = None
    info: Mapping[str, Any] | None = None  # stored in the recording's meta (model, rho, ...)
    flush_every_s: float = FLUSH_EVERY_S
