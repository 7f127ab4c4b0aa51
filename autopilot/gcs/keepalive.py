"""Heartbeats on the wall clock, whatever the flight loop is doing.

The flight loop sends telemetry on simulated time, between control steps. A step that
stalls (a slow simulator waited for, a flood of frames to parse, a machine under load) would
silence the link: MAVSDK and QGroundControl call a vehicle lost after about 3 s without a
heartbeat. This thread sends the newest heartbeat again whenever none has gone out for a
period of wall time; while the loop keeps up, it never has to.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

HEARTBEAT_PERIOD_S = 1.0  # what ground stations expect (MAVLink: 1 Hz)
CHECK_INTERVAL_S = 0.1


class Keepalive:
    """Calls `resend()` (which sends the newest heartbeat, if any, and returns whether it did)
    when `last_sent_s()` is a heartbeat period or more in the past."""

    def __init__(
        self,
        last_sent_s: Callable[[], float | None],
        resend: Callable[[float], bool],
        period_s: float = HEARTBEAT_PERIOD_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._last_sent_s, self._resend = last_sent_s, resend
        self.period_s, self._clock = period_s, clock
        self.resent = 0  # heartbeats this thread sent: how often the loop fell behind
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="gcs-keepalive", daemon=True)

    def start(self) -> Keepalive:
        self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(CHECK_INTERVAL_S):
            last = self._last_sent_s()
            now = self._clock()
            if last is not None and now - last >= self.period_s and self._resend(now):
                self.resent += 1

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
