"""Lean MAVLink 2 framing for the hot loop, built from pymavlink's own message metadata.

pymavlink builds a message object and walks generic code for every packet (about 5 us
each); the lockstep link sends several per 4 ms step. `WirePacker` takes the wire layout,
message id and CRC extra from the pymavlink class once and packs in about 1.5 us. The bytes
are identical to pymavlink's (tests check it); decoding stays with pymavlink.
"""

from __future__ import annotations

import struct
from typing import Any

import fastcrc

_crc = fastcrc.crc16.mcrf4xx
_HEADER = struct.Struct("<BBBBBBBHB")
_CRC = struct.Struct("<H")
MAVLINK2_STX = 0xFD


def _array_layout(message_class: Any) -> tuple[tuple[str, int], ...]:
    """(field, array length or 0) in wire order; a char array is one bytes value."""
    types = dict(zip(message_class.fieldnames, message_class.fieldtypes, strict=True))
    return tuple(
        (name, 0 if types[name] == "char" else length)
        for name, length in zip(
            message_class.ordered_fieldnames, message_class.array_lengths, strict=True
        )
    )


class PacketSequence:
    """The packet sequence number of one outgoing stream."""

    __slots__ = ("value",)

    def __init__(self) -> None:
        self.value = 0

    def next(self) -> int:
        v = self.value
        self.value = (v + 1) & 0xFF
        return v


def _flattener(message_class: Any) -> Any:
    """A function from the constructor's arguments to the payload's values in wire order, an
    array's elements spread in place: one tuple display, built once per message type (a
    loop over the fields costs a microsecond a packet on the hot path)."""
    names = message_class.fieldnames
    parts = []
    for name, length in _array_layout(message_class):
        index = names.index(name)
        parts.append(f"*v[{index}]" if length else f"v[{index}]")
    return eval(f"lambda v: ({', '.join(parts)},)")  # our own text, from the dialect


class WirePacker:
    """Packs one message type; arguments in the order of the pymavlink class's constructor."""

    def __init__(
        self, message_class: Any, src_system: int, src_component: int, seq: PacketSequence
    ) -> None:
        self._flat = _flattener(message_class)
        self._struct = message_class.unpacker
        self._crc_extra = bytes([message_class.crc_extra])
        self._msgid = message_class.id
        self._src = (src_system, src_component)
        self._seq = seq

    def pack(self, *values: Any) -> bytes:
        # MAVLink 2 drops trailing zero bytes of the payload, keeping at least one.
        payload = self._struct.pack(*self._flat(values)).rstrip(b"\0") or b"\0"
        msgid = self._msgid
        seq = self._seq
        v = seq.value
        seq.value = (v + 1) & 0xFF
        src = self._src
        body = _HEADER.pack(
            MAVLINK2_STX, len(payload), 0, 0, v, src[0], src[1], msgid & 0xFFFF, msgid >> 16
        )
        body += payload
        return body + _CRC.pack(_crc(body[1:] + self._crc_extra))


class WireUnpacker:
    """Decodes the payload of one message type with pymavlink's layout."""

    def __init__(self, message_class: Any) -> None:
        self._struct = message_class.unpacker
        self._size = self.size = message_class.unpacker.size
        self.unpack = message_class.unpacker.unpack  # a whole payload's values, in wire order
        self._layout = _array_layout(message_class)
        types = dict(zip(message_class.fieldnames, message_class.fieldtypes, strict=True))
        self._text = tuple(name for name, kind in types.items() if kind == "char")
        # without arrays a payload's values are its fields in wire order: one zip
        self._names = (
            None if any(count for _, count in self._layout) else [n for n, _ in self._layout]
        )
        # with arrays, each field's index into the values or its slice of them
        self._index: list[tuple[str, int | slice]] = []
        i = 0
        for name, count in self._layout:
            self._index.append((name, slice(i, i + count) if count else i))
            i += count or 1

    def decode_payload(self, payload: bytes) -> dict[str, Any] | None:
        """The fields of one payload (MAVLink 2 may have dropped its trailing zeros)."""
        length = len(payload)
        if length < self._size:
            payload += bytes(self._size - length)
        elif length > self._size:
            return None
        values = self._struct.unpack(payload)
        if self._names is not None:
            fields = dict(zip(self._names, values))  # noqa: B905 (lengths equal by construction)
        else:
            fields = {name: values[at] for name, at in self._index}
        for name in self._text:  # as pymavlink: text up to the first NUL
            fields[name] = fields[name].split(b"\0", 1)[0].decode("utf-8", "replace")
        return fields


SIGNED_FLAG = 0x01
SIGNATURE_LEN = 13
_PARTIAL = object()


class FrameReader:
    """A MAVLink 2 byte stream into (message name, fields) pairs, resynchronising after noise.

    Every frame is checked against its CRC with the dialect's CRC extra. After noise, a bad
    CRC or a message id outside the dialect, reading resumes at the next byte, so a broken
    header cannot swallow the real frames behind it; in lockstep a swallowed tick would stall
    both ends. A frame that looks incomplete is taken for noise when a whole valid frame
    follows it in the bytes already received. Counts: `malformed` (noise runs and frames
    failing their CRC), `unknown` (ids outside the dialect).
    """

    def __init__(self, dialect: Any) -> None:
        self._classes = dialect.mavlink_map  # msgid -> pymavlink message class
        self._unpackers: dict[int, tuple[str, bytes, WireUnpacker]] = {}
        self._pending = b""
        self.malformed = 0
        self.unknown = 0

    def _known(self, msgid: int) -> tuple[str, bytes, WireUnpacker] | None:
        entry = self._unpackers.get(msgid)
        if entry is None:
            cls = self._classes.get(msgid)
            if cls is None:
                return None
            entry = (cls.msgname, bytes([cls.crc_extra]), WireUnpacker(cls))
            self._unpackers[msgid] = entry
        return entry

    def _frame(self, buf: bytes, i: int) -> Any:
        """(name, fields, end) for a valid frame at i; _PARTIAL if cut short; None if invalid."""
        n = len(buf)
        if n - i < 10:
            return _PARTIAL
        length, flags = buf[i + 1], buf[i + 2]
        if flags & ~SIGNED_FLAG:
            return None
        msgid = buf[i + 7] | buf[i + 8] << 8 | buf[i + 9] << 16
        known = self._unpackers.get(msgid) or self._known(msgid)
        if known is None:
            self.unknown += 1
            return None
        end = i + 12 + length
        if end + (SIGNATURE_LEN if flags & SIGNED_FLAG else 0) > n:
            return _PARTIAL
        name, crc_extra, unpacker = known
        if _crc(buf[i + 1 : i + 10 + length] + crc_extra) != buf[end - 2] | buf[end - 1] << 8:
            self.malformed += 1
            return None
        fields = unpacker.decode_payload(buf[i + 10 : end - 2])
        if fields is None:
            self.malformed += 1
            return None
        return name, fields, end + (SIGNATURE_LEN if flags & SIGNED_FLAG else 0)

    def lone(self, data: bytes, msgid: int) -> tuple[Any, ...] | None:
        """The payload's values in wire order when nothing is pending and `data` is exactly
        one whole, unsigned, valid frame of message `msgid` at its full length (a lockstep
        reply, the usual case: about a microsecond instead of `feed`'s three); otherwise None
        with nothing read or counted, for `feed` to take."""
        n = len(data)
        if (
            self._pending
            or n < 12
            or data[0] != MAVLINK2_STX
            or data[2]
            or data[7] | data[8] << 8 | data[9] << 16 != msgid
            or n != 12 + data[1]
        ):
            return None
        known = self._known(msgid)
        if known is None or data[1] != known[2].size:
            return None
        if _crc(data[1 : n - 2] + known[1]) != data[n - 2] | data[n - 1] << 8:
            return None
        return known[2].unpack(data[10 : n - 2])

    def _next_valid(self, buf: bytes, i: int) -> int | None:
        while (j := buf.find(MAVLINK2_STX, i)) >= 0:
            unknown, malformed = self.unknown, self.malformed
            frame = self._frame(buf, j)
            self.unknown, self.malformed = unknown, malformed  # only looking ahead
            if frame is not None and frame is not _PARTIAL:
                return j
            i = j + 1
        return None

    @property
    def pending(self) -> bool:
        """Whether bytes wait to be decoded (a frame cut short, or frames after a stop)."""
        return bool(self._pending)

    def feed(self, data: bytes, stop_after: str | None = None) -> list[tuple[str, dict[str, Any]]]:
        """The frames in what is pending plus `data`. With `stop_after`, decoding stops after
        the first frame of that name and the rest waits, undecoded, for the next call (an
        autopilot answering a tick decodes only what precedes it before replying)."""
        out: list[tuple[str, dict[str, Any]]] = []
        buf = self._pending + data if self._pending else data
        self._pending = b""
        i, n = 0, len(buf)
        while i < n:
            j = buf.find(MAVLINK2_STX, i)
            if j < 0:
                self.malformed += 1  # a run of noise to the end
                break
            if j > i:
                self.malformed += 1  # a run of noise before the next start byte
                i = j
            frame = self._frame(buf, i)
            if frame is None:
                i += 1
            elif frame is _PARTIAL:
                later = self._next_valid(buf, i + 1)
                if later is None:
                    self._pending = buf[i:]
                    break
                self.malformed += 1
                i = later
            else:
                name, fields, i = frame
                out.append((name, fields))
                if name == stop_after:
                    self._pending = buf[i:]
                    break
        return out
