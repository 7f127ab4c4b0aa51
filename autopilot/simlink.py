"""The autopilot's end of the PX4 simulator protocol: a TCP client (`tcp:HOST:PORT`).

Each step it reads the simulator's messages up to HIL_SENSOR (the tick) and answers with one
HIL_ACTUATOR_CONTROLS stamped with that tick's time and the lockstep flag. Malformed and
unknown messages are counted and dropped; a closed socket or a silent simulator ends the
flight with `LinkLost`.

Until the first reply the simulator streams its ticks at real-time pace (the vehicle on its
stand), so an autopilot starved after connecting (a busy machine) finds a backlog of ticks.
Every tick is still taken in order (the flight's rows stay those of an unstarved start), and
`behind()` says whether more are already waiting: the runner arms a reproducible flight only
once it has caught up, so that no take-off is commanded into replies the simulator drops as
stale. In lockstep there is never more than one tick waiting.
"""

from __future__ import annotations

import socket
import time
from dataclasses import dataclass, field
from typing import Any

from simbridge.hil import ARMED_MODE, LOCKSTEP_FLAG, mavlink
from simbridge.spin import SpinPolicy
from simbridge.wire import FrameReader, PacketSequence, WirePacker

AUTOPILOT_SYSTEM_ID, AUTOPILOT_COMPONENT_ID = 1, 1


class LinkLost(Exception):
    """The simulator link is gone; the message says how."""


def parse_url(url: str) -> tuple[str, int]:
    """`tcp:HOST:PORT` (pymavlink style) into (host, port)."""
    parts = url.split(":")
    if len(parts) != 3 or parts[0] != "tcp" or not parts[2].isdigit():
        raise ValueError(f"--sim: expected tcp:HOST:PORT, got {url!r}")
    return parts[1], int(parts[2])


@dataclass
class Step:
    """The latest message of each kind, as fields, when a HIL_SENSOR closed the step."""

    sensor: dict[str, Any]
    latest: dict[str, dict[str, Any]] = field(default_factory=dict)
    new: set[str] = field(default_factory=set)  # kinds that arrived during this step


class SimLink:
    def __init__(self, url: str, timeout_s: float = 1.0, connect_timeout_s: float = 10.0) -> None:
        host, port = parse_url(url)
        deadline = time.monotonic() + connect_timeout_s
        while True:
            try:
                self._sock = socket.create_connection((host, port), timeout=connect_timeout_s)
                break
            except ConnectionRefusedError:
                if time.monotonic() > deadline:
                    raise LinkLost(f"no simulator at {url}") from None
                time.sleep(0.05)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock.settimeout(timeout_s)
        self._timeout_s = timeout_s
        # the first state may take longer: a simulator starved on a loaded machine (or an
        # outside one still building its world) is not a lost link
        self._first_timeout_s = max(timeout_s, connect_timeout_s)
        self._reader = FrameReader(mavlink)
        self._queue: list[tuple[str, dict[str, Any]]] = []
        self._latest: dict[str, dict[str, Any]] = {}
        self._pack = WirePacker(
            mavlink.MAVLink_hil_actuator_controls_message,
            AUTOPILOT_SYSTEM_ID,
            AUTOPILOT_COMPONENT_ID,
            PacketSequence(),
        )
        self._controls = [0.0] * 16
        self._spin = SpinPolicy()
        self.received = 0  # messages decoded

    @property
    def malformed(self) -> int:
        return self._reader.malformed

    @property
    def unknown(self) -> int:
        return self._reader.unknown

    def counters(self) -> tuple[int, int, int]:
        """(received, dropped, rejected) for the recording: dropped are the malformed and the
        unknown; the simulator link rejects nothing it can decode."""
        return (self.received, self._reader.malformed + self._reader.unknown, 0)

    def receive_step(self) -> Step:
        new: set[str] = set()
        while True:
            while self._queue:
                kind, fields = self._queue.pop(0)
                self._latest[kind] = fields
                new.add(kind)
                if kind == "HIL_SENSOR":
                    return Step(fields, self._latest, new)
            data = self._poll()
            try:
                if data is None:
                    self._sock.settimeout(self._wait_s())
                    data = self._sock.recv(65536)
            except TimeoutError:
                raise LinkLost(
                    f"lost the simulator link: no data for {self._wait_s():g} s"
                ) from None
            except OSError as err:
                raise LinkLost(
                    f"lost the simulator link: {(err.strerror or str(err)).lower()}"
                ) from None
            if not data:
                raise LinkLost("lost the simulator link: it closed the connection")
            frames = self._reader.feed(data)
            self.received += len(frames)
            self._queue.extend(frames)

    def _wait_s(self) -> float:
        return self._timeout_s if self.received else self._first_timeout_s

    def behind(self) -> bool:
        """Whether another tick is already waiting (received, or in the socket): the autopilot
        is working through a backlog. A peek, for the moments before arming only."""
        if any(kind == "HIL_SENSOR" for kind, _ in self._queue):
            return True
        self._sock.setblocking(False)  # with a timeout set, recv would wait for data first
        try:
            return bool(self._sock.recv(1, socket.MSG_PEEK))
        except (BlockingIOError, InterruptedError):
            return False
        except OSError:
            return False  # the next receive reports it

    def _poll(self) -> bytes | None:
        """Busy-poll briefly before sleeping in the kernel, on an otherwise idle machine only
        (simbridge/spin.py): the simulator's step takes about 100 us."""
        spin_s = self._spin.spin_s()
        if not spin_s:
            return None
        sock = self._sock
        sock.setblocking(False)
        end = time.perf_counter() + spin_s
        while time.perf_counter() < end:
            try:
                return sock.recv(65536)
            except BlockingIOError:
                continue
            except OSError:
                return None  # the blocking receive reports it
        return None

    def send(
        self,
        time_us: int,
        controls: tuple[float, float, float, float],
        channels: tuple[int, ...],
        armed: bool,
    ) -> None:
        c = self._controls
        for value, ch in zip(controls, channels, strict=True):
            c[ch] = value
        mode = ARMED_MODE if armed else 0
        try:
            self._sock.settimeout(self._timeout_s)
            self._sock.sendall(self._pack.pack(time_us, c, mode, LOCKSTEP_FLAG))
        except OSError:
            raise LinkLost("lost the simulator link: it closed the connection") from None

    def close(self) -> None:
        self._sock.close()
