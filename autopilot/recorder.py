"""The flight recorder: every flight as one rerun recording, written by the autopilot.

The simulator's truth reaches the autopilot over MAVLink (the true state in
HIL_STATE_QUATERNION, the true ground-effect force in DEBUG_VECT "GE_TRUE", the actual rotor
speeds in ESC telemetry), so the autopilot alone writes truth and its own view side by side:
one process, one file, one recording id. The layout is `autopilot.recording`'s.

The loop must not wait for it. `step` appends one tuple per control step; every
`flush_every_s` of simulated time (or FLUSH_WALL_S of wall time, if that comes first) the
rows become numpy columns and leave as a few Arrow record batches (`autopilot.rrbatch`: one
per set of entities sharing their times, not one call per entity); rerun encodes and writes
them on its own thread. A SIGKILL loses at most the rows since the last flush (and the
footer: the reader copes).
"""

from __future__ import annotations

import json
import math
import threading
import time
import uuid
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import rerun as rr

from autopilot.blueprint import default_blueprint
from autopilot.commander import Mission
from autopilot.controller import ControlOutput, FlightState, Setpoint
from autopilot.navigator import Waypoint
from autopilot.recording import (
    APPLICATION_ID,
    COUNTERS,
    DRONE,
    EVENTS,
    GE_ARROW_M_PER_N,
    GE_PREDICTED_ARROW,
    GE_TRUE_ARROW,
    LAYOUT_VERSION,
    MAVLINK,
    META,
    SERIES,
    TIMELINE,
    TRAJECTORY,
)
from autopilot.rrbatch import ColumnBatch
from autopilot.scene import (
    log_drone,
    log_mission,
    log_world,
    mission_path,
    surface_height_m,
)
from autopilot.simlink import Step
from simbridge.frames import Vec3
from simbridge.hil import RAD_S_TO_RPM
from simbridge.rotors import Quad
from simbridge.vehicle import Vehicle
from simbridge.world import World

TRUTH = "DEBUG_VECT"
TRUTH_NAME = "GE_TRUE"
ESC = "ESC_TELEMETRY_1_TO_4"
FLUSH_EVERY_S = 2.0  # simulated seconds between flushes, at most (what a SIGKILL may lose)
FLUSH_WALL_S = 0.5  # ... and wall seconds: when the simulator runs slower than 4x real time
SCENE_PERIOD_S = 0.02  # the 3-D scene at 50 Hz
TRAIL_SPACING_M = 0.01  # a trail point every centimetre flown
TRAIL_PERIOD_S = 0.25  # the trail is redrawn this often (simulated seconds)
TRAIL_SEGMENT_S = 10.0  # the trail's pieces: world/trajectory/0 covers 0-10 s, and so on
NAN3 = (math.nan,) * 3
NAN4 = (math.nan,) * 4
NAN2 = (math.nan,) * 2

# Columns of a step row (one tuple per control step).
T, P, V, Q, SP, SPV, H, MODE, GE, N, TRUE, ACT, DES = (
    0, 1, 4, 7, 11, 14, 17, 18, 19, 22, 26, 29, 33,
)  # fmt: skip
ROW_WIDTH = 35
STEP_SERIES = tuple(
    p
    for p in SERIES
    if not p.startswith("plots/learner/") and not p.endswith("/true") and p != "plots/rotors/actual"
)

GE_COLORS = {"true": (40, 180, 80), "predicted": (255, 140, 0)}
TRAIL_RGBA = 0xFFFFFFFF  # white, opaque (rerun packs colours as 0xRRGGBBAA)
ROTOR_COLORS = ((220, 60, 60), (60, 120, 220), (60, 180, 90), (230, 170, 40))


class Recorder(Protocol):
    """What the flight loop calls; `NullRecorder` when recording is off."""

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
    ) -> None: ...
    def event(self, text: str, level: str = "INFO", t_s: float | None = None) -> None: ...
    def learner(
        self, t_s: float, loss: float | None = None, version: int | None = None
    ) -> None: ...
    def watch_counters(self, link: str, read: Callable[[], Sequence[int]]) -> None: ...
    def close(self, ended: str) -> None: ...
    def stats(self) -> dict[str, float]: ...


@dataclass(frozen=True)
class RecordOptions:
    """Where and what to record: the file, and the world drawn in it (the autopilot does not
    know the simulator's world; the world file is passed for the picture only)."""

    path: Path
    world: World | None = None
    info: Mapping[str, Any] | None = None  # stored in the recording's meta (model, rho, ...)
    flush_every_s: float = FLUSH_EVERY_S


class NullRecorder:
    """Recording off."""

    def step(self, *args: object) -> None:
        pass

    def event(self, text: str, level: str = "INFO", t_s: float | None = None) -> None:
        pass

    def learner(self, t_s: float, loss: float | None = None, version: int | None = None) -> None:
        pass

    def watch_counters(self, link: str, read: Callable[[], Sequence[int]]) -> None:
        pass

    def close(self, ended: str) -> None:
        pass

    def stats(self) -> dict[str, float]:
        return {}


def open_recorder(
    options: RecordOptions | None,
    vehicle: Vehicle,
    mission: Mission,
    takeoff_altitude_m: float,
    modes: Sequence[str],
) -> Recorder:
    if options is None:
        return NullRecorder()
    return FlightRecorder(options, vehicle, mission, takeoff_altitude_m, modes)


def _s(path: str) -> str:
    """The key of a time series' values in a ColumnBatch."""
    return f"{path}:Scalars:scalars"


def _column_batches() -> tuple[ColumnBatch, ColumnBatch, ColumnBatch, ColumnBatch]:
    """What every control step logs; the true ground effect (when GE_TRUE arrives); the
    actual rotor speeds (when ESC telemetry arrives); the 3-D scene (at SCENE_PERIOD_S)."""

    def scalars(width: int) -> Any:
        return rr.Scalars.columns(scalars=np.zeros((1, width)))

    step = ColumnBatch(TIMELINE)
    for path in STEP_SERIES:
        step.add(path, scalars(len(SERIES[path])))
    truth = ColumnBatch(TIMELINE)
    for axis in "xyz":
        truth.add(f"plots/ground_effect/{axis}/true", scalars(1))
    esc = ColumnBatch(TIMELINE)
    esc.add("plots/rotors/actual", scalars(4))
    scene = ColumnBatch(TIMELINE)
    pose = rr.Transform3D.columns(translation=np.zeros((1, 3)), quaternion=[[0.0, 0.0, 0.0, 1.0]])
    scene.add(DRONE, pose)
    for path in (GE_PREDICTED_ARROW, GE_TRUE_ARROW):
        scene.add(path, rr.Arrows3D.columns(origins=np.zeros((1, 3)), vectors=np.zeros((1, 3))))
    return step, truth, esc, scene


def _firsts(t_s: np.ndarray, last_s: float, period_s: float) -> np.ndarray:
    """The rows that open a new period (multiples of `period_s`) after time `last_s`."""
    before = np.concatenate(([last_s], t_s[:-1]))
    return np.floor(t_s / period_s) > np.floor(before / period_s)


def _duration(t_s: np.ndarray) -> rr.TimeColumn:
    # Whole nanoseconds, rounded: rerun would truncate t * 1e9 (0.012 s -> 11999999 ns).
    return rr.TimeColumn(TIMELINE, duration=np.rint(t_s * 1e9).astype("timedelta64[ns]"))


class FlightRecorder:
    def __init__(
        self,
        options: RecordOptions,
        vehicle: Vehicle,
        mission: Mission,
        takeoff_altitude_m: float,
        modes: Sequence[str],
    ) -> None:
        self.path = options.path
        self._vehicle = vehicle
        self._mission = mission
        self._takeoff_altitude_m = takeoff_altitude_m
        self._boxes = options.world.obstacles if options.world is not None else ()
        self._every_s = options.flush_every_s
        self._modes = list(modes)
        self._info = dict(options.info or {})
        self.path.parent.mkdir(parents=True, exist_ok=True)
        rec = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4())
        last = mission.waypoints[-1].position_m
        focus = (last[0], last[1], surface_height_m(last[0], last[1], self._boxes))
        rec.save(self.path, default_blueprint=default_blueprint(focus))
        rec.set_log_time_enabled(False)  # sim_time only: the same flight, the same data
        rec.send_recording_name(self.path.stem)
        self._rec = rec
        batches = _column_batches()
        self._step_batch, self._truth_batch, self._esc_batch, self._scene_batch = batches
        self._scene_t = -math.inf  # the last step the scene has seen
        self._truth_held = np.zeros(3)  # the true ground effect last received
        self._rows: list[tuple[float, ...]] = []
        self._events: list[tuple[float, str, str]] = []
        self._learner: list[tuple[float, float, float]] = []
        self._learner_lock = threading.Lock()  # the online learner reports from its thread
        self._counters: dict[str, tuple[Callable[[], Sequence[int]], ColumnBatch]] = {}
        self._segment = 0  # the trail's segment in progress
        self._segment_points = np.zeros((0, 3))  # its points so far
        self._segment_drawn = 0  # how many of them its last drawing had
        self._trail_batches: dict[str, ColumnBatch] = {}
        self._trail_length_m = 0.0
        self._trail_last: np.ndarray | None = None
        self._trail_t = -math.inf  # the last step the trail has seen
        self._next_flush_s = -math.inf
        self._flush_deadline = -math.inf
        self._last_t = 0.0
        self._mode: str | None = None
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
    ) -> None:
        """One control step: what the autopilot saw, decided and sent, and the truth."""
        t0 = time.perf_counter()
        if not self._started:
            self._start(t_s, state.position_m)
        if mode != self._mode:
            self._mode_changed(t_s, mode)
        if armed != self._armed:
            self._armed = armed
            self._events.append((t_s, "INFO", "armed" if armed else "disarmed"))
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
        self._rows.append(
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

    def learner(self, t_s: float, loss: float | None = None, version: int | None = None) -> None:
        """The online learner's loss and the weight-snapshot version now in use (thread-safe)."""
        with self._learner_lock:
            self._learner.append(
                (
                    t_s,
                    math.nan if loss is None else loss,
                    math.nan if version is None else float(version),
                )
            )

    def watch_counters(self, link: str, read: Callable[[], Sequence[int]]) -> None:
        """Record `read()` = (received, dropped, rejected) of a MAVLink link at every flush."""
        path = f"{MAVLINK}/{link}"
        batch = ColumnBatch(TIMELINE)
        batch.add(path, rr.Scalars.columns(scalars=np.zeros((1, len(COUNTERS)))))
        self._counters[link] = (read, batch)
        self._rec.log(path, rr.SeriesLines(names=list(COUNTERS)), static=True)

    def close(self, ended: str) -> None:
        """Flush everything, note how the flight ended, and finish the file (with its footer)."""
        if self._closed:
            return
        self._closed = True
        level = "INFO" if ended == "landed" else "WARN"
        self._events.append((self._last_t, level, f"flight ended: {ended}"))
        self.flush()
        self._rec.flush()
        self._rec.disconnect()  # closes the file sink: writes the footer
        self._background_s = time.process_time() - time.thread_time() - self._cpu0

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
            self._send_rows(np.asarray(rows, dtype=float))
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
            a = np.asarray(learned, dtype=float)
            for col, path in ((1, "plots/learner/loss"), (2, "plots/learner/version")):
                keep = ~np.isnan(a[:, col])
                if keep.any():
                    self._scalars(path, a[keep, 0], a[keep, col])
        now_ns = np.array([round(self._last_t * 1e9)], dtype=np.int64)
        for link, (read, batch) in self._counters.items():
            counts = np.asarray([read()], dtype=float)
            batch.send(self._rec, now_ns, {_s(f"{MAVLINK}/{link}"): counts})
        self._next_flush_s = self._last_t + self._every_s
        self._flush_deadline = time.perf_counter() + FLUSH_WALL_S

    def _send(self, path: str, t_s: np.ndarray, columns: Any) -> None:
        rr.send_columns(path, indexes=[_duration(t_s)], columns=columns, recording=self._rec)

    def _scalars(self, path: str, t_s: np.ndarray, values: np.ndarray) -> None:
        self._send(path, t_s, rr.Scalars.columns(scalars=values))

    def _send_rows(self, a: np.ndarray) -> None:
        t = a[:, T]
        time_ns = np.rint(t * 1e9).astype(np.int64)
        p, v, q = a[:, P : P + 3], a[:, V : V + 3], a[:, Q : Q + 4]
        sp, spv = a[:, SP : SP + 3], a[:, SPV : SPV + 3]
        ge, true_ge = a[:, GE : GE + 3], a[:, TRUE : TRUE + 3]
        w, x, y, z = q.T
        roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
        pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
        values = {
            _s("plots/position"): p,
            _s("plots/velocity"): v,
            _s("plots/setpoint"): sp,
            _s("plots/z"): np.column_stack((p[:, 2], sp[:, 2])),
            _s("plots/height"): a[:, H],
            _s("plots/mode"): a[:, MODE],
            _s("plots/errors/position"): sp - p,
            _s("plots/errors/velocity"): spv - v,
            _s("plots/errors/attitude"): a[:, DES : DES + 2] - np.column_stack((roll, pitch)),
            _s("plots/rotors/commanded"): a[:, N : N + 4],
        }
        for i, axis in enumerate("xyz"):
            values[_s(f"plots/ground_effect/{axis}/predicted")] = ge[:, i]
        self._step_batch.send(self._rec, time_ns, values)
        has_truth = ~np.isnan(true_ge[:, 0])
        if has_truth.any():
            values = {
                _s(f"plots/ground_effect/{axis}/true"): true_ge[has_truth, i]
                for i, axis in enumerate("xyz")
            }
            self._truth_batch.send(self._rec, time_ns[has_truth], values)
        has_esc = ~np.isnan(a[:, ACT])
        if has_esc.any():
            actual = a[has_esc, ACT : ACT + 4] / RAD_S_TO_RPM
            self._esc_batch.send(self._rec, time_ns[has_esc], {_s("plots/rotors/actual"): actual})
        self._send_scene(t, time_ns, p, q, ge, true_ge)
        self._send_trail(t, p)

    def _send_scene(
        self,
        t: np.ndarray,
        time_ns: np.ndarray,
        p: np.ndarray,
        q: np.ndarray,
        ge: np.ndarray,
        true_ge: np.ndarray,
    ) -> None:
        """The drone's pose and the ground-effect arrows at SCENE_PERIOD_S (the plots keep
        every step): a 3-D view needs no more, and it is a third of the data."""
        keep = _firsts(t, self._scene_t, SCENE_PERIOD_S)
        # the truth last received (it comes every step unless the world slows it down)
        seen = np.flatnonzero(~np.isnan(true_ge[:, 0]))
        truth = np.tile(self._truth_held, (len(t), 1))
        if len(seen):
            held = np.searchsorted(seen, np.arange(len(t)), side="right") - 1
            truth[held >= 0] = true_ge[seen[held[held >= 0]]]
            self._truth_held = true_ge[seen[-1]]
        self._scene_t = t[-1]
        if not keep.any():
            return
        values = {
            f"{DRONE}:Transform3D:translation": p[keep],
            f"{DRONE}:Transform3D:quaternion": q[keep][:, [1, 2, 3, 0]],  # rerun's: x y z w
            f"{GE_PREDICTED_ARROW}:Arrows3D:origins": p[keep],
            f"{GE_PREDICTED_ARROW}:Arrows3D:vectors": ge[keep] * GE_ARROW_M_PER_N,
            f"{GE_TRUE_ARROW}:Arrows3D:origins": p[keep],
            f"{GE_TRUE_ARROW}:Arrows3D:vectors": truth[keep] * GE_ARROW_M_PER_N,
        }
        self._scene_batch.send(self._rec, time_ns[keep], values)

    def _send_trail(self, t: np.ndarray, p: np.ndarray) -> None:
        """The flown path: a point every TRAIL_SPACING_M flown, drawn every TRAIL_PERIOD_S up
        to the drone. A 3-D view shows the latest value of each entity, so the trail is
        redrawn rather than appended to; to keep that linear in the flight's length it is cut
        into segments of TRAIL_SEGMENT_S (`world/trajectory/<k>`), and only the segment in
        progress is redrawn."""
        if self._trail_last is None:
            self._segment_points, self._trail_last = p[:1], p[0]
        steps = np.linalg.norm(np.diff(np.vstack((self._trail_last, p)), axis=0), axis=1)
        flown = self._trail_length_m + np.cumsum(steps)
        before = np.concatenate(([self._trail_length_m], flown[:-1]))
        keep = np.floor(flown / TRAIL_SPACING_M) > np.floor(before / TRAIL_SPACING_M)
        kept_t, kept_p = t[keep], p[keep]
        self._trail_length_m, self._trail_last = float(flown[-1]), p[-1]
        drawn: dict[int, tuple[list[float], list[np.ndarray]]] = {}
        used = 0
        for i in np.flatnonzero(_firsts(t, self._trail_t, TRAIL_PERIOD_S)):
            upto = int(np.searchsorted(kept_t, t[i], side="right"))
            points = np.vstack((self._segment_points, kept_p[used:upto]))
            used = upto
            segment = int(t[i] // TRAIL_SEGMENT_S)
            if segment != self._segment:  # start the next one where the last drawing ended
                points = points[max(self._segment_drawn - 1, 0) :]
                self._segment = segment
            self._segment_points, self._segment_drawn = points, len(points)
            times, strips = drawn.setdefault(segment, ([], []))
            times.append(t[i])
            strips.append(np.vstack((points, p[i : i + 1])))
        self._trail_t = t[-1]
        self._segment_points = np.vstack((self._segment_points, kept_p[used:]))
        for segment, (times, strips) in drawn.items():
            path = f"{TRAJECTORY}/{segment}"
            if path not in self._trail_batches:
                batch = ColumnBatch(TIMELINE)
                batch.add(path, rr.LineStrips3D.columns(strips=[np.zeros((2, 3))], colors=[0]))
                self._trail_batches[path] = batch
            values = {
                f"{path}:LineStrips3D:strips": strips,
                f"{path}:LineStrips3D:colors": np.full(len(strips), TRAIL_RGBA, dtype=np.uint32),
            }
            time_ns = np.rint(np.asarray(times) * 1e9).astype(np.int64)
            self._trail_batches[path].send(self._rec, time_ns, values)

    # -- the static part and the start ------------------------------------------------------

    def _log_static(self) -> None:
        rec = self._rec
        wps = self._mission.waypoints
        log_world(rec, self._boxes, [wp.position_m for wp in wps])
        log_drone(rec, self._vehicle)
        for path, names in SERIES.items():
            if "/ground_effect/" in path:
                color = GE_COLORS[path.rsplit("/", 1)[1]]
                rec.log(path, rr.SeriesLines(names=list(names), colors=[color]), static=True)
            elif path.startswith("plots/rotors/"):
                rec.log(path, rr.SeriesLines(names=list(names), colors=ROTOR_COLORS), static=True)
            else:
                rec.log(path, rr.SeriesLines(names=list(names)), static=True)
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
        self.mission(self._mission.waypoints, position_m, t_s)
        self.learner(t_s, version=0)  # the offline weights until an online update replaces them

    def mission(self, waypoints: Sequence[Waypoint], start_m: Vec3, t_s: float) -> None:
        """Draw the mission (a new upload replaces the drawing from `t_s` on)."""
        path = mission_path(
            waypoints, start_m, self._takeoff_altitude_m, self._mission.land, self._boxes
        )
        self._rec.set_time(TIMELINE, duration=np.timedelta64(round(t_s * 1e9), "ns"))
        log_mission(self._rec, waypoints, path)

    def _mode_changed(self, t_s: float, mode: str) -> None:
        if mode not in self._modes:  # a mode the caller did not announce: name it in the meta
            self._modes.append(mode)
            self._log_meta()
        self._events.append((t_s, "INFO", f"mode {mode}" if self._mode else f"mode {mode} (start)"))
        self._mode = mode
        self._mode_index = float(self._modes.index(mode))
