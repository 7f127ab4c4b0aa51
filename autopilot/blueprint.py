"""The default layout of a flight recording in the rerun viewer.

Left: the 3-D world (looking at the landing point) over the event log and the status plots.
Right, top to bottom: z against its setpoint, the true against the predicted ground effect
(z large, x and y beside each other), then rotor speeds and controller errors in tabs. A
newcomer sees the landing at a glance: the drone settling onto the ground in 3-D, z meeting
its setpoint, and the green (true) and orange (predicted) ground-effect curves rising together.
"""

from __future__ import annotations

import rerun.blueprint as rrb

from learner.flightlogs.recording import EVENTS, MAVLINK, TIMELINE, WORLD
from simbridge.frames import Vec3

EYE_OFFSET_M = (-1.6, -1.6, 1.0)  # where the 3-D camera stands, from the point it looks at


def default_blueprint(focus_m: Vec3 = (0.0, 0.0, 0.0)) -> rrb.Blueprint:
    eye = tuple(f + o for f, o in zip(focus_m, EYE_OFFSET_M, strict=True))
    world = rrb.Spatial3DView(
        origin=WORLD,
        name="world",
        eye_controls=rrb.EyeControls3D(position=eye, look_target=focus_m, eye_up=(0, 0, 1)),
    )
    status = rrb.Tabs(
        rrb.TextLogView(origin=EVENTS, name="events"),
        rrb.TimeSeriesView(origin="plots/mode", name="mode"),
        rrb.TimeSeriesView(origin=MAVLINK, name="MAVLink counters"),
        rrb.TimeSeriesView(origin="plots/learner", name="learner"),
    )
    z = rrb.TimeSeriesView(
        origin="plots", contents=["plots/z", "plots/height"], name="z and its setpoint (m)"
    )
    ge = rrb.Vertical(
        rrb.TimeSeriesView(origin="plots/ground_effect/z", name="ground effect z (N)"),
        rrb.Horizontal(
            rrb.TimeSeriesView(origin="plots/ground_effect/x", name="ground effect x (N)"),
            rrb.TimeSeriesView(origin="plots/ground_effect/y", name="ground effect y (N)"),
        ),
        row_shares=[2, 1],
    )
    control = rrb.Tabs(
        rrb.TimeSeriesView(origin="plots/rotors", name="rotor speeds (rad/s)"),
        rrb.TimeSeriesView(origin="plots/errors/position", name="position error (m)"),
        rrb.TimeSeriesView(origin="plots/errors/velocity", name="velocity error (m/s)"),
        rrb.TimeSeriesView(origin="plots/errors/attitude", name="attitude error (rad)"),
    )
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(world, status, row_shares=[3, 1]),
            rrb.Vertical(z, ge, control, row_shares=[2, 3, 2]),
            column_shares=[1, 1],
        ),
        rrb.TimePanel(timeline=TIMELINE),
        collapse_panels=True,
    )
