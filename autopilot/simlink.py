"""The autopilot's end of the PX4 simulator protocol: a client of `tcp:HOST:PORT` or, where
the simulator is ours, `unix:PATH` (simbridge/transport.py: blocking reads, no polling).

Each step it reads the simulator's messages up to HIL_SENSOR (the tick) and answers with one
HIL_ACTUATOR_CONTROLS stamped with that tick's time and the lockstep flag. Malformed and
unknown messages are counted and dropped. A slow simulator (a loaded machine, a debugger, a
stopped process) is waited for: only a gone one ends the flight with `LinkLost`, whose message
says which way it went, a closed socket (the process exited) or silence beyond `timeout_s`.

Until the first reply the simulator streams its ticks at real-time pace (the vehicle on its
stand), so an autopilot starved after connecting (a busy machine) finds a backlog of ticks.
Every tick is still taken in order (the flight's rows stay those of an unstarved start), and
`behind()` says whether more are already waiting: the runner arms a reproducible flight only
once it has caught up, so that no take-off is commanded into replies the simulator drops as
stale. In lockstep there is never more than one tick waiting.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from autopilot.types import Step
from simbridge import transport
from simbridge.actuator_controls import ARMED_MODE, LOCKSTEP_FLAG
from simbridge.hil import mavlink
from simbridge.wire import FrameReader, PacketSequence, WirePacker

AUTOPILOT_SYSTEM_ID, AUTOPILOT_COMPONENT_ID = 1, 1
LOST = "lost the simulator link"  # how every mid-flight `LinkLost` message begins
DEFAULT_LINK_TIMEOUT_S = transport.PEER_SILENCE_S
# A wait for the simulator is cut in slices this long, so that a stop request is heard while a
# slow (or stopped) simulator is waited for; a step that arrives in time never sees one.
WAIT_SLICE_S = 0.25


class Stopped(Exception):
    """A stop was asked (a signal) while the simulator was waited for."""


class LinkLost(Exception):
    """The simulator link is gone; the message says how."""


def parse_url(url: str) -> None:
    """Refuses a `--sim` URL that is neither `tcp:HOST:PORT` nor `unix:PATH` (ValueError)."""
    transport.parse_url(url)


class SimLink:
    def __init__(
        self,
        url: str,
        timeout_s: float = DEFAULT_LINK_TIMEOUT_S,
        connect_timeout_s: float = 10.0,
        stop: Callable[[], bool] = lambda: False,
    ) -> None:
        try:
            self._sock = transport.connect(url, connect_timeout_s, stop)
        except ConnectionError as err:  # nothing listening until the connect timeout
            raise LinkLost(str(err)) from None
        except OSError as err:
            raise LinkLost(f"cannot reach the simulator at {url}: {err}") from None
        self._timeout_s = timeout_s
        # the first state may take longer: a simulator starved on a loaded machine (or an
        # outside one still building its world) is not a lost link
        self._first_timeout_s = max(timeout_s, connect_timeout_s)
        self._stop = stop
        transport.set_recv_timeout(self._sock, min(WAIT_SLICE_S, self._first_timeout_s))
        transport.set_send_timeout(self._sock, timeout_s)
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
        self.received = 0  # messages decoded
        self._replied = False  # a HIL_ACTUATOR_CONTROLS sent: from now on, lockstep

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
            if not self._decode_pending():
                self._read()

    def receive_truth(self, step: Step) -> None:
        """Read on to the truth of `step`'s tick: its HIL_STATE_QUATERNION (the end of the truth
        our simulator sends right after each tick), so that `step` holds that tick's truth.
        Called after the reply, off the control path, before the estimator's fusions: our
        simulator sends the tick's other sensors with its truth. A simulator that sends its
        truth before the tick (the PX4 order) has it there already; one that sends none ends
        the wait with its next tick, which is left for `receive_step`."""
        time_us = step.sensor["time_usec"]
        truth = self._latest.get("HIL_STATE_QUATERNION")
        if truth is not None and truth["time_usec"] >= time_us:
            return
        while not self._take(step):
            if not self._decode_pending():
                self._read()

    def _take(self, step: Step) -> bool:
        """Moves the queued frames of `step`'s tick into it; True once its truth is taken or
        the next tick is at the head of the queue (no truth came for this one)."""
        time_us = step.sensor["time_usec"]
        while self._queue:
            kind, fields = self._queue[0]
            if kind == "HIL_SENSOR":
                return True
            self._queue.pop(0)
            self._latest[kind] = fields
            step.new.add(kind)
            if kind == "HIL_STATE_QUATERNION" and fields["time_usec"] >= time_us:
                return True
        return False

    def rest_of_tick(self, step: Step) -> None:
        """`step`'s other sensors before the reply: for the estimator's alignment, which needs
        the tick's pose or fix. Read on to its truth where that cannot stall the lockstep:
        before the first reply (a simulator streams its ticks until then) or from a simulator
        that sends truth (ours sends the tick's other sensors with it); else what has
        arrived, without waiting."""
        if "HIL_STATE_QUATERNION" in self._latest or not self._replied:
            self.receive_truth(step)
        else:
            self._arrived(step)

    def _arrived(self, step: Step) -> None:
        """What has already arrived of `step`'s tick after its HIL_SENSOR (up to its truth),
        without waiting for more. The next tick is left for `receive_step`."""
        try:
            data = transport.recv_now(self._sock)
        except OSError:
            data = None  # the next receive reports it
        if data:
            self._queue_frames(data)
        while not self._take(step) and self._decode_pending():
            pass

    def _read(self) -> None:
        """One blocking read into the queue of decoded frames."""
        waited_s = 0.0
        while True:
            try:
                data = self._sock.recv(65536)  # blocking, bounded by SO_RCVTIMEO
                break
            except (BlockingIOError, TimeoutError):
                waited_s += WAIT_SLICE_S
                if self._stop():
                    raise Stopped from None
                if waited_s >= self._wait_s():
                    raise LinkLost(f"{LOST}: silent for {self._wait_s():g} s") from None
            except (ConnectionResetError, BrokenPipeError):
                # a peer killed with bytes unread resets rather than closes: gone all the same
                raise LinkLost(f"{LOST}: it closed the connection") from None
            except OSError as err:
                raise LinkLost(f"{LOST}: {(err.strerror or str(err)).lower()}") from None
        if not data:
            raise LinkLost(f"{LOST}: it closed the connection")
        self._queue_frames(data)

    def _queue_frames(self, data: bytes, stop_after: str | None = "HIL_SENSOR") -> None:
        """Decodes up to the first tick in `data` (on the control path, nothing after it is
        needed before the reply); the rest waits in the reader for `_decode_pending`."""
        frames = self._reader.feed(data, stop_after)
        self.received += len(frames)
        self._queue.extend(frames)

    def _decode_pending(self) -> bool:
        """Decodes what the reader holds back, up to the next tick; whether any frame came
        of it (if not, what it holds is a frame cut short: more must be read)."""
        if not self._reader.pending:
            return False
        queued = len(self._queue)
        self._queue_frames(b"")
        return len(self._queue) > queued

    def _wait_s(self) -> float:
        return self._timeout_s if self.received else self._first_timeout_s

    def behind(self) -> bool:
        """Whether another tick is already waiting: the autopilot is working through a
        backlog. What has arrived is read (without blocking) and looked through for a
        HIL_SENSOR; for the moments before arming only."""
        try:
            while (data := transport.recv_now(self._sock)) is not None:
                if not data:
                    break  # closed: the next receive reports it
                self._queue_frames(data, None)
        except OSError:
            pass  # the next receive reports it
        self._queue_frames(b"", None)  # and whatever an earlier read held back
        return any(kind == "HIL_SENSOR" for kind, _ in self._queue)

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
        self._replied = True
        try:
            self._sock.sendall(self._pack.pack(time_us, c, mode, LOCKSTEP_FLAG))
        except OSError:
            raise LinkLost(f"{LOST}: it closed the connection") from None

    def close(self) -> None:
        self._sock.close()
