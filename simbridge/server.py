"""The HIL link: a TCP server speaking the PX4 simulator protocol to one autopilot.

Lockstep (the autopilot sets HIL_ACTUATOR_CONTROLS.flags bit 0, as PX4 does): send the
sensors for time t, wait for exactly one HIL_ACTUATOR_CONTROLS, step physics to t + dt,
repeat; every wait is bounded. Free-running (no lockstep flag): step at `speedup` times real
time with the latest actuators. Until the first HIL_ACTUATOR_CONTROLS arrives the sensors
flow at real-time pace and the vehicle stands at its start pose, as on a stand, so an
autopilot that takes seconds to boot finds it where the world file put it.
"""

from __future__ import annotations

import contextlib
import os
import socket
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from simbridge import transport
from simbridge.actuator_controls import ActuatorCommand, decode_actuators
from simbridge.cpu_latency import CpuLatencyRequest
from simbridge.hil import HilEncoder, mavlink
from simbridge.physics import Simulation
from simbridge.vehicle import Vehicle
from simbridge.wire import FrameReader
from simbridge.world import World


@dataclass(frozen=True)
class ServerOptions:
    host: str = "127.0.0.1"
    port: int = 4560  # 0: an ephemeral port, printed when listening
    unix_path: str | None = None  # listen on this Unix-domain socket instead of TCP
    speedup: float | None = 1.0  # simulated seconds per wall second; None: as fast as possible
    timeout_s: float = transport.PEER_SILENCE_S  # longest wait for a reply in lockstep
    wait: bool = False  # after an autopilot leaves, wait for the next one (a fresh world)
    # Lockstep from the first tick: wait for the reply to the first state before stepping.
    # Flights are then the same to the bit however slowly the autopilot starts; PX4 needs its
    # clock running before it replies, so by default the clock runs in real time until then.
    lockstep_start: bool = False
    # As fast as possible, hold the kernel's CPU wake-up latency request while an autopilot
    # is served (simbridge/cpu_latency.py): lockstep then pays no halted-CPU wake-ups
    low_latency_idle: bool = True


# HIL_ACTUATOR_CONTROLS's payload in wire order (pymavlink's layout; tests check it):
# time_usec, flags, controls[16], mode
ACTUATORS = mavlink.MAVLink_hil_actuator_controls_message


@dataclass
class LinkCounters:
    steps: int = 0
    actuator_messages: int = 0
    malformed: int = 0  # bad CRC or framing
    unknown: int = 0  # message ids outside the dialect
    ignored: int = 0  # valid messages the simulator has no use for
    clamped: int = 0  # actuator values NaN or outside [0, 1]
    stale: int = 0  # lockstep replies to an earlier step than the last one sent


class LinkEnded(Exception):
    """The run is over; the message says why in one line. A timeout is not a clean end."""

    def __init__(self, reason: str, clean: bool = True) -> None:
        super().__init__(reason)
        self.clean = clean


class SimServer:
    def __init__(
        self,
        world: World,
        vehicle: Vehicle,
        options: ServerOptions,
        say: Callable[[str], None] = print,
    ) -> None:
        self.world, self.vehicle, self.options, self.say = world, vehicle, options, say
        self.counters = LinkCounters()
        self._reader = FrameReader(mavlink)
        self._recv_timeout_s = 0.0  # the SO_RCVTIMEO now set on the connection
        self._listener: socket.socket | None = None
        self.sim_time_s = 0.0
        self.wall_s = 0.0
        self._request: CpuLatencyRequest | None = None  # this run's wake-up latency request

    def listen(self) -> str:
        """Bind and listen; returns the URL an autopilot connects to (`tcp:HOST:PORT`, the
        port chosen with port 0, or `unix:PATH`)."""
        o = self.options
        if o.unix_path is not None:
            self._listener = transport.listen(transport.UNIX, o.unix_path)
            return f"unix:{o.unix_path}"
        self._listener = transport.listen(transport.TCP, o.host, o.port)
        return f"tcp:{o.host}:{self._listener.getsockname()[1]}"

    def serve(self, on_end: Callable[[LinkEnded], None] | None = None) -> LinkEnded:
        """Serve one autopilot (or, with `wait`, one after another, each in a fresh world)
        until it leaves or a wait times out; returns why the last run ended."""
        if self._listener is None:
            self.listen()
        assert self._listener is not None
        try:
            while True:
                # the world is built before the autopilot connects: its first state goes out
                # at once (building it can take seconds on a loaded machine)
                with Simulation(self.world, self.vehicle, held=True) as sim:
                    conn, _ = self._listener.accept()
                    transport.blocking(conn)
                    transport.set_send_timeout(conn, self.options.timeout_s)
                    self._recv_timeout_s = 0.0
                    self.counters, self._reader = LinkCounters(), FrameReader(mavlink)
                    try:
                        with self._latency_request():
                            self._run(conn, sim)
                    except LinkEnded as end:
                        if not self.options.wait:
                            return end
                        if on_end is not None:
                            on_end(end)
                    finally:
                        conn.close()
        finally:
            self._listener.close()
            if self.options.unix_path is not None:
                with contextlib.suppress(OSError):
                    os.unlink(self.options.unix_path)

    def _latency_request(self) -> CpuLatencyRequest:
        """The wake-up latency request for one autopilot's run: asked for only as fast as
        possible (a paced run waits on its clock anyway) and unless declined."""
        o = self.options
        declined = "" if o.low_latency_idle else "declined"
        why = "a paced run" if o.speedup is not None else declined
        self._request = CpuLatencyRequest(0, not_asked=why)
        return self._request

    def summary(self, reason: str) -> str:
        c = self.counters
        rtf = self.sim_time_s / self.wall_s if self.wall_s > 0 else 0.0
        latency = f"; {self._request.describe()}" if self._request is not None else ""
        return (
            f"{reason}; {c.steps} steps, {self.sim_time_s:.3f} s simulated in {self.wall_s:.2f} s "
            f"wall ({rtf:.1f}x real time); dropped {c.malformed} malformed and {c.unknown} unknown "
            f"messages; clamped {c.clamped} actuator values{latency}"
        )

    # -- the loop -------------------------------------------------------------------------

    def _run(self, conn: socket.socket, sim: Simulation) -> None:
        world, options = self.world, self.options
        encoder = HilEncoder(world, self.vehicle)
        command: ActuatorCommand | None = None
        period = world.control_period_s
        wall0 = pace0 = time.perf_counter()
        try:
            self._send_step(conn, encoder, sim, with_forces=False)
            while True:
                if command is None:  # before the first actuators: real-time pace, no waiting
                    if options.lockstep_start:
                        command = self._receive(conn, options.timeout_s, True)
                    else:
                        command = self._receive(conn, period, False)
                    if command is not None:
                        sim.release()
                        pace0 = time.perf_counter() - sim.time_s / (options.speedup or 1.0)
                elif command.lockstep:
                    command = self._receive(conn, options.timeout_s, True, sim.time_us) or command
                else:
                    command = self._receive(conn, 0.0, False) or command
                sim.step(command.rotor_speeds_rad_s if command else (0.0, 0.0, 0.0, 0.0))
                self.counters.steps += 1
                self.sim_time_s = sim.time_s
                if options.speedup is not None and command is not None:
                    lag = pace0 + sim.time_s / options.speedup - time.perf_counter()
                    if lag > 0.0:
                        time.sleep(lag)
                self._send_step(conn, encoder, sim, with_forces=True)
        finally:
            self.wall_s = time.perf_counter() - wall0

    def _send_step(
        self, conn: socket.socket, encoder: HilEncoder, sim: Simulation, *, with_forces: bool
    ) -> None:
        """One step's messages: the tick (HIL_SENSOR), then in a second send the step's other
        sensors and its truth, encoded while the autopilot computes its reply (an autopilot
        answers HIL_SENSOR and takes the rest as it comes; ours reads it after its reply)."""
        self._send(conn, encoder.tick(sim.state(), sim.time_us))
        forces = sim.ground_effect_n if with_forces else None
        self._send(conn, encoder.truth(sim.time_us, forces))

    def _send(self, conn: socket.socket, data: bytes) -> None:
        try:
            conn.sendall(data)  # blocking; SO_SNDTIMEO bounds a peer that stops reading
        except OSError:
            raise LinkEnded("autopilot disconnected") from None

    def _receive(
        self, conn: socket.socket, wait_s: float, required: bool, not_before_us: int = 0
    ) -> ActuatorCommand | None:
        """The latest HIL_ACTUATOR_CONTROLS answering a step at or after `not_before_us`,
        within `wait_s` (0: only what has already arrived); counts and drops everything
        else, stale replies included (a reply that arrives a step late must not leave the
        autopilot one step behind for good). The wait is a blocking read in the kernel."""
        deadline = time.perf_counter() + wait_s
        first = True
        while True:
            try:
                if wait_s <= 0.0:
                    data = transport.recv_now(conn)
                    if data is None:
                        return None
                else:
                    # the kernel's bound: the whole wait, then (after a part of a message)
                    # what is left of it; set only when it changes
                    bound = wait_s if first else deadline - time.perf_counter()
                    if bound <= 0.0:
                        return self._timed_out(wait_s, required)
                    if (bound != self._recv_timeout_s) if first else (bound < self._recv_timeout_s):
                        transport.set_recv_timeout(conn, bound)
                        self._recv_timeout_s = bound
                    first = False
                    data = conn.recv(65536)
            except (BlockingIOError, TimeoutError):
                return self._timed_out(wait_s, required)
            except OSError:
                raise LinkEnded("autopilot disconnected") from None
            if not data:
                raise LinkEnded("autopilot disconnected")
            command = self._parse(data, not_before_us)
            if command is not None:
                return command

    @staticmethod
    def _timed_out(wait_s: float, required: bool) -> None:
        if required:
            raise LinkEnded(f"no HIL_ACTUATOR_CONTROLS for {wait_s:g} s", clean=False)
        return None

    def _parse(self, data: bytes, not_before_us: int) -> ActuatorCommand | None:
        c, reader = self.counters, self._reader
        values = reader.lone(data, ACTUATORS.id)
        if values is not None:  # the usual reply: one whole frame, its values in wire order
            return self._taken(values[0], values[2:18], values[18], values[1], not_before_us)
        latest = None
        for kind, fields in reader.feed(data):
            if kind != "HIL_ACTUATOR_CONTROLS":
                c.ignored += 1
                continue
            command = self._taken(
                fields["time_usec"], fields["controls"], fields["mode"], fields["flags"],
                not_before_us,
            )  # fmt: skip
            if command is not None:  # the latest reply that is not stale
                latest = command
        c.malformed, c.unknown = reader.malformed, reader.unknown
        return latest

    def _taken(
        self, time_us: int, controls: Sequence[float], mode: int, flags: int, not_before_us: int
    ) -> ActuatorCommand | None:
        """One reply decoded and counted; None if it answers a step before `not_before_us`."""
        c = self.counters
        command = decode_actuators(time_us, controls, mode, flags, self.vehicle)
        c.actuator_messages += 1
        c.clamped += command.clamped
        if command.time_us < not_before_us:
            c.stale += 1
            return None
        return command
