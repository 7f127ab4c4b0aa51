"""`groundfx demo`: the demo flight with the analytic, the learned and no ground-effect model."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from mission import EXAMPLES_DIR
from mission.flight_report_page import write_report
from mission.fly import describe, fly
from mission.recordings import default_recording_path
from simbridge.plots import plot_ground_effect
from simbridge.vehicle import load_vehicle
from simbridge.world import load_world

DEMO_MISSION = EXAMPLES_DIR / "demo.yaml"
DEMO_MODELS = ("analytic", "neural", "none")


def fly_demo(
    world: str, logs: Path, say: Callable[[str], None] = print
) -> dict[str, dict[str, Any]]:
    """The demo mission once per model, each recorded into `logs`; the summaries by model.

    The autopilot starts the mission itself at a fixed simulated time: a ground station's
    messages arrive at wall-clock moments, and would move the flights by a few hundredths of
    a millimetre from run to run; so the demo's figures repeat to the digit."""
    summaries = {}
    for model in DEMO_MODELS:
        record = default_recording_path(DEMO_MISSION, model, logs)
        summary = fly(DEMO_MISSION, world=world, model=model, record=record, via_gcs=False)
        if Path(record).is_file():  # each flight on one page beside its recording
            summary["report"] = str(write_report(Path(record))[0])
        summaries[model] = summary
        say(describe(summary))
    return summaries


def _mm(value: float | None, digits: int = 2) -> str:
    return "n/a" if value is None else f"{value * 1000:.{digits}f}"


def demo_table(summaries: dict[str, dict[str, Any]]) -> str:
    """The three models side by side, then how to open each recording."""
    rows = [
        "| model | landing error (mm) | hold RMS (mm) | touchdown speed (m/s) | recording |",
        "|---|---|---|---|---|",
    ]
    for model, s in summaries.items():
        speed = s.get("touchdown_speed_m_s")
        rows.append(
            f"| {model} | {_mm(s.get('landing_error_m'))} | {_mm(s.get('hold_z_rms_error_m'))} "
            f"| {'n/a' if speed is None else f'{speed:.3f}'} | {s.get('recording') or 'none'} |"
        )
    recordings = [s["recording"] for s in summaries.values() if s.get("recording")]
    if recordings:
        rows += ["", "open a recording in the rerun viewer (--web on a headless machine):"]
        rows += [f"  groundfx review {path}" for path in recordings]
    reports = [s["report"] for s in summaries.values() if s.get("report")]
    if reports:
        rows += ["", "each flight on one page:", *(f"  {path}" for path in reports)]
    return "\n".join(rows)


def run_flight_demo(world: str, logs: Path, say: Callable[[str], None] = print) -> bool:
    say(
        f"groundfx demo: {DEMO_MISSION.name} on world {world!r}: take off to 1 m, fly a square, "
        "hover 3 cm above the ground, land"
    )
    summaries = fly_demo(world, logs, say)
    vehicle = load_vehicle(load_world(world).vehicle)
    png = plot_ground_effect(vehicle, [0.5, 1.0, 2.0, 4.0], logs / "ground_effect.png")
    say(f"ground effect against altitude for rho 0.5, 1, 2, 4: {png}")
    say("")
    say(demo_table(summaries))
    return all(bool(s["landed"]) for s in summaries.values())
