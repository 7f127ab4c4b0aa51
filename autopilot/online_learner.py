"""The online learner's host in the autopilot: a thread, a bounded queue, the current snapshot.

The control loop calls `submit` (never blocks: a full queue drops the sample and counts it)
and reads `snapshot` (one reference, replaced whole by the learner). In deterministic mode
there is no thread: the update runs inside `submit` when a batch completes, so updates
happen at the same simulated times on every run (lockstep makes that free of drift).
Pause, reset and new settings travel to the thread through a command deque, never a lock
the control loop could wait on.
"""

from __future__ import annotations

import collections
import queue
import shutil
import threading
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from learner.model import GroundEffectNet, save_model
from learner.online.memory import Memory
from learner.online.session import OnlineSession
from learner.online.settings import OnlineSettings
from learner.online.snapshot import Snapshot

QUEUE_SIZE = 512  # samples: 5 s of slack before dropping
Report = Callable[[float, float | None, int], None]  # (sim time, loss, version)


class OnlineLearner:
    def __init__(
        self,
        base: GroundEffectNet,
        settings: OnlineSettings,
        memory: Memory | None = None,
        deterministic: bool = True,
        on_report: Report | None = None,
        queue_size: int = QUEUE_SIZE,
    ) -> None:
        if deterministic:
            import torch

            torch.set_num_threads(1)  # the update runs in the control thread: one core
        self.session = OnlineSession(base, settings, memory)
        self.deterministic = deterministic
        self.on_report = on_report
        self.snapshot: Snapshot = self.session.snapshot  # what the controller reads
        self.paused = False
        self.dropped = 0
        self.ignored_paused = 0
        self.errors: list[str] = []
        self.losses: list[tuple[float, float, int]] = []  # (t, loss, version) per update
        self._queue: queue.Queue[tuple[np.ndarray, np.ndarray, float] | None] = queue.Queue(
            maxsize=queue_size
        )
        self._commands: collections.deque[tuple[str, Any]] = collections.deque()
        self._thread: threading.Thread | None = None
        if not deterministic:
            self._thread = threading.Thread(target=self._run, name="online-learner", daemon=True)
            self._thread.start()

    # --- the control loop's side: never waits ---------------------------------------------

    def submit(self, features: np.ndarray, target_n: np.ndarray, t_s: float) -> None:
        if self.paused:
            self.ignored_paused += 1
            return
        if self.deterministic:
            self._learn(features, target_n, t_s)
            return
        try:
            self._queue.put_nowait((features, target_n, t_s))
        except queue.Full:
            self.dropped += 1

    def pause(self, paused: bool) -> None:
        self.paused = paused

    def reset(self, t_s: float) -> None:
        """Back to the offline weights."""
        if self.deterministic:
            self._publish(self.session.reset(t_s))
        else:
            self._commands.append(("reset", t_s))

    def configure(self, settings: OnlineSettings) -> None:
        if self.deterministic:
            self.session.configure(settings)
        else:
            self._commands.append(("configure", settings))

    def close(self) -> None:
        """Stop the thread after the samples already queued (deterministic: nothing to do)."""
        if self._thread is not None:
            self._queue.put(None)
            self._thread.join(timeout=30.0)
            self._thread = None

    # --- the learner's side ----------------------------------------------------------------

    def _run(self) -> None:
        import torch

        torch.set_num_threads(1)  # one core: the other belongs to the control loop
        while True:
            item = self._queue.get()
            while self._commands:
                kind, value = self._commands.popleft()
                try:
                    if kind == "reset":
                        self._publish(self.session.reset(value))
                    else:
                        self.session.configure(value)
                except Exception as err:  # a bad setting must not kill the thread
                    self.errors.append(f"{kind}: {err}")
            if item is None:
                return
            self._learn(*item)

    def _learn(self, features: np.ndarray, target_n: np.ndarray, t_s: float) -> None:
        updates = self.session.counts["updates"]
        snapshot = self.session.add(features, target_n, t_s)
        if snapshot is not None:
            self._publish(snapshot)
        elif self.session.counts["updates"] != updates and self.on_report is not None:
            self.on_report(t_s, self.session.last_loss, self.snapshot.version)  # rejected

    def _publish(self, snapshot: Snapshot) -> None:
        self.snapshot = snapshot  # one reference assignment: the atomic swap
        if snapshot.loss is not None:
            self.losses.append((snapshot.t_s, snapshot.loss, snapshot.version))
        if self.on_report is not None:
            self.on_report(snapshot.t_s, snapshot.loss, snapshot.version)

    # --- the end of the flight -------------------------------------------------------------

    def summary(self) -> dict[str, Any]:
        c = self.session.counts
        return {
            "online_method": self.session.settings.method,
            "online_mode": "deterministic" if self.deterministic else "asynchronous",
            "online_version": self.snapshot.version,
            "online_samples": c["samples"],
            "online_updates": c["updates"],
            "online_accepted": c["accepted"],
            "online_rejected": c["rejected"],
            "online_reject_reasons": dict(self.session.reject_reasons),
            "online_dropped": self.dropped,
            "online_ignored_paused": self.ignored_paused,
            "online_outliers": c["outliers"],
            "online_resets": c["resets"],
            "online_loss_first": self.losses[0][1] if self.losses else None,
            "online_loss_last": self.session.last_loss,
            "online_errors": self.errors,
            "online_settings": asdict(self.session.settings),
        }

    def save(self, path: Path) -> Path:
        """The current snapshot as a model file (with the base model's memory beside it, so
        that ewc and replay can go on from it)."""
        net = self.snapshot.net
        out = save_model(
            path,
            GroundEffectNet(net.weights, net.biases, net.normaliser, self.session.adapted_header()),
        )
        source = self.session.memory.header.get("path") if self.session.memory else None
        if source and Path(source).exists():
            from learner.online.memory import memory_path_for

            target = memory_path_for(out)
            if Path(source).resolve() != target.resolve():
                shutil.copyfile(source, target)
        return out
