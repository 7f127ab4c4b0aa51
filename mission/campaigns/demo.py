"""`groundfx demo`: the demo flight with the analytic, the learned and no ground-effect model."""

from __future__ import annotations

from pathlib import Path

from mission import EXAMPLES_DIR
from mission.fly import describe, fly
from mission.recordings import default_recording_path
from simbridge.plots import plot_ground_effect
from simbridge.vehicle import load_vehicle
from simbridge.world import load_world

DEMO_MISSION = EXAMPLES_DIR / "demo.yaml"


def run_flight_demo(world: str, logs: Path, say=print) -> bool:
    say(
        f"groundfx demo: {DEMO_MISSION.name} on world {world!r}: take off to 1 m, fly a square, "
        "hover 3 cm above the ground, land"
    )
    landed = True
    for model in ("analytic", "neural", "none"):
        record = default_recording_path(DEMO_MISSION, model, logs)
        summary = fly(DEMO_MISSION, world=world, model=model, record=record)
        say(describe(summary))
        landed &= bool(summary["landed"])
    vehicle = load_vehicle(load_world(world).vehicle)
    png = plot_ground_effect(vehicle, [0.5, 1.0, 2.0, 4.0], logs / "ground_effect.png")
    say(f"ground effect against altitude for rho 0.5, 1, 2, 4: {png}")
    return landed
