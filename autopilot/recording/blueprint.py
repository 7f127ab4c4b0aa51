"""The default layout of a flight recording in the rerun viewer: a reviewer's five questions,
each answered without a click, in reading order.

Top left, 1. did it land, where and how: the 3-D world seen from close to the landing point
(the drone standing on it fills a good part of the view), and under it the landing error and
touchdown speed in a sentence (with what the learner did). Top right, 2. how well did it hold
near the ground: z minus its setpoint in millimetres; 3. how good was the ground-effect model:
predicted minus true vertical force in millinewtons. Both are scaled to the hold near the
ground once the flight has ended (`autopilot.recording.review`): a take-off's error, a metre,
leaves the view instead of squashing the hold's millimetres into a line. Bottom left, 4. what
did the learner do: the flight's phase, flight mode and model in use as named states, the
loss and each update accepted or rejected with its reason (flights that learn). Bottom right,
5. the rotors: commanded minus measured (ESC telemetry) speed in rad/s, one view and one
colour per rotor (n0 to n3).

Two series on top of each other read as one; this layout shows their difference instead
(`learner.flightlogs.recording.DIFFERENCES`), and keeps the series themselves (z and its
setpoint, the true and predicted ground effect) one tab away, beside the event log.
"""

from __future__ import annotations

import rerun.blueprint as rrb
import rerun.blueprint.components as rrbc

from learner.flightlogs.recording import (
    EVENTS,
    LEARNER_UPDATES,
    MAVLINK,
    REVIEW,
    STATES,
    TIMELINE,
    WORLD,
)
from simbridge.frames import Vec3

# where the 3-D camera stands, from the landing point: half a metre away, so that a drone 17 cm
# across (rotor discs included) is plain to see as it touches down
EYE_OFFSET_M = (-0.35, -0.3, 0.25)
DEFAULT_Z_RANGE_M = (-0.05, 1.5)  # the z view's range until a mission gives its heights
# below the lowest and above the highest point of the mission: a view of a metre and a bit,
# so that at 250 px its tenths of a metre are labelled (the viewer labels powers of ten
# only, each at least 20 px apart)
Z_MARGIN_M = (0.05, 0.1)
HOLD_VIEW = "plots/height_error_mm"
MODEL_VIEW = "plots/model_error_mn"
ROTOR_VIEWS = tuple(f"plots/rotors/difference/{i}" for i in range(4))
Ranges = dict[str, tuple[float, float]]  # entity path -> its view's y range


def z_range_m(path_m: list[Vec3] | tuple[Vec3, ...]) -> tuple[float, float]:
    """The z view's range for a mission flown along `path_m` (the ground at 0 included)."""
    if not path_m:
        return DEFAULT_Z_RANGE_M
    zs = [p[2] for p in path_m]
    return (min(0.0, min(zs)) - Z_MARGIN_M[0], max(zs) + Z_MARGIN_M[1])


def _axis(y_range: tuple[float, float] | None) -> rrb.ScalarAxis | None:
    return None if y_range is None else rrb.ScalarAxis(range=y_range)


def _series(origin: str, name: str, ranges: Ranges) -> rrb.TimeSeriesView:
    """A view of one series: no legend (the view's name says what it is)."""
    return rrb.TimeSeriesView(
        origin=origin,
        name=name,
        axis_y=_axis(ranges.get(origin)),
        plot_legend=rrb.PlotLegend(visible=False),
    )


def _log(origin: str, name: str) -> rrb.TextLogView:
    return rrb.TextLogView(  # time, level and text: the entity path is always the origin
        origin=origin,
        name=name,
        columns=rrb.TextLogColumns(
            text_log_columns=[
                rrbc.TextLogColumn("entitypath", visible=False),
                rrbc.TextLogColumn("loglevel"),
                rrbc.TextLogColumn("body"),
            ]
        ),
    )


def _more(z_view_m: tuple[float, float], learning: bool, ranges: Ranges) -> rrb.Tabs:
    """The event log (the learner's updates first on flights that learn), the series whose
    differences the review shows, and the rest as tables."""
    updates = [rrb.TextLogView(origin=LEARNER_UPDATES, name="learner updates")] if learning else []
    return rrb.Tabs(
        *updates,
        _log(EVENTS, "events"),
        rrb.TimeSeriesView(
            origin="plots/z", name="z and its setpoint (m)", axis_y=rrb.ScalarAxis(range=z_view_m)
        ),
        rrb.TimeSeriesView(
            origin="plots/ground_effect/z",
            name="ground effect z (N)",
            axis_y=_axis(ranges.get("plots/ground_effect/z/true")),
        ),
        rrb.DataframeView(origin="plots/errors", name="controller errors"),
        rrb.DataframeView(origin=MAVLINK, name="MAVLink counters"),
    )


def default_blueprint(
    focus_m: Vec3 = (0.0, 0.0, 0.0),
    z_view_m: tuple[float, float] = DEFAULT_Z_RANGE_M,
    learning: bool = False,
    ranges: Ranges | None = None,
) -> rrb.Blueprint:
    ranges = ranges or {}
    eye = tuple(f + o for f, o in zip(focus_m, EYE_OFFSET_M, strict=True))
    landing = rrb.Vertical(
        rrb.Spatial3DView(
            origin=WORLD,
            name="the landing (3-D)",
            eye_controls=rrb.EyeControls3D(position=eye, look_target=focus_m, eye_up=(0, 0, 1)),
        ),
        rrb.TextDocumentView(origin=REVIEW, name="landing and learner"),
        row_shares=[4, 1],
    )
    hold_and_model = rrb.Vertical(
        _series(HOLD_VIEW, "near the ground: z - setpoint (mm)", ranges),
        _series(MODEL_VIEW, "ground-effect model: predicted - true, vertical (mN)", ranges),
    )
    states = rrb.StateTimelineView(origin=STATES, name="phase, flight mode and model")
    loss = [_series("plots/learner/log10_loss", "learner loss (log10)", ranges)] if learning else []
    learner = rrb.Vertical(
        states, rrb.Horizontal(*loss, _more(z_view_m, learning, ranges)), row_shares=[1, 1]
    )
    rotors = rrb.Horizontal(
        *(_series(p, f"n{i} cmd-ESC", ranges) for i, p in enumerate(ROTOR_VIEWS))
    )
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(landing, hold_and_model, column_shares=[1, 1]),
            rrb.Horizontal(learner, rotors, column_shares=[1, 1]),
            row_shares=[5, 4],
        ),
        # collapsed: its streams would take a fifth of the page; following: the time cursor
        # stays at the latest data as the file loads (the landing, at the end)
        rrb.TimePanel(timeline=TIMELINE, state="collapsed", play_state="following"),
        collapse_panels=True,
    )
