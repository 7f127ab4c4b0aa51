"""MAVLink 2 message signing on the ground-station link: the key, the check, what persists.

pymavlink 2.4.50's `check_signature` records a stream's timestamp before it verifies the
HMAC, so one forged packet with a far-future timestamp locks the real ground station out.
`SignedMAVLink` verifies the HMAC first and records nothing for a packet that fails it.

The key file holds 64 hexadecimal digits (the 32-byte key) or a passphrase, whose SHA-256 is
the key (MAVProxy's `signing setup PASSPHRASE`). The last timestamp is kept beside it in
`KEYFILE.timestamp`, so that a restarted vehicle never signs with, or accepts, an old one.
"""

from __future__ import annotations

import hashlib
import struct
import time
from pathlib import Path

from simbridge.config import ConfigError
from simbridge.hil import mavlink as mav

# Signing timestamps count 10 us since 2015-01-01 00:00 UTC.
SIGNING_EPOCH_S = 1420070400
# Unsigned packets accepted even when signing is on: radio status, which radios inject.
UNSIGNED_ALLOWED = frozenset({mav.MAVLINK_MSG_ID_RADIO_STATUS})


def now_timestamp() -> int:
    return int((time.time() - SIGNING_EPOCH_S) * 100_000)


def read_key(path: Path) -> bytes:
    """The 32-byte key from a key file (64 hex digits, or a passphrase)."""
    try:
        text = path.read_text().strip()
    except OSError as e:
        raise ConfigError(f"--signing-key-file: cannot read {path}: {e.strerror}") from None
    if not text:
        raise ConfigError(
            f"--signing-key-file: {path} is empty; write 64 hex digits or a passphrase"
        )
    try:
        key = bytes.fromhex(text)
        if len(key) == 32:
            return key
    except ValueError:
        pass
    return hashlib.sha256(text.encode()).digest()


class SignedMAVLink(mav.MAVLink):
    """pymavlink's MAVLink with the signature checked before any timestamp is recorded."""

    def check_signature(self, msgbuf: bytearray, srcSystem: int, srcComponent: int) -> bool:
        key = self.signing.secret_key
        digest = hashlib.sha256(key + bytes(msgbuf[:-6])).digest()[:6]
        if digest != bytes(msgbuf[-6:]):
            return False
        link_id = msgbuf[-13]
        low, high = struct.unpack("<IH", bytes(msgbuf[-12:-6]))
        timestamp = low + (high << 32)
        stream = (link_id, srcSystem, srcComponent)
        last = self.signing.stream_timestamps.get(stream)
        if last is not None and timestamp <= last:
            return False  # a replay
        if last is None and timestamp + 6_000_000 < self.signing.timestamp:
            return False  # a new stream more than a minute behind
        self.signing.stream_timestamps[stream] = timestamp
        self.signing.timestamp = max(self.signing.timestamp, timestamp)
        return True


class Signing:
    """The key and the persisted timestamp; `apply` turns signing on for a parser/packer."""

    def __init__(self, key_file: Path) -> None:
        self.key_file = key_file
        self.key = read_key(key_file)
        self.timestamp_file = key_file.with_name(key_file.name + ".timestamp")
        self.saved_timestamp = 0
        if self.timestamp_file.exists():
            try:
                self.saved_timestamp = int(self.timestamp_file.read_text().strip() or 0)
            except (OSError, ValueError):
                raise ConfigError(
                    f"{self.timestamp_file}: not a signing timestamp; delete it to start anew"
                ) from None
        self.rejected = 0  # unsigned or wrongly signed packets dropped

    def apply(self, link: mav.MAVLink) -> None:
        link.signing.secret_key = self.key
        link.signing.sign_outgoing = True
        link.signing.link_id = 0
        link.signing.timestamp = max(now_timestamp(), self.saved_timestamp + 1)
        link.signing.allow_unsigned_callback = self._allow_unsigned

    def _allow_unsigned(self, link: mav.MAVLink, msg_id: int) -> bool:
        return msg_id in UNSIGNED_ALLOWED

    def save(self, timestamp: int) -> None:
        tmp = self.timestamp_file.with_name(self.timestamp_file.name + ".tmp")
        tmp.write_text(f"{timestamp}\n")
        tmp.replace(self.timestamp_file)
        self.saved_timestamp = timestamp
