"""The online learner's host in the autopilot: a bounded queue, a thread, the current snapshot.

The control loop calls `submit` (never blocks: a full queue drops the sample and counts it)
and reads `snapshot` (one reference, replaced whole by the learner thread).

Asynchronous (the default with a ground station): samples go, in chunks (CHUNK_SAMPLES),
down a pipe to the learner process (autopilot/online/learner_process.py), which runs the update
on the other core; the queue is the pipe, bounded by the samples sent and not yet taken
off it. The learner thread here waits on the pipe for new weights and publishes each as
an immutable snapshot by one reference assignment; it holds the interpreter only for that.

Deterministic (lockstep tests and trials): no process and no thread; the update runs
inside `submit` when a batch completes, so updates happen at the same simulated times on
every run. Pause, reset and new settings reach the learner in order with the samples.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import shutil
import threading
import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from autopilot.online.learner_process import (
    ROW_FEATURES,
    ROW_TARGETS,
    ROW_TIME,
    ROW_TRACKING,
    ROW_WIDTH,
    learner_main,
)
from learner.model import GroundEffectNet, save_model
from learner.online.memory import Memory
from learner.online.session import OnlineSession, adapted_header
from learner.online.settings import OnlineSettings
from learner.online.snapshot import Snapshot, make_snapshot

QUEUE_SIZE = 512  # samples: 5 s of slack before dropping
NEAR_SURFACE_M = 0.05  # within 2 rotor radii of the surface the grounds tell apart ...
CLEAR_OF_SURFACE_M = 0.5  # ... reached coming down from this high (not the take-off)
CHUNK_SAMPLES = 16  # a message carries at least 0.16 s of samples ...
CHUNK_WALL_S = 0.05  # ... and goes at least this long after the one before, with up to
CHUNK_MAX = 128  # this many: in real time a message per 0.16 s, in a lockstep flight at
# full speed about 20 a second of wall time, not 60. Each message wakes the learner process,
# which updates at once; `composite`, updating every 16 samples, was woken 50 times a
# second, and the loop's p99 step time in `groundfx bench online` rose 1.1-1.3-fold
# against the learner resting (about 1.0 with these chunks).
READY_TIMEOUT_S = 60.0  # the learner process imports torch: about 2 s, far more under load
# (sim time, loss, version, what became of the update in words, the ground in use or None)
Report = Callable[[float, float | None, int, str, str | None], None]
# the learner's last word: counts, reject reasons, last loss, why updates were held, and
# composite's memory of grounds at the end (what --save-model stores)
Final = tuple[
    dict[str, int], dict[str, int], float | None, dict[str, float] | None, dict[str, Any] | None
]


class OnlineLearner:
    def __init__(
        self,
        base: GroundEffectNet,
        settings: OnlineSettings,
        memory: Memory | None = None,
        deterministic: bool = True,
        on_report: Report | None = None,
        queue_size: int = QUEUE_SIZE,
        offline: GroundEffectNet | None = None,
    ) -> None:
        self.base = base
        self.offline = offline if offline is not None else base
        self.settings = settings
        self.memory = memory
        self.deterministic = deterministic
        self.on_report = on_report
        self.snapshot: Snapshot = Snapshot(0, base, 0.0)  # what the controller reads
        self.paused = False
        self.dropped = 0
        self.ignored_paused = 0
        self.errors: list[str] = []
        self.losses: list[tuple[float, float, int]] = []  # (t, loss, version) per update
        # composite: the grounds known, what became of them in flight (created, recalled) and
        # when the vehicle first came down near the surface (before it, nothing tells them
        # apart)
        self.ground_events: list[dict[str, Any]] = []
        basis = base.header.get("basis") or {}
        self._grounds_known = {basis.get("home")} | {g["name"] for g in basis.get("learnt") or []}
        self.near_surface_s: float | None = None
        self._cleared_surface = False
        self.session: OnlineSession | None = None
        if deterministic:
            self.session = OnlineSession(base, settings, memory, offline)
            self.session.warm_up()  # not in the first update of the flight
            self.snapshot = self.session.snapshot  # composite: its home ground
            return
        self._queue_size = queue_size
        self._chunk_samples = max(1, min(CHUNK_SAMPLES, queue_size))
        self._chunk = np.empty((max(self._chunk_samples, min(CHUNK_MAX, queue_size)), ROW_WIDTH))
        self._last_flush_s = 0.0  # wall clock, monotonic
        self._filled = 0
        context = multiprocessing.get_context("spawn")
        self._sent = 0  # samples down the pipe ...
        self._taken = context.RawValue("q", 0)  # ... and taken off it (the learner counts)
        # counts, reject reasons, last loss, held evidence: the learner process's last word
        self._final: Final | None = None
        self._ready = threading.Event()
        self._conn, child = multiprocessing.Pipe(duplex=True)  # a socket pair: 200 kB buffer
        self._process = context.Process(
            target=learner_main,
            args=(child, self._taken, base, settings, memory, offline),
            name="groundfx-learner",
            daemon=True,
        )
        self._process.start()
        child.close()
        self._thread = threading.Thread(target=self._run, name="online-learner", daemon=True)
        self._thread.start()

    # --- the control loop's side: never waits ---------------------------------------------

    def submit(
        self, features: np.ndarray, target_n: np.ndarray, t_s: float, tracking_m_s: float = 0.0
    ) -> None:
        if self.paused:
            self.ignored_paused += 1
            return
        if self.near_surface_s is None:  # features[0]: the height above the surface, m
            if features[0] > CLEAR_OF_SURFACE_M:
                self._cleared_surface = True
            elif self._cleared_surface and features[0] < NEAR_SURFACE_M:
                self.near_surface_s = t_s
        if self.session is not None:
            self._learn(features, target_n, t_s, tracking_m_s)
            return
        row = self._chunk[self._filled]
        row[ROW_TIME] = t_s
        row[ROW_FEATURES] = features
        row[ROW_TARGETS] = target_n
        row[ROW_TRACKING] = tracking_m_s
        self._filled += 1
        if self._filled >= self._chunk_samples and (
            self._filled == len(self._chunk)
            or time.monotonic() - self._last_flush_s >= CHUNK_WALL_S
        ):
            self._flush()

    def _flush(self) -> None:
        n, self._filled = self._filled, 0
        self._last_flush_s = time.monotonic()
        if n == 0:
            return
        if self._sent - self._taken.value + n > self._queue_size or self._final is not None:
            self.dropped += n  # the learner is behind (or gone): drop, never wait
            return
        try:
            self._conn.send(("samples", self._chunk[:n].copy()))
        except OSError:  # the learner process died: its thread reports it; count the loss
            self.dropped += n
            return
        self._sent += n

    def wait_ready(self, timeout_s: float = READY_TIMEOUT_S) -> bool:
        """Before the flight: wait until the learner process is up (in flight, never)."""
        return self.session is not None or self._ready.wait(timeout_s)

    def pause(self, paused: bool) -> None:
        self.paused = paused

    def reset(self, t_s: float) -> None:
        """Back to the offline weights."""
        if self.session is not None:
            self._publish(self.session.reset(t_s), "reset")
        else:
            self._command("reset", t_s)

    def configure(self, settings: OnlineSettings) -> None:
        self.settings = settings
        if self.session is not None:
            self.session.configure(settings)
        else:
            self._command("configure", settings)

    def _command(self, kind: str, value: Any) -> None:
        self._flush()  # the samples before the command are learnt before it
        if self._final is None:
            with contextlib.suppress(OSError):  # a dead learner: its thread reports it
                self._conn.send((kind, value))

    def close(self) -> None:
        """Let the learner finish the samples already sent, then stop it."""
        if self.session is not None:
            return
        self._command("close", None)
        self._thread.join(timeout=60.0)
        self._process.join(timeout=10.0)
        if self._process.is_alive():
            self._process.kill()
            self._process.join()
        self._conn.close()

    # --- the learner thread: the pipe in, snapshots out ------------------------------------

    def _run(self) -> None:
        while True:
            try:
                message = self._conn.recv()
            except (EOFError, OSError):
                if self._final is None:
                    code = self._process.exitcode
                    self.errors.append(f"the learner process ended unexpectedly (exit {code})")
                    self._final = ({}, {}, None, None, None)
                self._ready.set()
                return
            kind = message[0]
            if kind == "snapshot":
                _, version, weights, biases, t_s, loss, basis, verdict = message
                header = adapted_header(self.base.header, self.settings, version, {})
                if basis is not None:
                    header["basis"] = basis
                normaliser = self.base.normaliser
                snapshot = make_snapshot(version, weights, biases, normaliser, header, t_s, loss)
                self._publish(snapshot, verdict)
            elif kind == "rejected":
                self._report(message[1], message[2], message[3])
            elif kind == "reset":
                self._publish(Snapshot(message[1], self.offline, message[2]), "reset")
            elif kind == "error":
                self.errors.append(message[1])
            elif kind == "ready":
                self._ready.set()
            elif kind == "summary":
                self._final = (message[1], message[2], message[3], message[4], message[5])
                self._ready.set()
                return

    # --- both modes ------------------------------------------------------------------------

    def _learn(
        self, features: np.ndarray, target_n: np.ndarray, t_s: float, tracking_m_s: float
    ) -> None:
        assert self.session is not None
        updates = self.session.counts["updates"]
        snapshot = self.session.add(features, target_n, t_s, tracking_m_s)
        if snapshot is not None:
            self._publish(snapshot, self.session.last_verdict)
        elif self.session.counts["updates"] != updates:  # rejected, or held back
            self._report(t_s, self.session.last_loss, self.session.last_verdict)

    def _publish(self, snapshot: Snapshot, verdict: str = "") -> None:
        self.snapshot = snapshot  # one reference assignment: the atomic swap
        if snapshot.loss is not None:
            self.losses.append((snapshot.t_s, snapshot.loss, snapshot.version))
        self._ground_event(snapshot, verdict)
        self._report(snapshot.t_s, snapshot.loss, verdict)

    def _ground_event(self, snapshot: Snapshot, verdict: str) -> None:
        """composite: a ground recalled, or a new one learnt (its first publication)."""
        basis = snapshot.net.header.get("basis") or {}
        ground = basis.get("current", basis.get("home"))
        if verdict.startswith("accepted (recalled"):
            event = "recalled"
            # "accepted (recalled, merging learnt-2)": a ground this flight created, dropped
            merged = verdict.partition(", merging ")[2].rstrip(")")
            if merged:
                self.ground_events.append(
                    {"t_s": snapshot.t_s, "event": "merged", "ground": merged, "into": ground}
                )
        elif verdict == "accepted (adapted)" and ground not in self._grounds_known:
            event = "created"
        else:
            return
        self._grounds_known.add(ground)
        self.ground_events.append({"t_s": snapshot.t_s, "event": event, "ground": ground})

    def _report(self, t_s: float, loss: float | None, verdict: str) -> None:
        """The update's loss and verdict, the version and ground now in use, to the recorder."""
        if self.on_report is not None:
            basis = self.snapshot.net.header.get("basis") or {}
            ground = basis.get("current", basis.get("home"))
            self.on_report(t_s, loss, self.snapshot.version, verdict, ground)

    # --- the end of the flight -------------------------------------------------------------

    def _counts(self) -> Final:
        if self.session is not None:
            s = self.session
            counts, reasons = dict(s.counts), dict(s.reject_reasons)
            return counts, reasons, s.last_loss, s.held_evidence(), s.known_grounds()
        return self._final if self._final is not None else ({}, {}, None, None, None)

    def summary(self) -> dict[str, Any]:
        c, reasons, last_loss, held_evidence, _ = self._counts()
        return {
            "online_method": self.settings.method,
            "online_mode": "deterministic" if self.deterministic else "asynchronous",
            "online_version": self.snapshot.version,
            "online_samples": c.get("samples", 0),
            "online_updates": c.get("updates", 0),
            "online_accepted": c.get("accepted", 0),
            "online_rejected": c.get("rejected", 0),
            "online_reject_reasons": reasons,
            "online_dropped": self.dropped,
            "online_ignored_paused": self.ignored_paused,
            "online_outliers": c.get("outliers", 0),
            "online_resets": c.get("resets", 0),
            **self._composite_summary(c),
            "online_held_evidence": held_evidence,
            "online_loss_first": self.losses[0][1] if self.losses else None,
            "online_loss_last": last_loss,
            "online_errors": self.errors,
            "online_settings": asdict(self.settings),
        }

    def _composite_summary(self, counts: dict[str, int]) -> dict[str, Any]:
        """`composite`: how often the confidence test held, adapted or recalled a ground,
        and the ground in use at the end."""
        if self.settings.method != "composite":
            return {}
        basis = self.snapshot.net.header.get("basis") or {}
        return {
            "online_held": counts.get("held", 0),
            "online_adapted": counts.get("adapted", 0),
            "online_recalled": counts.get("recalled", 0),
            "online_ground": basis.get("current", basis.get("home")),
            "online_grounds": [basis.get("home")] + [g["name"] for g in basis.get("learnt") or []],
            "online_ground_events": self.ground_events,
            "online_near_surface_s": self.near_surface_s,
        }

    def save(self, path: Path) -> Path:
        """The current snapshot as a model file, with the offline weights it came from beside
        it (NAME.offline.npz: what the protecting methods and a reset go back to in a later
        flight) and the base model's memory (so that ewc and replay can go on from it)."""
        from learner.online.memory import memory_path_for, offline_path_for

        net = self.snapshot.net
        counts, _, _, _, memory = self._counts()
        header = adapted_header(self.base.header, self.settings, self.snapshot.version, counts)
        basis = memory if memory is not None else net.header.get("basis")
        if basis:  # composite: the grounds it knows now
            header["basis"] = basis
        out = save_model(path, GroundEffectNet(net.weights, net.biases, net.normaliser, header))
        save_model(offline_path_for(out), self.offline)
        source = self.memory.header.get("path") if self.memory else None
        if source and Path(source).exists():
            target = memory_path_for(out)
            if Path(source).resolve() != target.resolve():
                shutil.copyfile(source, target)
        return out
