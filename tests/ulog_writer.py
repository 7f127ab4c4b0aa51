"""A minimal PX4 ULog writer for the tests: the file format of PX4's logger (header, flag bits,
formats, parameters, subscriptions, data messages), as pyulog parses it. Real PX4 writes more
topics and fields; the reader takes only these."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

MAGIC = b"ULog\x01\x12\x35"
FORMATS = {"uint64_t": "Q", "float": "f", "int32_t": "i", "uint8_t": "B"}


def _message(kind: bytes, body: bytes) -> bytes:
    return struct.pack("<HB", len(body), kind[0]) + body


def _key_value(type_name: str, value: bytes) -> bytes:
    key = type_name.encode()
    return struct.pack("<B", len(key)) + key + value


def write_ulog(
    path: Path,
    topics: dict[str, tuple[list[tuple[str, str]], np.ndarray]],
    params: dict[str, float],
) -> Path:
    """`topics`: name -> ([(type, field)], rows); the first field is `uint64_t timestamp` in
    microseconds; a field `float[4] q` takes four columns. `params`: float parameters."""
    out = bytearray(MAGIC + b"\x01" + struct.pack("<Q", 0))
    out += _message(b"B", bytes(16) + bytes(24))  # no compat/incompat flags, no appended data
    for name, (fields, _) in topics.items():
        spec = "".join(f"{t} {f};" for t, f in fields)
        out += _message(b"F", f"{name}:{spec}".encode())
    for name, value in params.items():
        out += _message(b"P", _key_value(f"float {name}", struct.pack("<f", value)))
    packers = {}
    for msg_id, (name, (fields, _)) in enumerate(topics.items()):
        out += _message(b"A", struct.pack("<BH", 0, msg_id) + name.encode())
        codes = ""
        for t, _ in fields:
            base, _, count = t.partition("[")
            codes += (count.rstrip("]") if count else "") + FORMATS[base]
        packers[name] = struct.Struct("<H" + codes)
    rows = [
        (int(row[0]), msg_id, name, row)
        for msg_id, (name, (_, data)) in enumerate(topics.items())
        for row in data
    ]
    for _, msg_id, name, row in sorted(rows, key=lambda r: (r[0], r[1])):
        packer = packers[name]
        values = [int(row[0]), *(float(v) for v in row[1:])]
        out += _message(b"D", packer.pack(msg_id, *values))
    path.write_bytes(bytes(out))
    return path
