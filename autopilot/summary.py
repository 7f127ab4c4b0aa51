"""What a flight leaves behind: its trace (rows, timings, errors, samples) as the loop
collects it, and the summary's figures computed from it after the loop."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from autopilot.commander.commander import CommanderState, Phase
from autopilot.metrics import (
    COLUMNS,
    flight_metrics,
    ge_error_metrics,
    near_ground_hold,
    trajectory_sha256,
)
from autopilot.nav_metrics import estimator_metrics

MODES = [p.value for p in Phase]
# What a run that outlives its flights (`sitl`) keeps of its steps on the ground: 10 s at 250 Hz
IDLE_ROWS_KEPT = 2500


@dataclass
class FlightTrace:
    """What the loop collects, step by step, for the figures after it."""

    rows: list[tuple[float, ...]] = field(default_factory=list)  # metrics.COLUMNS
    timings: list[float] = field(default_factory=list)  # controller and ground-effect model
    step_timings: list[float] = field(default_factory=list)  # with the estimator's prediction
    correction_timings: list[float] = field(default_factory=list)  # the estimator's fusions
    # (t, h, predicted, true): the ground-effect model's vertical force against the truth
    ge_pairs: list[tuple[float, float, float, float]] = field(default_factory=list)
    nav_errors: list[tuple[float, ...]] = field(default_factory=list)  # in the air
    samples: list[tuple[float, ...]] = field(default_factory=list)  # learner.dataset.COLUMNS
    failsafes: list[str] = field(default_factory=list)
    flights: list[dict[str, Any]] = field(default_factory=list)  # a long run's, each landed one's

    def flew(self) -> bool:
        """The controller ran since the trace began: the rotors were on."""
        return bool(self.timings)

    def close_flight(self, figures: dict[str, Any]) -> None:
        """A long run's flight is over: its figures are kept, its steps let go, so that a
        `sitl` flying for hours stays the size it was."""
        self.flights.append({**figures, "failsafes": list(self.failsafes)})
        for steps in (
            self.rows, self.timings, self.step_timings, self.correction_timings, self.ge_pairs,
            self.nav_errors, self.failsafes,
        ):  # fmt: skip
            steps.clear()

    def trim_idle(self) -> None:
        """On the ground between flights: only the last IDLE_ROWS_KEPT steps (amortised)."""
        for steps in (self.rows, self.correction_timings):
            if len(steps) > 2 * IDLE_ROWS_KEPT:
                del steps[:-IDLE_ROWS_KEPT]


def landing_target_xy(cmd: CommanderState) -> tuple[float, float] | None:
    """Where the mission meant to land: its landing item's position, else the last waypoint
    flown before it, else home (a return)."""
    last = None
    for step in cmd.plan:
        if step.kind == "land":
            return step.position_m[:2] if step.position_m is not None else last
        if step.kind == "return":
            return cmd.home_m[:2] if cmd.home_m is not None else last
        if step.position_m is not None:
            last = step.position_m[:2]
    return None


def _percentiles(prefix: str, seconds: list[float]) -> dict[str, float]:
    if not seconds:
        return {}
    us = np.asarray(seconds) * 1e6
    return {
        f"{prefix}_us_p50": float(np.percentile(us, 50)),
        f"{prefix}_us_p99": float(np.percentile(us, 99)),
    }


def trace_log(trace: FlightTrace) -> np.ndarray:
    """The trajectory, one row per step with metrics.COLUMNS."""
    return np.asarray(trace.rows, dtype=float).reshape(-1, len(COLUMNS))


def flight_figures(
    trace: FlightTrace,
    log: np.ndarray,
    cmd: CommanderState,
    resting_height_m: float,
    wall_s: float,
    nav: Any,
) -> dict[str, Any]:
    """The flight's figures: landing, holds, touchdown, estimator and ground-effect errors,
    the loop's speed and timings. `nav`: the estimator, for its height source."""
    summary: dict[str, Any] = {}
    if len(log):
        summary.update(flight_metrics(log, MODES, landing_target_xy(cmd), resting_height_m))
        sim_s = float(log[-1, 0] - log[0, 0])
        summary.update(
            sim_s=sim_s,
            wall_s=wall_s,
            rtf=sim_s / wall_s if wall_s > 0 else 0.0,
            steps=len(log),
            trajectory_sha256=trajectory_sha256(log),
        )
    summary.update(estimator_metrics(np.asarray(trace.nav_errors).reshape(-1, 7), nav))
    hold_times_s = log[near_ground_hold(log, MODES), 0] if len(log) else np.zeros(0)
    pairs = np.asarray(trace.ge_pairs, dtype=float).reshape(-1, 4)
    summary.update(ge_error_metrics(pairs, hold_times_s))
    summary.update(_percentiles("controller", trace.timings))
    summary.update(_percentiles("estimator_controller", trace.step_timings))
    summary.update(_percentiles("estimator_correction", trace.correction_timings))
    return summary
