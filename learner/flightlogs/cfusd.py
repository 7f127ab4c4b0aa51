"""Crazyflie microSD-deck logs: both on-card formats, decoded with numpy alone.

Legacy (usddeck before about 2020; the neural-swarm data): uint8 N; N ASCII entries
`group.name(T),` (T a Python struct code); a CRC-32 of the header; then blocks until the end
of the file: uint8 k, k packed little-endian records, a CRC-32. Every CRC is stored so that
crc32(covered bytes + crc) is the CRC-32 residue 0xFFFFFFFF. One fixed-rate set, timed by a
logged `tick` variable.

Event format (Bitcraze firmware today, `tools/usdlog/cfusdlog.py`): 0xBC; uint16 version
(1 or 2); uint16 number of event types; per type uint16 id, a NUL-terminated name, uint16
number of variables and their NUL-terminated `name(T)`; then records: uint16 id, a timestamp
(v1 uint32 ms, v2 uint64 us), the packed payload; a plain CRC-32 of all that at the end. The
periodic set is the event `fixedFrequency`.

Compressed quaternions (`stateEstimateZ.quat`, firmware quatcompress.h) are expanded into
`<group>.qx, .qy, .qz, .qw`. The log's time is the column `timestamp` in the unit the card
wrote (legacy: the `tick` variable; v1 ms; v2 us); the packaged mappings detect it.
"""

from __future__ import annotations

import re
import struct
import zlib
from pathlib import Path

import numpy as np

from learner.flightlogs.flightlog import FlightLog
from learner.flightlogs.tables import ColumnMapping, load_mapping, table_log
from simbridge.config import ConfigError
from simbridge.vehicle import Vehicle

DTYPES = {
    "b": "i1", "B": "u1", "h": "<i2", "H": "<u2", "i": "<i4", "I": "<u4",
    "q": "<i8", "Q": "<u8", "f": "<f4", "d": "<f8", "e": "<f2", "?": "u1",
}  # fmt: skip
CRC_RESIDUE = 0xFFFFFFFF
EVENT_MAGIC = 0xBC
PERIODIC_EVENT = "fixedFrequency"
# A legacy header starts with the variable count, then the first `name(T),` entry.
_LEGACY_ENTRY = re.compile(rb"[A-Za-z_][A-Za-z0-9_.\[\]]*\([bBhHiIqQfde?]\),")


def looks_like_cfusd(head: bytes) -> bool:
    """Whether a file's first bytes are a Crazyflie microSD log of either format."""
    if len(head) >= 5 and head[0] == EVENT_MAGIC:
        version, n_events = struct.unpack_from("<HH", head, 1)
        return version in (1, 2) and n_events > 0
    return len(head) > 2 and head[0] > 0 and _LEGACY_ENTRY.match(head, 1) is not None


def quat_decompress(packed: np.ndarray) -> np.ndarray:
    """Inverse of the firmware's quatcompress: uint32 -> (N, 4) x, y, z, w. Bits 31-30 hold
    the index of the largest component (x, y, z, w order), then three 10-bit fields (sign
    bit + 9-bit magnitude m, |q_i| = m / 511 / sqrt 2) for the others in increasing index,
    most significant first; the largest is +sqrt(1 - the others' squares)."""
    c = np.asarray(packed, dtype=np.uint64).ravel()
    largest = (c >> np.uint64(30)).astype(np.int64)
    q = np.zeros((c.size, 4))
    squares = np.zeros(c.size)
    for i in range(3, -1, -1):
        other = largest != i
        magnitude = (c & np.uint64(511)).astype(float) * np.sqrt(0.5) / 511.0
        negative = ((c >> np.uint64(9)) & np.uint64(1)).astype(bool)
        value = np.where(negative, -magnitude, magnitude)
        q[other, i] = value[other]
        squares[other] += value[other] ** 2
        c = np.where(other, c >> np.uint64(10), c)
    q[np.arange(len(q)), largest] = np.sqrt(np.clip(1.0 - squares, 0.0, None))
    return q


def read_cfusd_columns(path: Path) -> tuple[dict[str, np.ndarray], list[str]]:
    """The periodic set of a microSD log as float columns (with `timestamp` and the expanded
    quaternions), and notes on what was left out (bad CRC, truncation)."""
    try:
        data = Path(path).read_bytes()
    except OSError as err:
        raise ConfigError(f"{path}: cannot read ({err.strerror})") from None
    if not looks_like_cfusd(data[:256]):
        raise ConfigError(f"{path}: not a Crazyflie microSD log (neither format's header)")
    try:
        if data[0] == EVENT_MAGIC:
            records, notes = _event_records(data)
        else:
            records, notes = _legacy_records(data)
    except (ValueError, IndexError, struct.error) as err:
        raise ConfigError(f"{path}: damaged Crazyflie microSD log header ({err})") from None
    if "timestamp" not in records:
        raise ConfigError(
            f"{path}: the legacy log has no 'tick' variable to time its records by; "
            f"log tick(I) first, as the microSD deck's config.txt does by default"
        )
    columns = {k: np.asarray(v, dtype=float) for k, v in records.items() if k[-5:] != ".quat"}
    for name, packed in records.items():
        if name.endswith(".quat"):
            xyzw = quat_decompress(packed)
            for i, axis in enumerate("xyzw"):
                columns[f"{name[:-5]}.q{axis}"] = xyzw[:, i]
    if not len(columns["timestamp"]):
        raise ConfigError(f"{path}: no records in the Crazyflie microSD log")
    return columns, notes


def read_cfusd_log(
    path: Path, mapping: ColumnMapping | None = None, vehicle: Vehicle | str | None = None
) -> FlightLog:
    """A microSD log as a FlightLog, through `mapping` or, by default, the packaged one for
    the state it holds (`crazyflie_z` for stateEstimateZ.*, else `crazyflie`)."""
    path = Path(path)
    columns, notes = read_cfusd_columns(path)
    if mapping is None or mapping.is_default:
        name = "crazyflie_z" if "stateEstimateZ.x" in columns else "crazyflie"
        mapping = load_mapping(name)
        notes.append(f"columns: the packaged mapping {name}")
    return table_log(columns, path, mapping, vehicle, meta={"conversions": notes})


def _dtype(entries: list[str]) -> np.dtype:
    fields = []
    for entry in entries:
        m = re.fullmatch(r"(.+)\((.)\)", entry.strip())
        if m is None or m.group(2) not in DTYPES:
            raise ValueError(f"variable {entry!r} is not name(T) with T one of {''.join(DTYPES)}")
        fields.append((m.group(1), DTYPES[m.group(2)]))
    return np.dtype(fields)


def _legacy_records(data: bytes) -> tuple[dict[str, np.ndarray], list[str]]:
    count, at = data[0], 1
    entries = []
    for _ in range(count):
        end = data.index(b",", at)
        entries.append(data[at:end].decode("ascii"))
        at = end + 1
    dtype = _dtype(entries)
    notes = []
    if zlib.crc32(data[: at + 4]) != CRC_RESIDUE:
        notes.append("microSD: the header's CRC does not match (the file may be damaged)")
    at += 4
    chunks, bad_blocks, bad_records = [], 0, 0
    while at < len(data):
        k = data[at]
        end = at + 1 + k * dtype.itemsize
        if end + 4 > len(data):
            notes.append(f"microSD: a truncated last block ({len(data) - at} bytes) left out")
            break
        if zlib.crc32(data[at : end + 4]) == CRC_RESIDUE:
            chunks.append(np.frombuffer(data, dtype=dtype, count=k, offset=at + 1))
        else:
            bad_blocks, bad_records = bad_blocks + 1, bad_records + k
        at = end + 4
    if bad_blocks:
        notes.append(
            f"microSD: {bad_blocks} block{'s' * (bad_blocks != 1)} with a bad CRC left out "
            f"({bad_records} records)"
        )
    rec = np.concatenate(chunks) if chunks else np.zeros(0, dtype)
    records = {name: rec[name] for name in dtype.names or ()}
    if "tick" in records:
        records["timestamp"] = records["tick"]
    return records, notes


def _event_records(data: bytes) -> tuple[dict[str, np.ndarray], list[str]]:
    version, n_events = struct.unpack_from("<HH", data, 1)
    at, events = 5, {}
    for _ in range(n_events):
        (event_id,) = struct.unpack_from("<H", data, at)
        name, at = _cstring(data, at + 2)
        (n_vars,) = struct.unpack_from("<H", data, at)
        at += 2
        entries = []
        for _ in range(n_vars):
            entry, at = _cstring(data, at)
            entries.append(entry)
        events[event_id] = (name, _dtype(entries))
    notes = []
    if zlib.crc32(data[:-4]) != struct.unpack("<I", data[-4:])[0]:
        notes.append("microSD: the file's CRC does not match (the file may be damaged)")
    head = struct.Struct("<HI" if version == 1 else "<HQ")
    names = {name: event_id for event_id, (name, _) in events.items()}
    if PERIODIC_EVENT in names:
        wanted = names[PERIODIC_EVENT]
    elif len(events) == 1:
        wanted = next(iter(events))
    else:
        raise ValueError(
            f"no {PERIODIC_EVENT!r} event among {', '.join(names)}: log the state in the "
            f"periodic set"
        )
    payloads, stamps, end = [], [], len(data) - 4
    while at + head.size <= end:
        event_id, stamp = head.unpack_from(data, at)
        if event_id not in events:
            notes.append(f"microSD: an unknown event id {event_id} at byte {at}; the rest left out")
            break
        size = events[event_id][1].itemsize
        if at + head.size + size > end:
            notes.append("microSD: a truncated last record left out")
            break
        if event_id == wanted:
            payloads.append(data[at + head.size : at + head.size + size])
            stamps.append(stamp)
        at += head.size + size
    dtype = events[wanted][1]
    rec = np.frombuffer(b"".join(payloads), dtype=dtype)
    records = {name: rec[name] for name in dtype.names or ()}
    records["timestamp"] = np.asarray(stamps, dtype=np.uint64)
    return records, notes


def _cstring(data: bytes, at: int) -> tuple[str, int]:
    end = data.index(b"\x00", at)
    return data[at:end].decode("ascii"), end + 1
