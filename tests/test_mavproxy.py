"""Acceptance with MAVProxy 1.8.75 as a real client (headless, commands on standard input)
over loopback UDP: it loads the square as a WPL file and flies it under both identities
(tests/client_vehicle.py).
"""

from __future__ import annotations

import contextlib
import os
import queue
import re
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mav

from autopilot.identity import identity_named
from tests.client_vehicle import (
    EXAMPLES,
    FLIGHT_WALL_S,
    IDENTITIES,
    LANDED_WITHIN_M,
    LANDING_ACCEPTANCE_M,
    free_udp_port,
    vehicle,
)

__all__ = ["vehicle"]  # the fixture, used by name


class MavProxy:
    """MAVProxy 1.8.75 as a process, its console on a pipe: commands in, lines out."""

    def __init__(self, master_port: int, forward_port: int, workdir: Path) -> None:
        command = [
            sys.executable, str(Path(sys.executable).parent / "mavproxy.py"),
            "--master", f"udpin:127.0.0.1:{master_port}",
            "--out", f"udpout:127.0.0.1:{forward_port}", "--no-state",
        ]  # fmt: skip
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        self.proc = subprocess.Popen(
            command,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env=env,
            cwd=workdir,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.transcript: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.rstrip())

    def send(self, command: str) -> None:
        assert self.proc.stdin is not None
        self.transcript.append(f">>> {command}")
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()

    def expect(
        self, ok: Callable[[str], bool], what: str, timeout_s: float = 15.0, fail: bool = True
    ) -> str | None:
        """The first new console line that is `ok` (MAVProxy prefixes some with a prompt);
        None after `timeout_s` if not `fail`."""
        end = time.monotonic() + timeout_s
        while (left := end - time.monotonic()) > 0:
            try:
                line = self.lines.get(timeout=min(left, 0.2))
            except queue.Empty:
                if self.proc.poll() is not None:
                    break
                continue
            self.transcript.append(line)
            if ok(line.split("> ")[-1].strip()):
                return line
        if not fail:
            return None
        tail = "\n".join(self.transcript[-25:])
        raise AssertionError(f"MAVProxy: no {what} within {timeout_s:g} s; console:\n{tail}")

    def ask_until(
        self, command: str, ok: Callable[[str], bool], what: str, timeout_s: float = 10.0
    ) -> str:
        """Send `command` every half second until a line answering it is `ok`."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            self.send(command)
            line = self.expect(ok, what, 0.5, fail=False)
            if line is not None:
                return line
        tail = "\n".join(self.transcript[-25:])
        raise AssertionError(f"MAVProxy: no {what} within {timeout_s:g} s; console:\n{tail}")

    def close(self) -> None:
        """End of input ends MAVProxy's console and MAVProxy."""
        with contextlib.suppress(OSError):
            assert self.proc.stdin is not None
            self.proc.stdin.close()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


class Listener:
    """What MAVProxy forwards on its `--out`: the items reached, as MAVProxy saw them."""

    def __init__(self) -> None:
        self.link = mavutil.mavlink_connection("udpin:127.0.0.1:0")
        self.port = self.link.port.getsockname()[1]
        self.reached: list[int] = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.stop.is_set():
            m = self.link.recv_match(type="MISSION_ITEM_REACHED", blocking=True, timeout=0.2)
            if m is not None:
                self.reached.append(m.seq)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=5)
        self.link.close()


def param_value(line: str, name: str) -> float | None:
    """`name`'s value in a `param show` line; None for any other line. MAVProxy may print
    its prompt right after the value, before the line's end ("NAV_ACC_RAD 0.02LOITER>")."""
    m = re.match(rf"{name}\s+(-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?)", line)
    return float(m[1]) if m else None


@pytest.mark.parametrize("identity", IDENTITIES)
def test_mavproxy_loads_the_wpl_file_arms_starts_it_and_sees_every_item_reached(
    vehicle, identity, tmp_path
):
    master_port = free_udp_port()
    listener = Listener()
    flight = vehicle(identity, f"udpout:127.0.0.1:{master_port}")
    mavproxy = MavProxy(master_port, listener.port, tmp_path)
    t0 = time.monotonic()
    try:
        mavproxy.expect(lambda s: s.startswith("Detected vehicle 1:1"), "vehicle detected")
        mavproxy.expect(lambda s: re.fullmatch(r"Received \d+ parameters", s), "parameters")
        mavproxy.send(f"param set NAV_ACC_RAD {LANDING_ACCEPTANCE_M}")
        mavproxy.ask_until(  # the set is queued: its PARAM_VALUE reply updates the cache
            "param show NAV_ACC_RAD",
            lambda s: param_value(s, "NAV_ACC_RAD") == pytest.approx(LANDING_ACCEPTANCE_M),
            f"NAV_ACC_RAD {LANDING_ACCEPTANCE_M} from the vehicle",
        )
        mavproxy.send(f"wp load {EXAMPLES / 'square.waypoints'}")
        mavproxy.expect(lambda s: s == "Sent all 9 waypoints", "mission sent")
        mavproxy.expect(lambda s: s == "Got MISSION_ACK: TYPE_MISSION: ACCEPTED", "mission ack")
        mavproxy.send("arm throttle")
        mavproxy.expect(lambda s: s == "ARMED", "arming")
        if identity_named(identity).autopilot == mav.MAV_AUTOPILOT_ARDUPILOTMEGA:
            mavproxy.send("mode AUTO")
            mavproxy.expect(lambda s: s == "Mode AUTO", "AUTO mode")
        else:  # `mode AUTO` means nothing under PX4: AUTO.MISSION by number
            mavproxy.send("long DO_SET_MODE 1 4 4")
            mavproxy.expect(
                lambda s: s == "Got COMMAND_ACK: DO_SET_MODE: ACCEPTED", "mission mode ack"
            )
        mavproxy.expect(lambda s: s == "DISARMED", "disarm after landing", FLIGHT_WALL_S)
        wall = time.monotonic() - t0
        summary = flight.summary()
    finally:
        mavproxy.close()
        listener.close()
    # MAVProxy uploads the file's row 0, home, as item 0: ArduCopter keeps it as home; PX4
    # flies it, and it is reached on the ground, where the vehicle stands.
    expected = list(range(1 if identity_named(identity).home_is_item_0 else 0, 9))
    assert listener.reached == expected, "\n".join(mavproxy.transcript[-40:])
    assert summary["landed"] and summary["landing_error_m"] < LANDED_WITHIN_M, summary
    assert summary["mission_items"] == 9
    print(f"MAVProxy {identity}: {wall:.1f} s wall, {summary['sim_s']:.1f} s simulated")
