"""A flight request: what `groundfx fly`, the command line and the autopilot process agree on."""

from __future__ import annotations

DEFAULT_MAX_FLIGHT_S = 900.0  # a flight ends (exit code 3) after this many simulated seconds
