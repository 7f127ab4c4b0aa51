"""`groundfx bench sitl`: simulator and autopilot as separate processes over MAVLink."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from mission.fly import fly

BENCH_MISSION = Path(__file__).parent / "examples" / "low_hover.yaml"


def bench_sitl(world: str = "default") -> dict[str, Any]:
    """250 Hz control, 1000 Hz physics, ground effect on, the analytic model, lockstep."""
    summary = fly(BENCH_MISSION, world=world, model="analytic", speedup="max", via_gcs=False)
    keys = (
        "rtf",
        "controller_us_p50",
        "controller_us_p99",
        "sim_s",
        "wall_s",
        "steps",
        "hold_z_rms_error_m",
        "landing_error_m",
        "simulator",
    )
    return {"mission": str(BENCH_MISSION), **{k: summary.get(k) for k in keys}}
