"""The recorder's per-step rows and how a flush turns them into rerun data.

`FlightRecorder.step` appends one tuple per control step in the order of `Row` below (so
that the loop pays for one tuple, nothing more); `RowSender.send` turns a block of them into
columns: every step's plots as one Arrow batch, the truth and the ESC telemetry where they
arrived, the 3-D scene at 50 Hz and the trail (`autopilot.recording.trail`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import rerun as rr

from autopilot.metrics import NEAR_GROUND_M
from autopilot.recording.review import ReviewSpread
from autopilot.recording.rrbatch import ColumnBatch
from autopilot.recording.trail import Trail, firsts
from learner.flightlogs.recording import (
    DRONE,
    GE_ARROW_M_PER_N,
    GE_PREDICTED_ARROW,
    GE_TRUE_ARROW,
    SERIES,
    TIMELINE,
    TRAJECTORY,
)
from simbridge.frames import quat_to_matrices
from simbridge.sensors.esc import RAD_S_TO_RPM
from simbridge.vehicle import GRAVITY_M_S2


class Row:
    """Where each quantity starts in a row: time s; position m, velocity m/s, quaternion
    (w, x, y, z); setpoint position m and velocity m/s (NaN: none); height m; mode index;
    predicted ground effect N; commanded rotor speeds rad/s; true ground effect N (NaN: not
    received this step); actual rotor speeds rpm (NaN: not received); desired roll, pitch rad
    (NaN: no control output); body rates rad/s; the accelerometer's specific force m/s^2
    (body FRD; logged as the world acceleration, gravity removed)."""

    T, P, V, Q, SP, SPV, H, MODE, GE, N, TRUE, ACT, DES, RATES, ACC = (
        0, 1, 4, 7, 11, 14, 17, 18, 19, 22, 26, 29, 33, 35, 38,
    )  # fmt: skip
    WIDTH = 41


SCENE_PERIOD_S = 0.02  # the 3-D scene at 50 Hz (the plots keep every step)
TRAIL_SPACING_M = 0.01  # a trail point every centimetre flown
TRAIL_PERIOD_S = 0.25  # the trail is redrawn this often (simulated seconds)
TRAIL_SEGMENT_S = 10.0  # world/trajectory/0 covers 0-10 s of flight, /1 10-20 s, ...
TRAIL_RGBA = 0x17BECFFF  # teal, opaque, against the light ground (rerun packs 0xRRGGBBAA)

# The series logged at every step (the rest: truth, ESC telemetry, learner reports).
TRUTH_SERIES = (*(f"plots/ground_effect/{axis}/true" for axis in "xyz"), "plots/model_error_mn")
ESC_SERIES = ("plots/rotors/actual", *(f"plots/rotors/difference/{i}" for i in range(4)))
STEP_SERIES = tuple(
    p
    for p in SERIES
    if not p.startswith("plots/learner/") and p not in TRUTH_SERIES and p not in ESC_SERIES
)


def scalars_key(path: str) -> str:
    """The key of a time series' values in a ColumnBatch."""
    return f"{path}:Scalars:scalars"


def _scalars(width: int) -> Any:
    return rr.Scalars.columns(scalars=np.zeros((1, width)))


def world_acceleration(q: np.ndarray, specific_force_frd: np.ndarray) -> np.ndarray:
    """The accelerometer's specific force (body FRD, m/s^2) in the world frame, gravity
    removed: as autopilot.recording.flight_log.kinematic_acceleration_m_s2, for many steps at
    once."""
    flu = specific_force_frd * np.array([1.0, -1.0, -1.0])
    world = np.einsum("nij,nj->ni", quat_to_matrices(q), flu)
    world[:, 2] -= GRAVITY_M_S2
    return world


class RowSender:
    def __init__(self, rec: rr.RecordingStream, hold_mode: float = -1.0) -> None:
        self._rec = rec
        self._step = ColumnBatch(TIMELINE)
        for path in STEP_SERIES:
            self._step.add(path, _scalars(len(SERIES[path])))
        self._truth = ColumnBatch(TIMELINE)
        for path in TRUTH_SERIES:
            self._truth.add(path, _scalars(1))
        self._esc = ColumnBatch(TIMELINE)
        for path in ESC_SERIES:
            self._esc.add(path, _scalars(len(SERIES[path])))
        self._hold_mode = hold_mode  # the `holding` phase's index in the rows' mode column
        self.spread = ReviewSpread()
        self._scene = ColumnBatch(TIMELINE)
        zero = np.zeros((1, 3))
        self._scene.add(DRONE, rr.Transform3D.columns(translation=zero, quaternion=[[0, 0, 0, 1]]))
        for path in (GE_PREDICTED_ARROW, GE_TRUE_ARROW):
            self._scene.add(path, rr.Arrows3D.columns(origins=zero, vectors=zero))
        self._scene_t = -np.inf  # the last step the scene has seen
        self._truth_held = np.zeros(3)  # the true ground effect last received
        self._trail = Trail(TRAIL_SPACING_M, TRAIL_PERIOD_S, TRAIL_SEGMENT_S)
        self._trail_batches: dict[str, ColumnBatch] = {}  # one per segment

    def send(self, a: np.ndarray) -> None:
        """Rows [n, Row.WIDTH] to rerun."""
        r = Row
        t = a[:, r.T]
        time_ns = np.rint(t * 1e9).astype(np.int64)
        p, v, q = a[:, r.P : r.P + 3], a[:, r.V : r.V + 3], a[:, r.Q : r.Q + 4]
        sp, spv = a[:, r.SP : r.SP + 3], a[:, r.SPV : r.SPV + 3]
        ge, true_ge = a[:, r.GE : r.GE + 3], a[:, r.TRUE : r.TRUE + 3]
        w, x, y, z = q.T
        roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
        pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
        attitude_error = a[:, r.DES : r.DES + 2] - np.column_stack((roll, pitch))
        height_error_mm = (p[:, 2] - sp[:, 2]) * 1e3
        values = {
            scalars_key("plots/position"): p,
            scalars_key("plots/velocity"): v,
            scalars_key("plots/setpoint"): sp,
            scalars_key("plots/z"): np.column_stack((p[:, 2], sp[:, 2])),
            scalars_key("plots/height"): a[:, r.H],
            scalars_key("plots/mode"): a[:, r.MODE],
            scalars_key("plots/errors/position"): sp - p,
            scalars_key("plots/errors/velocity"): spv - v,
            scalars_key("plots/errors/attitude"): attitude_error,
            scalars_key("plots/rotors/commanded"): a[:, r.N : r.N + 4],
            scalars_key("plots/attitude"): q,
            scalars_key("plots/rates"): a[:, r.RATES : r.RATES + 3],
            scalars_key("plots/acceleration"): world_acceleration(q, a[:, r.ACC : r.ACC + 3]),
            scalars_key("plots/height_error_mm"): height_error_mm,
        }
        for i, axis in enumerate("xyz"):
            values[scalars_key(f"plots/ground_effect/{axis}/predicted")] = ge[:, i]
        self._step.send(self._rec, time_ns, values)
        has_truth = ~np.isnan(true_ge[:, 0])
        model_error_mn = (ge[:, 2] - true_ge[:, 2]) * 1e3
        if has_truth.any():
            values = {
                scalars_key(f"plots/ground_effect/{axis}/true"): true_ge[has_truth, i]
                for i, axis in enumerate("xyz")
            }
            values[scalars_key("plots/model_error_mn")] = model_error_mn[has_truth]
            self._truth.send(self._rec, time_ns[has_truth], values)
        has_esc = ~np.isnan(a[:, r.ACT])
        difference = None
        if has_esc.any():
            actual = a[has_esc, r.ACT : r.ACT + 4] / RAD_S_TO_RPM
            difference = a[has_esc, r.N : r.N + 4] - actual
            values = {scalars_key("plots/rotors/actual"): actual}
            for i in range(4):
                values[scalars_key(f"plots/rotors/difference/{i}")] = difference[:, i]
            self._esc.send(self._rec, time_ns[has_esc], values)
        # near the ground: a hold whose setpoint is at most NEAR_GROUND_M above the surface
        hold = (a[:, r.MODE] == self._hold_mode) & (sp[:, 2] - p[:, 2] + a[:, r.H] <= NEAR_GROUND_M)
        self.spread.add("plots/height_error_mm", height_error_mm, hold)
        self.spread.add("plots/model_error_mn", np.where(has_truth, model_error_mn, np.nan), hold)
        self.spread.add("plots/ground_effect/z/true", true_ge[:, 2])
        if difference is not None:
            self.spread.add("plots/rotors/difference", difference)
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
        """The drone's pose and the ground-effect arrows at SCENE_PERIOD_S: a 3-D view needs
        no more, and it is a third of the data."""
        keep = firsts(t, self._scene_t, SCENE_PERIOD_S)
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
        self._scene.send(self._rec, time_ns[keep], values)

    def _send_trail(self, t: np.ndarray, p: np.ndarray) -> None:
        for segment, (times, strips) in self._trail.update(t, p).items():
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
