"""A minimal lockstep client of the simulator: pymavlink's parser over a plain TCP socket.

It answers every HIL_SENSOR with one HIL_ACTUATOR_CONTROLS from a policy (time, state) ->
normalised rotor commands. The benchmark and the simulator demo use it; the autopilot is
the real client.
"""

from __future__ import annotations

import math
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from simbridge.actuator_controls import ARMED_MODE, LOCKSTEP_FLAG
from simbridge.hil import mavlink

Policy = Callable[[int, "ClientView"], tuple[float, float, float, float]]


@dataclass
class ClientView:
    """The latest messages of each kind the client has seen, and its parser (with what it
    holds of a frame cut short): a loop run in parts with one view reads every frame."""

    latest: dict[str, object] = field(default_factory=dict)
    parser: mavlink.MAVLink = field(default_factory=lambda: mavlink.MAVLink(None))


def connect(host: str, port: int, timeout_s: float = 10.0) -> socket.socket:
    """Connect, retrying while the simulator is still starting."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            s = socket.create_connection((host, port), timeout=timeout_s)
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            return s
        except ConnectionRefusedError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)


def run_lockstep(
    sock: socket.socket,
    steps: int,
    policy: Policy,
    view: ClientView | None = None,
) -> ClientView:
    """Answer `steps` HIL_SENSOR messages, then return (the caller closes the socket)."""
    view = view or ClientView()
    parser = view.parser
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    controls = [0.0] * 16
    answered = 0
    while answered < steps:
        data = sock.recv(65536)
        if not data:
            break
        for msg in parser.parse_buffer(data) or ():
            kind = msg.get_type()
            view.latest[kind] = msg
            if kind != "HIL_SENSOR":
                continue
            controls[0:4] = policy(msg.time_usec, view)
            sock.sendall(
                mavlink.MAVLink_hil_actuator_controls_message(
                    msg.time_usec, controls, ARMED_MODE, LOCKSTEP_FLAG
                ).pack(mav)
            )
            answered += 1
    return view


def end_lockstep(sock: socket.socket, timeout_s: float = 10.0) -> None:
    """Tell the simulator this client is done (its write side shut) and read until the
    simulator closes: it then takes every reply before it ends. Closed at once, the socket
    could refuse the simulator's send of the last step's truth first (a Unix-domain socket
    does so at once), and the simulator would end a step short of the replies."""
    try:
        sock.shutdown(socket.SHUT_WR)
        sock.settimeout(timeout_s)
        while sock.recv(65536):
            pass
    except OSError:
        pass  # gone already, or silent past the timeout: the caller closes it either way


def constant(value: float) -> Policy:
    """The same normalised command on every rotor."""
    return lambda _t, _v: (value, value, value, value)


def hover_fraction(hover_rad_s: float, max_rad_s: float) -> float:
    return min(1.0, math.fabs(hover_rad_s / max_rad_s))
