"""`groundfx bench sitl`: simulator and autopilot as separate processes over MAVLink, beside
a reference measured in the same run (a pymavlink ping-pong of the same messages)."""

from __future__ import annotations

import os
import statistics
import tempfile
from pathlib import Path
from typing import Any

from mission import EXAMPLES_DIR
from mission.fly import fly
from simbridge.bench import pingpong_rtf, wake_latency
from simbridge.vehicle import load_vehicle
from simbridge.world import load_world, resolve_world_path

BENCH_MISSION = EXAMPLES_DIR / "low_hover.yaml"


def bench_sitl(world: str = "default", repeat: int = 5) -> dict[str, Any]:
    """250 Hz control, 1000 Hz physics, ground effect on, the analytic model, lockstep.

    Flies the mission `repeat` times with the recorder off and on, alternating (the load of
    the machine drifts); `rtf` and the rest are the median flight with recording off;
    `recording_rtf_ratio` the median over the pairs of rtf on / rtf off. Between the pairs,
    the reference: `simbridge.pingpong` (pymavlink, the same messages, no physics, no
    autopilot) for as many simulated seconds, against the benchmark's minimal client."""
    off: list[dict[str, Any]] = []
    on: list[dict[str, Any]] = []
    reference: list[float] = []
    world_obj = load_world(world)
    vehicle = load_vehicle(world_obj.vehicle)
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(repeat):
            ping = pingpong_rtf(str(resolve_world_path(world)), world_obj, vehicle, 16.0)
            reference.append(ping["pingpong_rtf"])
            off.append(
                fly(BENCH_MISSION, world, "analytic", speedup="max", via_gcs=False, record=False)
            )
            path = Path(tmp) / f"bench-{i}.rrd"
            on.append(
                fly(BENCH_MISSION, world, "analytic", speedup="max", via_gcs=False, record=path)
            )
            on[-1]["recording_bytes"] = path.stat().st_size
    keys = (
        "rtf",
        "controller_us_p50",
        "controller_us_p99",
        "estimator_controller_us_p50",
        "estimator_controller_us_p99",
        "estimator_correction_us_p50",
        "estimator_correction_us_p99",
        "sim_s",
        "wall_s",
        "steps",
        "hold_z_rms_error_m",
        "landing_error_m",
        "simulator",
    )
    median = sorted(off, key=lambda s: s["rtf"])[len(off) // 2]
    rtf_off = statistics.median(s["rtf"] for s in off)
    rtf_on = statistics.median(s["rtf"] for s in on)
    wall_per_step_off = statistics.median(s["wall_s"] / s["steps"] for s in off)
    wall_per_step_on = statistics.median(s["wall_s"] / s["steps"] for s in on)
    return {
        "mission": str(BENCH_MISSION),
        **{k: median.get(k) for k in keys},
        "repeat": repeat,
        "rtf_recording_off": rtf_off,
        "rtf_recording_on": rtf_on,
        # each flight with recording on against the one just before it without: the load of
        # a shared machine drifts less between neighbours than over the whole benchmark
        "recording_rtf_ratio": statistics.median(
            b["rtf"] / a["rtf"] for a, b in zip(off, on, strict=True)
        ),
        "recording_us_per_step": (wall_per_step_on - wall_per_step_off) * 1e6,
        "recording_bytes": int(statistics.median(s["recording_bytes"] for s in on)),
        "recorder_us_per_step": statistics.median(s["recorder_us_per_step"] for s in on),
        "recorder_background_us_per_step": statistics.median(
            s["recorder_background_us_per_step"] for s in on
        ),
        "rtf_runs_off": [s["rtf"] for s in off],
        "rtf_runs_on": [s["rtf"] for s in on],
        "pingpong_rtf": statistics.median(reference),
        # the flights and the reference alike (simbridge/cpu_latency.py)
        "cpu_wake_latency": wake_latency(median.get("simulator") or ""),
        "recording_on_to_pingpong": rtf_on / statistics.median(reference),
        "load_average": (load_before, os.getloadavg()[0]),
    }
