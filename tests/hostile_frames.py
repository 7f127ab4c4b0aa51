"""Hostile frames from a stranger (system 200): garbage, bad CRC, truncated, unknown ids,
commands for another system, out-of-range values. `python -m tests.hostile_frames PORT N S`
sends N of them to udp 127.0.0.1:PORT spread over about S seconds, from a process of its
own (a sender in the test's process would take turns with its receiver)."""

from __future__ import annotations

import os
import random
import socket
import struct
import sys
import threading
import time
from collections.abc import Iterator

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mav


def frames(seed: int = 7) -> Iterator[bytes]:
    rng = random.Random(seed)
    packer = mav.MAVLink(None, srcSystem=200, srcComponent=1)
    valid = [
        mav.MAVLink_command_long_message(42, 1, 400, 0, 0, 21196, 0, 0, 0, 0, 0),  # other system
        mav.MAVLink_command_long_message(1, 99, 400, 0, 0, 21196, 0, 0, 0, 0, 0),  # other comp
        mav.MAVLink_param_set_message(1, 1, b"MIS_TAKEOFF_ALT", 1e30, 9),  # out of range
        mav.MAVLink_param_set_message(1, 1, b"NO_SUCH_PARAM", 1.0, 9),
        mav.MAVLink_param_request_read_message(1, 1, b"", 30000),
        mav.MAVLink_mission_set_current_message(1, 1, 9999),
        mav.MAVLink_command_long_message(1, 1, 178, 0, 1, -5.0, 0, 0, 0, 0, 0),  # bad speed
        mav.MAVLink_set_position_target_local_ned_message(
            0, 1, 1, 1, 0, float("nan"), 1e30, 0, 0, 0, 0, 0, 0, 0, 0, 0
        ),
    ]
    n = 0
    while True:
        frame = bytearray(rng.choice(valid).pack(packer))
        kind = n % 5
        if kind == 0:
            frame = bytearray(rng.randbytes(rng.randint(1, 300)))
        elif kind == 1:
            frame[rng.randrange(10, len(frame))] ^= 0xFF  # bad CRC
        elif kind == 2:
            frame = frame[: rng.randrange(1, len(frame))]  # truncated
        elif kind == 3:  # an id outside the dialect, CRC as if it were known
            frame[7:10] = struct.pack("<I", 0x00FFF0 + rng.randrange(8))[:3]
        n += 1
        yield bytes(frame)


def flood(
    port: int, sent: list[int], stop: threading.Event, limit: int = 12_000, seconds: float = 0.0
) -> None:
    """Send up to `limit` frames, in bursts of 200, spread over `seconds` (0: as fast as about
    10^5 a second) or until `stop`."""
    pause_s = max(0.002, seconds * 200 / limit)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for frame in frames():
            if stop.is_set() or sent[0] >= limit:
                return
            sock.sendto(frame, ("127.0.0.1", port))
            sent[0] += 1
            if sent[0] % 200 == 0:
                time.sleep(pause_s)


if __name__ == "__main__":
    port, count, seconds = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
    sent = [0]
    flood(port, sent, threading.Event(), count, seconds)
    print(sent[0])
