"""The online learner's arithmetic, in a process of its own.

Why a process: CPython runs one thread's bytecode at a time. Computed on a thread of the
autopilot, an update (hundreds of small array operations, each holding the interpreter)
kept the control loop waiting: in lockstep at full speed the loop ran at 0.40 of its
learner-off rate and its p99 step latency rose 2.9-fold. In a process of its own the update
runs beside the loop, which never shares an interpreter with it. The process is started
with `spawn` (a fork of a threaded autopilot could inherit a lock held by another thread),
runs at a lower priority than the loop, and keeps to one core (the last), so that the
scheduler can keep the loop's processes on the others instead of sharing every core with
the learner's bursts.

Protocol over one duplex pipe (pickled tuples). Parent to learner: ("samples", rows),
("reset", t_s), ("configure", settings), ("close",). Learner to parent: ("ready",),
("snapshot", version, weights, biases, t_s, loss, basis, verdict), ("rejected", t_s, loss,
verdict), ("reset", version, t_s), ("error", text) and, last, ("summary", counts,
reject_reasons, last_loss, held_evidence).
A row is t, the 12 features, the 3 targets, the position loop's vertical composite error
(`composite`'s tracking term). The count of samples taken off the pipe is a
shared integer (`taken`), which the loop's side reads to bound the queue without a message
per chunk.
"""

from __future__ import annotations

import contextlib
import os
from multiprocessing.connection import Connection
from typing import Any

ROW_TIME, ROW_FEATURES, ROW_TARGETS, ROW_TRACKING = 0, slice(1, 13), slice(13, 16), 16
ROW_WIDTH = 17
NICE = 15  # low: the loop and the simulator first; on its own core it still keeps up


def learner_main(
    conn: Connection, taken: Any, base: Any, settings: Any, memory: Any, offline: Any
) -> None:  # pragma: no cover - runs in the child; tests drive it through OnlineLearner
    with contextlib.suppress(OSError):
        os.nice(NICE)
    with contextlib.suppress(OSError, AttributeError):  # not every system has affinity
        cpus = sorted(os.sched_getaffinity(0))
        if len(cpus) > 1:
            os.sched_setaffinity(0, {cpus[-1]})  # one core: the scheduler moves the loop off it
    from learner.online.session import OnlineSession  # numpy only: up in a fraction of a second

    try:
        session = OnlineSession(base, settings, memory, offline)
        session.warm_up()
    except Exception as err:  # a bad model or setting: say so, end cleanly
        conn.send(("error", f"learner did not start: {err}"))
        conn.send(("summary", {}, {}, None, None, None))
        return
    if session.snapshot.version > 0:  # composite starts on its home ground: publish it
        net = session.snapshot.net
        conn.send(("snapshot", 1, net.weights, net.biases, 0.0, None, net.header.get("basis"), ""))
    conn.send(("ready",))
    while True:
        try:
            message = conn.recv()
        except EOFError:  # the autopilot is gone
            return
        kind = message[0]
        if kind == "samples":
            rows = message[1]
            taken.value += len(rows)  # shared memory: no message, no wake-up of the loop's side
            events = session.add_many(
                rows[:, ROW_FEATURES],
                rows[:, ROW_TARGETS],
                rows[:, ROW_TIME],
                rows[:, ROW_TRACKING],
            )
            for t_s, snapshot, loss, verdict in events:
                if snapshot is None:
                    conn.send(("rejected", t_s, loss, verdict))
                else:
                    net = snapshot.net
                    basis = net.header.get("basis")  # composite: the grounds, for --save-model
                    conn.send(
                        (
                            "snapshot",
                            snapshot.version,
                            net.weights,
                            net.biases,
                            t_s,
                            snapshot.loss,
                            basis,
                            verdict,
                        )
                    )
        elif kind == "reset":
            snapshot = session.reset(message[1])
            conn.send(("reset", snapshot.version, message[1]))
        elif kind == "configure":
            try:
                session.configure(message[1])
            except Exception as err:  # a bad setting must not end learning
                conn.send(("error", f"configure: {err}"))
        elif kind == "close":
            conn.send(
                (
                    "summary", dict(session.counts), dict(session.reject_reasons),
                    session.last_loss, session.held_evidence(), session.known_grounds(),
                )
            )  # fmt: skip
            conn.close()
            os._exit(0)  # nothing left to keep: skip tearing torch down (about a second)
