"""`groundfx sim` as a process, driven by pymavlink clients over TCP on loopback."""

from __future__ import annotations

import contextlib
import math
import re
import signal
import socket
import struct
import subprocess
import time
from itertools import pairwise

import fastcrc
import numpy as np
import pytest
from pymavlink import mavextra, mavutil
from pymavlink.quaternion import Quaternion
from pymavlink.rotmat import Vector3

from simbridge.hil import mavlink
from simbridge.launch import finish
from tests.helpers import ideal_sensor_noise, wait_for

G = 9.81
START = {
    "xy_m": [0.5, -0.3],
    "altitude_m": 1.0,
    "roll_deg": 10.0,
    "pitch_deg": -5.0,
    "yaw_deg": 30.0,
}
ORIGIN = {"lat_deg": 47.397742, "lon_deg": 8.545594, "alt_m": 488.0}
HOVER_FRACTION = 75.8 / 140.0


def connect(port: int) -> mavutil.mavfile:
    conn = mavutil.mavlink_connection(
        f"tcp:127.0.0.1:{port}", dialect="ardupilotmega", autoreconnect=False
    )
    return conn


def answer(conn: mavutil.mavfile, sensor, controls4=(HOVER_FRACTION,) * 4, lockstep=True) -> None:
    controls = list(controls4) + [0.0] * 12
    conn.mav.hil_actuator_controls_send(
        sensor.time_usec, controls, mavlink.MAV_MODE_FLAG_SAFETY_ARMED, 1 if lockstep else 0
    )


def next_of(conn, kinds, seen):
    """The next message of one of `kinds`, recording every message type seen."""
    while True:
        msg = conn.recv_match(blocking=True, timeout=10)
        assert msg is not None, "the simulator went silent"
        seen[msg.get_type()] = seen.get(msg.get_type(), 0) + 1
        if msg.get_type() in kinds:
            return msg


def test_a_pymavlink_client_drives_1000_lockstep_steps(sim_process, write_world):
    world = write_world(
        {
            "origin": ORIGIN,
            "start": START,
            "effects": [{"name": "ground_effect", "rho": 1.0}],
            "sensor_noise": ideal_sensor_noise(),
        }
    )
    proc, port = sim_process(world)
    conn = connect(port)
    seen: dict[str, int] = {}

    # Before the first actuators the drone stands at its start pose: check what it reports.
    # the tick (HIL_SENSOR), then its truth
    sensor = next_of(conn, {"HIL_SENSOR"}, seen)
    state = next_of(conn, {"HIL_STATE_QUATERNION"}, seen)
    assert state.time_usec == sensor.time_usec
    # NED/FRD: roll keeps its sign, FLU pitch (+ nose down) flips, yaw from east becomes from north.
    expected_q = Quaternion([math.radians(10.0), math.radians(5.0), math.radians(90.0 - 30.0)])
    q = state.attitude_quaternion
    assert (
        min(
            max(abs(a - b) for a, b in zip(q, expected_q.q, strict=True)),
            max(abs(a + b) for a, b in zip(q, expected_q.q, strict=True)),
        )
        < 1e-6
    )
    # at rest, the accelerometer measures the reaction to gravity: R^T (0, 0, -g) in FRD
    expected_acc = expected_q.dcm.transposed() * Vector3(0.0, 0.0, -G)
    assert (sensor.xacc, sensor.yacc, sensor.zacc) == pytest.approx(
        (expected_acc.x, expected_acc.y, expected_acc.z), abs=1e-4
    )
    assert (sensor.xgyro, sensor.ygyro, sensor.zgyro) == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    lat, lon = mavextra.gps_offset(ORIGIN["lat_deg"], ORIGIN["lon_deg"], 0.5, -0.3)  # east, north
    assert state.lat == pytest.approx(lat * 1e7, abs=1) and state.lon == pytest.approx(
        lon * 1e7, abs=1
    )
    assert state.alt == round((ORIGIN["alt_m"] + 1.0) * 1000)
    assert sensor.pressure_alt == pytest.approx(ORIGIN["alt_m"] + 1.0, abs=1e-3)

    times = [sensor.time_usec]
    commands = (0.50, 0.55, 0.50, 0.55)
    answer(conn, sensor, commands)
    for _ in range(999):
        sensor = next_of(conn, {"HIL_SENSOR"}, seen)
        times.append(sensor.time_usec)
        answer(conn, sensor, commands)
    assert all(b > a for a, b in pairwise(times))  # strictly increasing
    assert {b - a for a, b in pairwise(times)} == {4000}
    # the last tick's truth follows it, whatever the autopilot answered
    assert next_of(conn, {"HIL_STATE_QUATERNION"}, seen).time_usec == times[-1]
    assert seen["HIL_STATE_QUATERNION"] == 1000
    assert 38 <= seen["HIL_GPS"] <= 42  # 10 Hz over 4 s
    assert 198 <= seen["DISTANCE_SENSOR"] <= 202  # 50 Hz
    assert 490 <= seen["ESC_TELEMETRY_1_TO_4"] <= 510  # 125 Hz
    esc = conn.recv_match(type="ESC_TELEMETRY_1_TO_4", blocking=True, timeout=5)
    assert list(esc.rpm) == [round(c * 140.0 * 60 / (2 * math.pi)) for c in commands]

    conn.close()
    last = finish(proc)
    assert proc.returncode == 0
    assert "autopilot disconnected; 1000 steps" in last
    assert "dropped 0 malformed and 0 unknown messages; clamped 0" in last


def frame(msgid: int, payload: bytes, crc_extra: int) -> bytes:
    header = struct.pack(
        "<BBBBBBBHB", 0xFD, len(payload), 0, 0, 0, 1, 1, msgid & 0xFFFF, msgid >> 16
    )
    return (
        header
        + payload
        + struct.pack("<H", fastcrc.crc16.mcrf4xx(header[1:] + payload + bytes([crc_extra])))
    )


def test_garbage_unknown_messages_and_bad_actuators_are_counted_and_survived(sim_process):
    proc, port = sim_process(start="0,0,1")
    conn = connect(port)
    seen: dict[str, int] = {}
    mav = mavlink.MAVLink(None, 1, 1)
    bad_steps = 20
    for step in range(100):
        sensor = next_of(conn, {"HIL_SENSOR"}, seen)
        if step < bad_steps:
            good = mavlink.MAVLink_hil_actuator_controls_message(
                sensor.time_usec, [math.nan, 1.5, -0.2, 0.5] + [0.0] * 12, 128, 1
            ).pack(mav)
            corrupted = bytearray(good)
            corrupted[20] ^= 0xFF
            conn.write(
                b"\x00\x01 not mavlink at all \x02\x03"
                + bytes(corrupted)
                + frame(60000, b"\x01\x02\x03", 0)
                + good
            )
        else:
            answer(conn, sensor)
    conn.close()
    last = finish(proc)
    assert proc.returncode == 0 and "autopilot disconnected; 100 steps" in last
    counts = re.search(r"dropped (\d+) malformed and (\d+) unknown messages; clamped (\d+)", last)
    malformed, unknown, clamped = (int(x) for x in counts.groups())
    assert malformed >= 2 * bad_steps and unknown >= bad_steps
    assert clamped == 3 * bad_steps  # NaN, 1.5 and -0.2 on each bad step


def test_a_stale_reply_is_dropped_and_the_current_one_awaited(sim_process):
    """A reply to an earlier step (one that arrived late) does not answer the current one:
    the simulator steps once, on the reply to the step it sent, whatever came before it."""
    proc, port = sim_process(lockstep_start=True, extra=["--timeout", "1"])
    conn = connect(port)
    seen: dict[str, int] = {}
    mav = mavlink.MAVLink(None, 1, 1)

    def reply(time_usec: int) -> bytes:
        controls = [HOVER_FRACTION] * 4 + [0.0] * 12
        message = mavlink.MAVLink_hil_actuator_controls_message(time_usec, controls, 128, 1)
        return message.pack(mav)

    sensor = next_of(conn, {"HIL_SENSOR"}, seen)
    answer(conn, sensor)
    times = [sensor.time_usec]
    for _ in range(20):  # a late reply to the step before, then this step's, in one write
        sensor = next_of(conn, {"HIL_SENSOR"}, seen)
        conn.write(reply(times[-1]) + reply(sensor.time_usec))
        times.append(sensor.time_usec)
    sensor = next_of(conn, {"HIL_SENSOR"}, seen)
    conn.write(reply(times[-1]))  # a late reply alone: the step is still unanswered
    last = finish(proc, timeout_s=10)
    assert {b - a for a, b in pairwise(times)} == {4000}  # never two steps on one tick
    assert sensor.time_usec == times[-1] + 4000
    assert proc.returncode == 1
    assert "no HIL_ACTUATOR_CONTROLS for 1 s; 21 steps" in last, last
    conn.close()


def test_a_silent_autopilot_ends_lockstep_after_the_timeout(sim_process):
    proc, port = sim_process(extra=["--timeout", "0.5"])
    conn = connect(port)
    seen: dict[str, int] = {}
    for _ in range(10):
        answer(conn, next_of(conn, {"HIL_SENSOR"}, seen))
    t0 = time.monotonic()
    last = finish(proc, timeout_s=10)
    assert time.monotonic() - t0 < 5
    assert proc.returncode == 1
    assert "no HIL_ACTUATOR_CONTROLS for 0.5 s; 10 steps" in last
    conn.close()


def test_with_lockstep_start_the_clock_waits_for_the_first_reply(sim_process):
    """`fly`'s flights: however late the autopilot's first reply (a starved start), the
    simulator has sent only the first state, so the flight is the same to the bit."""
    proc, port = sim_process(lockstep_start=True, speedup="1", extra=["--timeout", "1"])
    conn = connect(port)
    seen: dict[str, int] = {}
    first = next_of(conn, {"HIL_SENSOR"}, seen)
    last = finish(proc, timeout_s=10)  # never answered: the wait for the first reply ends
    while (msg := conn.recv_match(blocking=False)) is not None:  # all it sent before it ended
        seen[msg.get_type()] = seen.get(msg.get_type(), 0) + 1
    assert first.time_usec == 0 and seen["HIL_SENSOR"] == 1
    assert "no HIL_ACTUATOR_CONTROLS for 1 s; 0 steps" in last, last
    conn.close()


def test_free_running_without_the_lockstep_flag_does_not_wait(sim_process):
    proc, port = sim_process(start="0,0,1", speedup="10")
    conn = connect(port)
    seen: dict[str, int] = {}
    answer(conn, next_of(conn, {"HIL_SENSOR"}, seen), (0.3, 0.3, 0.3, 0.3), lockstep=False)
    times = [next_of(conn, {"HIL_SENSOR"}, seen).time_usec for _ in range(100)]  # never answered
    assert all(b > a for a, b in pairwise(times))
    esc = conn.recv_match(type="ESC_TELEMETRY_1_TO_4", blocking=True, timeout=5)
    assert list(esc.rpm) == [round(0.3 * 140 * 60 / (2 * math.pi))] * 4  # the last command holds
    conn.close()
    finish(proc)
    assert proc.returncode == 0


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_ends_the_simulator_cleanly_with_one_line(sim_process, sig):
    proc, port = sim_process()
    with socket.create_connection(("127.0.0.1", port)):
        time.sleep(0.2)  # the drone stands on its stand, sensors flowing, no actuators yet
        proc.send_signal(sig)
        try:
            out, err = proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:  # where it hangs, for the failure message
            proc.send_signal(signal.SIGUSR1)
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.communicate(timeout=2)
            proc.kill()
            out, err = proc.communicate()
            pytest.fail(f"the simulator did not end within 30 s of {sig.name}:\n{out}\n{err}")
    assert proc.returncode == 0, err
    lines = [ln for ln in out.splitlines() if ln.startswith("groundfx sim:")]
    assert lines[-1].startswith("groundfx sim: stopped by signal;")
    assert "Traceback" not in err


def test_an_autopilot_starved_before_its_first_reply_knows_it_is_behind_until_caught_up(
    sim_process,
):
    """Before the first reply the simulator streams ticks in real time; an autopilot that
    reads them late takes every one in order, `behind()` while more wait, then lockstep."""
    import fcntl
    import termios

    from autopilot.simlink import SimLink
    from simbridge.vehicle import load_vehicle

    proc, port = sim_process("default", speedup="1")
    link = SimLink(f"tcp:127.0.0.1:{port}", timeout_s=30.0)
    pending = struct.pack("i", 0)

    def waiting_bytes() -> int:
        return struct.unpack("i", fcntl.ioctl(link._sock, termios.FIONREAD, pending))[0]

    wait_for(lambda: waiting_bytes() > 10000, "a backlog of ticks", proc)  # tens of ticks
    channels = load_vehicle().actuator_channels
    times, behind = [], []
    for _ in range(400):
        times.append(link.receive_step().sensor["time_usec"])
        behind.append(link.behind())
        link.send(times[-1], (0.0, 0.0, 0.0, 0.0), channels, False)
        if len(behind) > 20 and not any(behind[-20:]):
            break
    link.close()
    assert sum(behind) >= 10 and behind[0]  # it knew it was working through a backlog
    assert not any(behind[-20:])  # and then caught up: one tick per reply
    assert np.all(np.diff(times) == 4000)  # every tick, in order, none skipped
