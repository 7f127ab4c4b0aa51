"""The lean packer writes exactly pymavlink's bytes; the fast decoder agrees with pymavlink."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simbridge.hil import mavlink
from simbridge.wire import FrameReader, PacketSequence, WirePacker

CASES = [
    (mavlink.MAVLink_debug_vect_message, (b"GE_TRUE", 4000, 0.0, 0.0, 0.25)),
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


def frames(reader_input: bytes) -> tuple[list[tuple[str, dict]], FrameReader]:
    reader = FrameReader(mavlink)
    return reader.feed(reader_input), reader


def test_reader_agrees_with_pymavlink():
    mav = mavlink.MAVLink(None, 1, 1)
    data = b"".join(cls(*values).pack(mav) for cls, values in CASES)
    decoded, reader = frames(data)
    reference = mavlink.MAVLink(None).parse_buffer(data)
    assert [name for name, _ in decoded] == [m.get_type() for m in reference]
    for (_, fields), msg in zip(decoded, reference, strict=True):
        for name, value in fields.items():
            expected = getattr(msg, name)
            if isinstance(value, str):
                assert value == expected, name
                continue
            assert np.array_equal(
                np.asarray(value, dtype=float), np.asarray(expected, dtype=float), equal_nan=True
            ), name
    assert reader.malformed == reader.unknown == 0


def test_reader_waits_for_the_rest_of_a_split_frame():
    mav = mavlink.MAVLink(None, 1, 1)
    data = b"".join(cls(*values).pack(mav) for cls, values in CASES)
    reader = FrameReader(mavlink)
    out = []
    for k in range(0, len(data), 7):  # seven bytes at a time
        out += reader.feed(data[k : k + 7])
    assert [name for name, _ in out] == [cls.msgname for cls, _ in CASES]


def test_reader_stops_after_a_tick_and_keeps_the_rest_undecoded():
    """An autopilot decodes what it needs before its reply (up to the tick) and the rest
    after: two ticks and their truth in one read come out in order, one tick per call."""
    mav = mavlink.MAVLink(None, 1, 1)
    data = b"".join(cls(*values).pack(mav) for cls, values in CASES) * 2
    names = [cls.msgname for cls, _ in CASES]
    first_tick = names.index("HIL_SENSOR") + 1
    reader = FrameReader(mavlink)
    out = reader.feed(data[:-5], stop_after="HIL_SENSOR")  # the last frame cut short
    assert [name for name, _ in out] == names[:first_tick] and reader.pending
    out = reader.feed(b"", stop_after="HIL_SENSOR")
    assert [name for name, _ in out] == (names[first_tick:] + names)[: len(names)]
    out = reader.feed(b"", stop_after="HIL_SENSOR")  # nothing whole left before the cut
    assert [name for name, _ in out] == names[first_tick:-1] and reader.pending
    assert [name for name, _ in reader.feed(data[-5:])] == names[-1:]
    assert not reader.pending and reader.malformed == reader.unknown == 0


def test_reader_resynchronises_after_noise_bad_crcs_and_broken_headers():
    mav = mavlink.MAVLink(None, 1, 1)
    values = dict(CASES)[mavlink.MAVLink_hil_sensor_message]
    good = mavlink.MAVLink_hil_sensor_message(*values).pack(mav)
    corrupted = bytearray(good)
    corrupted[20] ^= 0xFF
    unknown = bytes([0xFD, 3, 0, 0, 0, 1, 1, 0x60, 0xEA, 0, 1, 2, 3, 0, 0])  # id 60000
    broken_header = bytes([0xFD, 200, 0])  # claims 200 bytes: would swallow what follows
    stream = b"line noise" + bytes(corrupted) + unknown + broken_header + good
    decoded, reader = frames(stream)
    assert [name for name, _ in decoded] == ["HIL_SENSOR"]
    assert decoded[0][1]["time_usec"] == values[0]
    assert reader.malformed >= 3 and reader.unknown >= 1  # rescanning may count a stray 0xFD too


def test_a_lone_reply_frame_reads_as_feed_decodes_it_and_anything_else_is_left_to_feed():
    """The simulator reads a lockstep reply (one whole HIL_ACTUATOR_CONTROLS) by `lone`, and
    whatever else arrives by `feed`: the same values either way, nothing counted twice."""
    from simbridge.server import ACTUATORS

    mav = mavlink.MAVLink(None, 1, 1)
    controls = [0.5, 0.25, 0.125, 1.0] + [0.0] * 12
    armed = ACTUATORS(123456, controls, mavlink.MAV_MODE_FLAG_SAFETY_ARMED, 1).pack(mav)
    values = FrameReader(mavlink).lone(armed, ACTUATORS.id)
    [(name, fields)] = FrameReader(mavlink).feed(armed)
    assert values is not None and name == "HIL_ACTUATOR_CONTROLS"
    # the server's reading of the wire order
    assert (values[0], list(values[2:18]), values[18], values[1]) == (
        fields["time_usec"], list(fields["controls"]), fields["mode"], fields["flags"]
    )  # fmt: skip
    disarmed = ACTUATORS(123456, controls, 0, 1).pack(mav)  # mode 0: its last byte dropped
    corrupted = bytearray(armed)
    corrupted[30] ^= 0xFF
    reader = FrameReader(mavlink)
    for data in (disarmed, bytes(corrupted), armed + armed, armed[:-1], b"noise" + armed):
        assert reader.lone(data, ACTUATORS.id) is None
    assert reader.lone(armed, mavlink.MAVLink_hil_sensor_message.id) is None
    assert reader.malformed == reader.unknown == 0
    reader.feed(armed[:-1])  # a frame cut short waits: the next bytes are not a lone frame
    assert reader.pending and reader.lone(armed, ACTUATORS.id) is None
