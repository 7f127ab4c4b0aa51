"""The flight recorder's writer: `FlightRecorder`, opened through `autopilot.recording.recorder`.

See `autopilot.recording.recorder` for what it records and how it keeps out of the loop's way, and
`learner.flightlogs.recording` for the layout.
"""

from __future__ import annotations

import json
import math
import threading
import time
import uuid
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import rerun as rr

from autopilot.commander.mission_items import PlanStep
from autopilot.control.controller import ControlOutput
from autopilot.recording.blueprint import DEFAULT_Z_RANGE_M, default_blueprint, z_range_m
from autopilot.recording.compact import compact_recording
from autopilot.recording.record_options import FLUSH_WALL_S, RecordOptions
from autopilot.recording.recorder_rows import RowSender, scalars_key
from autopilot.recording.review import review_text
from autopilot.recording.rrbatch import ColumnBatch
from autopilot.recording.scene import (
    log_drone,
    log_mission,
    log_world,
    mission_path,
)
from autopilot.recording.series_style import GE_COLORS, counter_style, series_style
from autopilot.types import FlightState, Setpoint, Step
from learner.flightlogs.recording import (
    APPLICATION_ID,
    COUNTERS,
    EVENTS,
    FLIGHT_MODE_STATE,
    GE_ARROW_M_PER_N,
    GE_PREDICTED_ARROW,
    GE_TRUE_ARROW,
    LAYOUT_VERSION,
    LEARNER_UPDATES,
    MAVLINK,
    META,
    MODEL_STATE,
    PHASE_STATE,
    REVIEW,
    SERIES,
    SUMMARY,
    TIMELINE,
)
from simbridge.frames import Vec3
from simbridge.rotors import Quad
from simbridge.vehicle import Vehicle

TRUTH = "DEBUG_VECT"
TRUTH_NAME = "GE_TRUE"
ESC = "ESC_TELEMETRY_1_TO_4"
NAN3 = (math.nan,) * 3
NAN4 = (math.nan,) * 4
NAN2 = (math.nan,) * 2

# the estimator's error against the simulator's truth, one series each
ESTIMATOR_ERRORS = ("position_error_m", "velocity_error_m_s", "attitude_error_deg")


def _duration(t_s: np.ndarray) -> rr.TimeColumn:
    # Whole nanoseconds, rounded: rerun would truncate t * 1e9 (0.012 s -> 11999999 ns).
    return rr.TimeColumn(TIMELINE, duration=np.rint(t_s * 1e9).astype("timedelta64[ns]"))


class FlightRecorder:
    def __init__(
        self,
        options: RecordOptions,
        vehicle: Vehicle,
        modes: Sequence[str],
    ) -> None:
        self.path = options.path
        self._vehicle = vehicle
        self._boxes = options.world.obstacles if options.world is not None else ()
        self._every_s = options.flush_every_s
        self._modes = list(modes)
        self._info = dict(options.info or {})
        self.path.parent.mkdir(parents=True, exist_ok=True)
        rec = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4())
        # looking at the origin until a mission tells where the landing is
        self._learning = self._info.get("online", "off") != "off"
        rec.save(self.path, default_blueprint=default_blueprint(learning=self._learning))
        rec.set_log_time_enabled(False)  # sim_time only: the same flight, the same data
        rec.send_recording_name(self.path.stem)
        self._rec = rec
        hold = self._modes.index("holding") if "holding" in self._modes else -1
        self._sender = RowSender(rec, float(hold))
        self._focus_m: Vec3 = (0.0, 0.0, 0.0)  # where the 3-D view looks: the landing point
        self._z_view_m = DEFAULT_Z_RANGE_M
        self._rows: list[tuple[float, ...]] = []
        self._events: list[tuple[float, str, str]] = []
        # the learner's reports: (time, loss, version, what became of the update, ground)
        self._learner: list[tuple[float, float, float, str, str]] = []
        self._model_state = ""
        self._learner_lock = threading.Lock()  # the online learner reports from its thread
        self._estimator: list[tuple[float, float, float, float]] = []
        self._ratios: dict[str, list[tuple[float, float]]] = {}
        self._counters: dict[str, tuple[Callable[[], Sequence[int]], ColumnBatch]] = {}
        self._counters_t = -math.inf  # simulated time of the last counters sample
        self._next_flush_s = -math.inf
        self._flush_deadline = -math.inf
        self._last_t = 0.0
        self._mode: str | None = None
        self._flight_mode = ""
        self._mode_index = -1.0
        self._armed = False
        self._started = False
        self._closed = False
        # What recording costs: time in step() (flushes included) on the loop's thread, and
        # the CPU time of rerun's threads (encoding, writing) beside it.
        self._step_s = 0.0
        self._steps = 0
        self._cpu0 = time.process_time() - time.thread_time()
        self._background_s = 0.0
        self._log_static()

    # -- the loop's calls -------------------------------------------------------------------

    def step(
        self,
        t_s: float,
        msgs: Step,
        state: FlightState,
        height_m: float,
        mode: str,
        armed: bool,
        setpoint: Setpoint | None,
        ge_n: Vec3,
        speeds_rad_s: Quad,
        output: ControlOutput | None,
        flight_mode: str = "",
    ) -> None:
        """One control step: what the autopilot saw, decided and sent, and the truth. `mode`
        is the flight's phase; `flight_mode` the mode a ground station sets (hold, mission,
        ...). Both are named states in the recording (`states/`) as they change."""
        t0 = time.perf_counter()
        if not self._started:
            self._start(t_s, state.position_m)
        if mode != self._mode:
            self._mode_changed(t_s, mode)
            self._state_changed(t_s, PHASE_STATE, mode)
        if flight_mode != self._flight_mode:
            self._flight_mode = flight_mode
            self._state_changed(t_s, FLIGHT_MODE_STATE, flight_mode)
        if armed != self._armed:
            self._armed = armed
            self._events.append((t_s, "INFO", "armed" if armed else "disarmed"))
        sensor = msgs.sensor
        truth = msgs.latest.get(TRUTH) if TRUTH in msgs.new else None
        true_ge = (
            (truth["x"], truth["y"], truth["z"])
            if truth is not None and truth["name"] == TRUTH_NAME
            else NAN3
        )
        actual = msgs.latest[ESC]["rpm"] if ESC in msgs.new else NAN4
        if setpoint is not None:
            sp, spv = setpoint.position_m, setpoint.velocity_m_s
        else:
            sp = spv = NAN3
        desired = (output.desired_roll_rad, output.desired_pitch_rad) if output else NAN2
        self._rows.append(  # in the order of recorder_rows.Row
            (
                t_s,
                *state.position_m,
                *state.velocity_m_s,
                *state.quaternion,
                *sp,
                *spv,
                height_m,
                self._mode_index,
                *ge_n,
                *speeds_rad_s,
                *true_ge,
                *actual,
                *desired,
                *state.angular_velocity_body_rad_s,
                # the accelerometer as sent (FRD); turned into the world frame at the flush
                *((sensor["xacc"], sensor["yacc"], sensor["zacc"]) if "xacc" in sensor else NAN3),
            )
        )
        self._last_t = t_s
        if t_s >= self._next_flush_s or t0 >= self._flush_deadline:
            self.flush()
        self._steps += 1
        self._step_s += time.perf_counter() - t0

    def event(self, text: str, level: str = "INFO", t_s: float | None = None) -> None:
        """A line in the event log (failsafes, link events, ...); level as rerun's TextLog:
        TRACE, DEBUG, INFO, WARN, ERROR, CRITICAL. At the last step's time by default."""
        self._events.append((self._last_t if t_s is None else t_s, level, text))

    def learner(
        self,
        t_s: float,
        loss: float | None = None,
        version: int | None = None,
        note: str = "",
        ground: str | None = None,
    ) -> None:
        """The online learner's loss, the weight-snapshot version now in use, what became of
        the update (`note`: "accepted", "rejected: <why>", ...) and the ground it models
        (composite) (thread-safe)."""
        with self._learner_lock:
            self._learner.append(
                (
                    t_s,
                    math.nan if loss is None else loss,
                    math.nan if version is None else float(version),
                    note,
                    ground or "",
                )
            )

    def estimator(self, t_s: float, errors: Sequence[float], test_ratios: dict[str, float]) -> None:
        """The estimator against the truth (autopilot.nav_metrics.estimation_error: position
        x y z, velocity x y z, attitude angle) and the innovation test ratios of the
        measurements fused at this step, by source."""
        e = errors
        self._estimator.append(
            (
                t_s,
                math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]),
                math.sqrt(e[3] * e[3] + e[4] * e[4] + e[5] * e[5]),
                math.degrees(e[6]),
            )
        )
        for source, ratio in test_ratios.items():
            self._ratios.setdefault(source, []).append((t_s, ratio))

    def watch_counters(self, link: str, read: Callable[[], Sequence[int]]) -> None:
        """Record `read()` = (received, dropped, rejected) of a MAVLink link at every flush."""
        path = f"{MAVLINK}/{link}"
        batch = ColumnBatch(TIMELINE)
        batch.add(path, rr.Scalars.columns(scalars=np.zeros((1, len(COUNTERS)))))
        self._counters[link] = (read, batch)
        names, colors = counter_style(link)
        self._rec.log(path, rr.SeriesLines(names=names, colors=colors), static=True)

    def close(self, ended: str, summary: dict[str, Any] | None = None) -> None:
        """Flush everything, note how the flight ended (and its summary, as `groundfx fly
        --json` prints it), and finish the file (with its footer)."""
        if self._closed:
            return
        self._closed = True
        if summary is not None:
            text = json.dumps(summary, indent=1, default=str)
            self._rec.log(SUMMARY, rr.TextDocument(text, media_type="text/plain"), static=True)
        review = review_text(summary, self._info, ended)
        self._rec.log(REVIEW, rr.TextDocument(review, media_type="text/markdown"), static=True)
        level = "INFO" if ended == "landed" else "WARN"
        self._events.append((self._last_t, level, f"flight ended: {ended}"))
        self.flush()
        self._rec.flush()
        self._rec.disconnect()  # closes the file sink: writes the footer
        self._background_s = time.process_time() - time.thread_time() - self._cpu0
        # the file again in large chunks, with the layout's review views scaled to the flight
        ranges = self._sender.spread.ranges()
        blueprint = default_blueprint(self._focus_m, self._z_view_m, self._learning, ranges)
        compact_recording(self.path, blueprint)

    def stats(self) -> dict[str, float]:
        """Recording's cost per control step, in microseconds: in the loop (`step`, flushes
        included) and on rerun's threads (CPU time; they run beside the loop)."""
        steps = max(self._steps, 1)
        return {
            "recorder_us_per_step": self._step_s / steps * 1e6,
            "recorder_background_us_per_step": self._background_s / steps * 1e6,
        }

    # -- flushing ---------------------------------------------------------------------------

    def flush(self) -> None:
        """Send the buffered rows, events, learner reports and counters to rerun."""
        rows, self._rows = self._rows, []
        if rows:
            self._sender.send(np.asarray(rows, dtype=float))
        if self._events:
            events, self._events = self._events, []
            self._send(
                EVENTS,
                np.array([e[0] for e in events]),
                rr.TextLog.columns(text=[e[2] for e in events], level=[e[1] for e in events]),
            )
        with self._learner_lock:
            learned, self._learner = self._learner, []
        if learned:
            self._send_learner_notes(learned)
            a = np.asarray([row[:3] for row in learned], dtype=float)
            for col, path in ((1, "plots/learner/loss"), (2, "plots/learner/version")):
                keep = ~np.isnan(a[:, col])
                if keep.any():
                    self._scalars(path, a[keep, 0], a[keep, col])
            # rerun's axes are linear: a loss spanning decades reads as zero but for its peaks
            keep = a[:, 1] > 0.0
            if keep.any():
                log10_loss = np.log10(a[keep, 1])
                self._scalars("plots/learner/log10_loss", a[keep, 0], log10_loss)
                self._sender.spread.add("plots/learner/log10_loss", log10_loss)
        if self._estimator:
            a, self._estimator = np.asarray(self._estimator, dtype=float), []
            for col, name in enumerate(ESTIMATOR_ERRORS, start=1):
                self._scalars(f"plots/estimator/{name}", a[:, 0], a[:, col])
        ratios, self._ratios = self._ratios, {}
        for source, points in ratios.items():
            a = np.asarray(points, dtype=float)
            self._scalars(
                f"plots/estimator/test_ratio/{source.replace(' ', '_')}", a[:, 0], a[:, 1]
            )
        # once per simulated instant: a wall-clock flush and the closing one can fall on the
        # same step (a loaded machine), and the links' counters change only with a step
        if self._last_t > self._counters_t:
            self._counters_t = self._last_t
            now_ns = np.array([round(self._last_t * 1e9)], dtype=np.int64)
            for link, (read, batch) in self._counters.items():
                counts = np.asarray([read()], dtype=float)
                batch.send(self._rec, now_ns, {scalars_key(f"{MAVLINK}/{link}"): counts})
        self._next_flush_s = self._last_t + self._every_s
        self._flush_deadline = time.perf_counter() + FLUSH_WALL_S

    def _send_learner_notes(self, learned: list[tuple[float, float, float, str, str]]) -> None:
        """Each update's fate in the learner's log (with its loss and the weights then in
        use); the model in use as a named state: the offline weights, adapted (to which
        ground, for `composite`), or reset."""
        notes = [
            (t, note + ("" if math.isnan(loss) else f" (loss {loss:.3g}, weights v{version:.0f})"))
            for t, loss, version, note, _ in learned
            if note
        ]
        if notes:
            self._send(
                LEARNER_UPDATES,
                np.array([t for t, _ in notes]),
                rr.TextLog.columns(
                    text=[n for _, n in notes],
                    level=["INFO" if n.startswith("accepted") else "WARN" for _, n in notes],
                ),
            )
        model = str(self._info.get("model") or "model")
        for t, _, version, note, ground in learned:
            if math.isnan(version):
                continue
            if not self._learning:
                state = model
            elif version == 0 or note == "reset":
                state = f"{model}, offline weights" + (" (reset)" if note == "reset" else "")
            else:
                state = f"{model}, adapted online" + (f" to ground {ground}" if ground else "")
            if state != self._model_state:
                self._model_state = state
                self._state_changed(t, MODEL_STATE, state)

    def _send(self, path: str, t_s: np.ndarray, columns: Any) -> None:
        rr.send_columns(path, indexes=[_duration(t_s)], columns=columns, recording=self._rec)

    def _scalars(self, path: str, t_s: np.ndarray, values: np.ndarray) -> None:
        self._send(path, t_s, rr.Scalars.columns(scalars=values))

    # -- the static part and the start ------------------------------------------------------

    def _log_static(self) -> None:
        rec = self._rec
        log_world(rec, self._boxes, [])
        log_drone(rec, self._vehicle)
        for path in SERIES:
            names, colors = series_style(path, self._modes)
            rec.log(path, rr.SeriesLines(names=names, colors=colors), static=True)
        for path, color in ((GE_TRUE_ARROW, "true"), (GE_PREDICTED_ARROW, "predicted")):
            rec.log(path, rr.Arrows3D.from_fields(colors=[GE_COLORS[color]]), static=True)
        self._log_meta()

    def _log_meta(self) -> None:
        meta = {
            "layout_version": LAYOUT_VERSION,
            "modes": self._modes,
            "vehicle": self._vehicle.name,
            "ge_arrow_m_per_n": GE_ARROW_M_PER_N,
            "flush_every_s": self._every_s,
            **self._info,
        }
        self._rec.log(
            META, rr.TextDocument(json.dumps(meta, indent=1), media_type="text/plain"), static=True
        )

    def _start(self, t_s: float, position_m: Vec3) -> None:
        self._started = True
        self.learner(t_s, version=0)  # the offline weights until an online update replaces them

    def mission(
        self, plan: Sequence[PlanStep], start_m: Vec3, home_m: Vec3 | None, t_s: float
    ) -> None:
        """Draw the mission from where the vehicle is (a new upload replaces the drawing from
        `t_s` on), widen the ground under it and look at where it lands."""
        points, labels, path = mission_path(plan, start_m, home_m, self._boxes)
        log_world(self._rec, self._boxes, path)
        self._rec.set_time(TIMELINE, duration=np.timedelta64(round(t_s * 1e9), "ns"))
        log_mission(self._rec, points, labels, path)
        if points:
            self._focus_m, self._z_view_m = path[-1], z_range_m(path)
            self._send_blueprint()

    def _send_blueprint(self) -> None:
        """The default layout, looking at the landing point (until the flight's end scales
        its review views: `close`)."""
        blueprint = default_blueprint(self._focus_m, self._z_view_m, self._learning)
        self._rec.send_blueprint(blueprint, make_active=False)

    def _state_changed(self, t_s: float, path: str, state: str) -> None:
        self._rec.set_time(TIMELINE, duration=np.timedelta64(round(t_s * 1e9), "ns"))
        self._rec.log(path, rr.StateChange(state=state))

    def _mode_changed(self, t_s: float, mode: str) -> None:
        if mode not in self._modes:  # a mode the caller did not announce: name it in the meta
            self._modes.append(mode)
            self._log_meta()
            names, colors = series_style("plots/mode", self._modes)
            self._rec.log("plots/mode", rr.SeriesLines(names=names, colors=colors), static=True)
        self._events.append((t_s, "INFO", f"mode {mode}" if self._mode else f"mode {mode} (start)"))
        self._mode = mode
        self._mode_index = float(self._modes.index(mode))
