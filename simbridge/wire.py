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


class PacketSequence:
    """The packet sequence number of one outgoing stream."""

    __slots__ = ("value",)

    def __init__(self) -> None:
        self.value = 0

    def next(self) -> int:
        v = self.value
        self.value = (v + 1) & 0xFF
        return v


class WirePacker:
    """Packs one message type; arguments in the order of the pymavlink class's constructor."""

    def __init__(
        self, message_class: Any, src_system: int, src_component: int, seq: PacketSequence
    ) -> None:
        names = message_class.fieldnames
        self._order = tuple(
            (names.index(name), length)
            for name, length in zip(
                message_class.ordered_fieldnames, message_class.array_lengths, strict=True
            )
        )
        self._struct = message_class.unpacker
        self._crc_extra = bytes([message_class.crc_extra])
        self._msgid = message_class.id
        self._src = (src_system, src_component)
        self._seq = seq

    def pack(self, *values: Any) -> bytes:
        flat: list[Any] = []
        for index, length in self._order:
            if length:
                flat.extend(values[index])
            else:
                flat.append(values[index])
        # MAVLink 2 drops trailing zero bytes of the payload, keeping at least one.
        payload = self._struct.pack(*flat).rstrip(b"\0") or b"\0"
        msgid = self._msgid
        header = _HEADER.pack(
            MAVLINK2_STX,
            len(payload),
            0,
            0,
            self._seq.next(),
            self._src[0],
            self._src[1],
            msgid & 0xFFFF,
            msgid >> 16,
        )
        body = header + payload
        return body + _CRC.pack(_crc(body[1:] + self._crc_extra))


class WireUnpacker:
    """Decodes one message type from a buffer holding exactly one whole, valid, unsigned frame.

    Anything else (partial frames, other messages, bad CRC, signed packets) returns None, and
    the caller hands the bytes to pymavlink's robust parser instead.
    """

    def __init__(self, message_class: Any) -> None:
        self._struct = message_class.unpacker
        self._size = message_class.unpacker.size
        self._crc_extra = bytes([message_class.crc_extra])
        self._msgid = message_class.id
        self._layout = tuple(
            zip(message_class.ordered_fieldnames, message_class.array_lengths, strict=True)
        )

    def unpack(self, data: bytes) -> dict[str, Any] | None:
        n = len(data)
        if n < 12 or data[0] != MAVLINK2_STX or data[2] != 0:  # incompat_flags 0: unsigned
            return None
        length = data[1]
        if n != 12 + length or data[7] | data[8] << 8 | data[9] << 16 != self._msgid:
            return None
        if (
            _crc(data[1 : 10 + length] + self._crc_extra)
            != data[10 + length] | data[11 + length] << 8
        ):
            return None
        return self.decode_payload(data[10 : 10 + length])

    def decode_payload(self, payload: bytes) -> dict[str, Any] | None:
        """The fields of one payload (MAVLink 2 may have dropped its trailing zeros)."""
        length = len(payload)
        if length < self._size:
            payload += bytes(self._size - length)
        elif length > self._size:
            return None
        values = self._struct.unpack(payload)
        fields: dict[str, Any] = {}
        i = 0
        for name, count in self._layout:
            if count:
                fields[name] = values[i : i + count]
                i += count
            else:
                fields[name] = values[i]
                i += 1
        return fields


class FrameReader:
    """A byte stream into (message name, fields) pairs.

    Unsigned MAVLink 2 frames of the given message types take a fast path (framing and CRC
    checked here with pymavlink's metadata); anything else goes through pymavlink's robust
    parser, whose bad-data and unknown-message verdicts are counted. Partial frames wait for
    the next bytes.
    """

    def __init__(self, message_classes: list[Any], fallback: Any) -> None:
        self._known = {cls.id: (cls.msgname, WireUnpacker(cls)) for cls in message_classes}
        self._crc_extras = {cls.id: bytes([cls.crc_extra]) for cls in message_classes}
        self._fallback = fallback  # a pymavlink MAVLink object with robust_parsing on
        self._pending = b""
        self.malformed = 0
        self.unknown = 0

    def feed(self, data: bytes) -> list[tuple[str, dict[str, Any]]]:
        out: list[tuple[str, dict[str, Any]]] = []
        if self._fallback.buf_len() > 0:  # pymavlink holds a partial frame: let it finish
            self._slow(data, out)
            return out
        buf = self._pending + data if self._pending else data
        self._pending = b""
        i, n = 0, len(buf)
        while i < n:
            if buf[i] != MAVLINK2_STX or n - i < 10:
                break
            length = buf[i + 1]
            msgid = buf[i + 7] | buf[i + 8] << 8 | buf[i + 9] << 16
            known = self._known.get(msgid)
            if known is None or buf[i + 2] != 0:  # another message, or signed
                break
            end = i + 12 + length
            if end > n:  # a partial frame: wait for the rest
                self._pending = buf[i:]
                return out
            crc = buf[end - 2] | buf[end - 1] << 8
            if _crc(buf[i + 1 : i + 10 + length] + self._crc_extras[msgid]) != crc:
                break
            fields = known[1].decode_payload(buf[i + 10 : end - 2])
            if fields is None:
                break
            out.append((known[0], fields))
            i = end
        if i < n:
            self._slow(buf[i:], out)
        return out

    def _slow(self, data: bytes, out: list[tuple[str, dict[str, Any]]]) -> None:
        for msg in self._fallback.parse_buffer(data) or ():
            kind = msg.get_type()
            if kind == "BAD_DATA":
                self.malformed += 1
            elif kind.startswith("UNKNOWN_"):
                self.unknown += 1
            else:
                out.append((kind, {name: getattr(msg, name) for name in msg.get_fieldnames()}))
