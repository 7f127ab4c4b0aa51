"""The lean packer writes exactly pymavlink's bytes; the fast decoder agrees with pymavlink."""

from __future__ import annotations

import math

import pytest

from simbridge.hil import mavlink
from simbridge.wire import PacketSequence, WirePacker, WireUnpacker

CASES = [
    (
        mavlink.MAVLink_hil_sensor_message,
        (
            123456789,
            0.1,
            -0.2,
            -9.81,
            0.01,
            0.02,
            -0.03,
            0.2,
            0.0,
            0.4,
            1010.0,
            0.0,
            28.5,
            14.8,
            0x1FFF,
            0,
        ),
    ),
    (
        mavlink.MAVLink_hil_state_quaternion_message,
        (
            42,
            [0.9, 0.1, -0.2, 0.3],
            0.1,
            0.2,
            0.3,
            593498000,
            180707000,
            29000,
            -12,
            5,
            300,
            100,
            100,
            10,
            -20,
            -1000,
        ),
    ),
    (
        mavlink.MAVLink_odometry_message,
        (
            7,
            1,
            12,
            1.0,
            2.0,
            -3.0,
            [1.0, 0.0, 0.0, 0.0],
            0.1,
            0.2,
            0.3,
            0.0,
            0.0,
            0.5,
            [math.nan] + [0.0] * 20,
            [math.nan] + [0.0] * 20,
            0,
            6,
            100,
        ),
    ),
    (
        mavlink.MAVLink_distance_sensor_message,
        (1234, 1, 400, 37, 0, 0, 25, 0, 0.0, 0.0, [0.0] * 4, 0),
    ),
    (
        mavlink.MAVLink_esc_telemetry_1_to_4_message,
        ([0] * 4, [0] * 4, [0] * 4, [0] * 4, [724, 730, 0, 12], [5] * 4),
    ),
    (
        mavlink.MAVLink_hil_gps_message,
        (99, 3, 593498000, 180707000, 28000, 100, 100, 0, 0, 0, 0, 65535, 12, 0, 0),
    ),
    (
        mavlink.MAVLink_hil_actuator_controls_message,
        (4000, [0.5, 0.25, 0.0, 1.0] + [0.0] * 12, 128, 1),
    ),
]


@pytest.mark.parametrize(("cls", "values"), CASES, ids=[c[0].msgname for c in CASES])
def test_packer_writes_pymavlink_bytes(cls, values):
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    seq = PacketSequence()
    packer = WirePacker(cls, 1, 191, seq)
    for _ in range(3):  # the sequence number advances alike
        assert packer.pack(*values) == cls(*values).pack(mav)
        mav.seq = (mav.seq + 1) % 256


def test_fast_decoder_agrees_with_pymavlink_and_refuses_what_it_cannot_verify():
    mav = mavlink.MAVLink(None, 1, 1)
    frame = mavlink.MAVLink_hil_actuator_controls_message(
        4000, [0.5, 0.25, 0.0, 1.0] + [0.0] * 12, 128, 1
    ).pack(mav)
    fields = WireUnpacker(mavlink.MAVLink_hil_actuator_controls_message).unpack(frame)
    assert fields["time_usec"] == 4000 and fields["mode"] == 128 and fields["flags"] == 1
    assert fields["controls"][:4] == (0.5, 0.25, 0.0, 1.0)
    unpacker = WireUnpacker(mavlink.MAVLink_hil_actuator_controls_message)
    corrupted = bytearray(frame)
    corrupted[14] ^= 0x40
    assert unpacker.unpack(bytes(corrupted)) is None  # CRC
    assert unpacker.unpack(frame[:-1]) is None  # partial
    assert unpacker.unpack(frame + frame) is None  # more than one
    other = mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 0, 3).pack(mav)
    assert unpacker.unpack(other) is None
