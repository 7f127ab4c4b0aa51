"""The lockstep link's sockets: TCP (the PX4 simulator protocol, for any autopilot) or a
Unix-domain stream socket (where both ends are ours: `groundfx fly`, the campaigns), with
the same MAVLink bytes on either.

Each side blocks in the kernel until its peer's message arrives: one `recv` with the wait
bounded by SO_RCVTIMEO, no polling loop and no Python timeout (which would make every read
a poll plus a non-blocking read). A waiting process then costs no CPU, so two flights' four
processes share two cores without taking turns at spinning.
"""

from __future__ import annotations

import contextlib
import os
import socket
import struct
import time
from collections.abc import Callable

TCP, UNIX = "tcp", "unix"
# How long either side waits for its lockstep peer by default. A slow peer (a loaded machine,
# a debugger, a stopped process) is waited for; a gone one closes its socket, which ends the
# wait at once. Only a peer silent this long, yet connected, is given up on.
PEER_SILENCE_S = 30.0


def parse_url(url: str, option: str = "--sim") -> tuple[str, str, int]:
    """`tcp:HOST:PORT` or `unix:PATH` into (kind, host or path, port; 0 for unix)."""
    kind, _, rest = url.partition(":")
    if kind == UNIX and rest:
        return UNIX, rest, 0
    host, _, port = rest.rpartition(":")
    if kind == TCP and host and port.isdigit():
        return TCP, host, int(port)
    raise ValueError(f"{option}: expected tcp:HOST:PORT or unix:PATH, got {url!r}")


def listen(kind: str, where: str, port: int = 0) -> socket.socket:
    """A listening socket for one peer; a stale Unix socket file at `where` is replaced."""
    if kind == UNIX:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(where)
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        s.bind(where)
    else:
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind((where, port))
    s.listen(1)
    return s


def connect(url: str, timeout_s: float, stop: Callable[[], bool] = lambda: False) -> socket.socket:
    """Connect to `url`, retrying while the peer is not yet listening (it may still be
    starting); raises ConnectionError after `timeout_s`, or at once once `stop()` is true
    (a signal, a launcher that saw the peer's process exit)."""
    kind, where, port = parse_url(url)
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            if kind == UNIX:
                s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                try:
                    s.connect(where)
                except OSError:
                    s.close()
                    raise
            else:
                s = socket.create_connection((where, port), timeout=timeout_s)
            break
        except (ConnectionRefusedError, FileNotFoundError):
            if time.monotonic() > deadline:
                raise ConnectionError(f"no simulator at {url}") from None
            if stop():
                raise ConnectionError(f"stopped while waiting for a simulator at {url}") from None
            time.sleep(0.02)
    return blocking(s)


def blocking(s: socket.socket) -> socket.socket:
    """Blocking mode, Nagle off on TCP: each message leaves at once and a read waits in the
    kernel (bounded by `set_recv_timeout`)."""
    s.settimeout(None)
    if s.family != socket.AF_UNIX:
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return s


def _timeval(timeout_s: float) -> bytes:
    seconds = int(timeout_s)
    return struct.pack("ll", seconds, max(1, int((timeout_s - seconds) * 1e6)))


def set_recv_timeout(s: socket.socket, timeout_s: float) -> None:
    """Bound every blocking read by `timeout_s` in the kernel: past it `recv` raises
    BlockingIOError (a subclass of OSError)."""
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, _timeval(timeout_s))


def set_send_timeout(s: socket.socket, timeout_s: float) -> None:
    """Likewise for writes: a peer that stops reading fails `sendall` after `timeout_s`."""
    s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, _timeval(timeout_s))


def recv_now(s: socket.socket) -> bytes | None:
    """What is already waiting, without blocking; None if nothing."""
    try:
        return s.recv(65536, socket.MSG_DONTWAIT)
    except (BlockingIOError, InterruptedError):
        return None
