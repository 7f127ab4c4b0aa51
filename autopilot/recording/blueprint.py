"""The default layout of a flight recording in the rerun viewer.

Left: the 3-D world (looking down at the landing point from above the mission) over the
event log and the status plots. Right, top to bottom: z against its setpoint, the true
against the predicted ground effect (z large, x and y beside each other), then rotor speeds
and controller errors in tabs. A newcomer sees the landing at a glance: the drone settling
onto the ground in 3-D, z meeting its setpoint, and the green (true) and orange (predicted)
ground-effect curves rising together. The z view's range is fixed to the mission's heights,
so a setpoint that runs away cannot squeeze the hold near the ground into a line; the
learner's views appear only on flights that learn.
"""

from __future__ import annotations

import rerun.blueprint as rrb
import rerun.blueprint.components as rrbc

from learner.flightlogs.recording import EVENTS, MAVLINK, STATES, TIMELINE, WORLD
from simbridge.frames import Vec3

EYE_OFFSET_M = (-1.6, -1.6, 2.7)  # where the 3-D camera stands, from the point it looks at
DEFAULT_Z_RANGE_M = (-0.05, 1.5)  # the z view's range until a mission gives its heights
Z_MARGIN_M = (0.05, 0.25)
NEAR_GROUND_RANGE_M = (-0.005, 0.1)  # below the lowest and above the highest point of the mission


def z_range_m(path_m: list[Vec3] | tuple[Vec3, ...]) -> tuple[float, float]:
    """The z view's range for a mission flown along `path_m` (the ground at 0 included)."""
    if not path_m:
        return DEFAULT_Z_RANGE_M
    zs = [p[2] for p in path_m]
    return (min(0.0, min(zs)) - Z_MARGIN_M[0], max(zs) + Z_MARGIN_M[1])


def default_blueprint(
    focus_m: Vec3 = (0.0, 0.0, 0.0),
    z_view_m: tuple[float, float] = DEFAULT_Z_RANGE_M,
    learning: bool = False,
) -> rrb.Blueprint:
    eye = tuple(f + o for f, o in zip(focus_m, EYE_OFFSET_M, strict=True))
    world = rrb.Spatial3DView(
        origin=WORLD,
        name="world",
        eye_controls=rrb.EyeControls3D(position=eye, look_target=focus_m, eye_up=(0, 0, 1)),
    )
    learner = (
        [
            rrb.Vertical(
                rrb.TimeSeriesView(origin="plots/learner/log10_loss", name="learner loss (log10)"),
                rrb.TimeSeriesView(origin="plots/learner/version", name="weights version"),
                name="learner",
            )
        ]
        if learning
        else []
    )
    status = rrb.Tabs(
        rrb.TextLogView(  # time, level and text: the entity path is always `events`
            origin=EVENTS,
            name="events",
            columns=rrb.TextLogColumns(
                text_log_columns=[
                    rrbc.TextLogColumn("entitypath", visible=False),
                    rrbc.TextLogColumn("loglevel"),
                    rrbc.TextLogColumn("body"),
                ]
            ),
        ),
        rrb.StateTimelineView(origin=STATES, name="flight mode and phase"),
        rrb.TimeSeriesView(origin=f"{MAVLINK}/sim", name="MAVLink: simulator link"),
        rrb.TimeSeriesView(origin=f"{MAVLINK}/gcs", name="MAVLink: ground stations"),
        *learner,
    )
    z = rrb.Tabs(
        rrb.TimeSeriesView(
            origin="plots",
            contents=["plots/z", "plots/height"],
            name="z and its setpoint (m)",
            axis_y=rrb.ScalarAxis(range=z_view_m),
        ),
        rrb.TimeSeriesView(  # the hold and the touchdown, to the millimetre
            origin="plots",
            contents=["plots/z", "plots/height"],
            name="near the ground (m, lowest 10 cm)",
            axis_y=rrb.ScalarAxis(range=NEAR_GROUND_RANGE_M),
        ),
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
