"""The ground-station link: MAVLink 2 over UDP and TCP endpoints given as pymavlink-style URLs.

`udpout:HOST:PORT` sends to a fixed address (QGroundControl and MAVProxy listen on 14550)
and hears whatever answers; `udpin:HOST:PORT` listens (API clients send to 14540) and
answers everyone it has heard; `tcpin:HOST:PORT` accepts TCP clients. Everything sent goes
to every peer. Reading never blocks: the flight loop polls between control steps.

Nothing a peer sends can stop the loop: frames that fail their CRC, truncated frames,
unknown ids and garbage are counted and dropped; with signing on, unsigned and wrongly
signed packets are counted and dropped; messages addressed to another system are counted
and ignored. Heartbeats keep going on the wall clock when the loop stalls (`keepalive`).
"""

from __future__ import annotations

import contextlib
import errno
import socket
import threading
from dataclasses import dataclass, field
from typing import Any

from autopilot.gcs.keepalive import Keepalive
from autopilot.gcs.port_owner import port_owner
from autopilot.gcs.signing import SignedMAVLink, Signing
from simbridge.config import ConfigError
from simbridge.hil import mavlink as mav

SCHEMES = ("udpout", "udpin", "tcpin", "udp")
PEER_FORGET_S = 30.0  # a udpin peer silent this long is no longer sent to
MAX_DATAGRAMS_PER_POLL = 256  # bounds the time one poll may take under a flood
RECEIVE_BUFFER_BYTES = 4 << 20
SIGNING_SAVE_S = 10.0  # wall seconds between saves of the signing timestamp


def parse_url(url: str) -> tuple[str, str, int]:
    """(scheme, host, port) from `udpout:127.0.0.1:14550` (`udp:` means `udpin:`)."""
    parts = url.split(":")
    if len(parts) != 3 or parts[0] not in SCHEMES:
        raise ConfigError(
            f"{url!r}: expected SCHEME:HOST:PORT with SCHEME one of {', '.join(SCHEMES)}"
        )
    scheme, host, port_text = parts
    try:
        port = int(port_text)
    except ValueError:
        raise ConfigError(f"{url!r}: port {port_text!r} is not a number") from None
    if not 0 <= port <= 65535:
        raise ConfigError(f"{url!r}: port {port} outside [0, 65535]")
    return ("udpin" if scheme == "udp" else scheme), host, port


@dataclass
class Counters:
    received: int = 0  # messages accepted
    malformed: int = 0  # garbage, bad CRC, truncated, bad length
    unknown: int = 0  # message ids outside the dialect
    rejected: int = 0  # unsigned or badly signed (signing on)
    wrong_target: int = 0  # addressed to another system or component
    invalid: int = 0  # well-formed but refused (out-of-range values, bad requests)

    @property
    def dropped(self) -> int:
        return self.malformed + self.unknown + self.rejected + self.wrong_target

    def recorded(self) -> tuple[int, int, int]:
        """(received, dropped, rejected) for the recording: dropped never reached a handler;
        rejected were well-formed requests refused."""
        return (self.received, self.dropped, self.invalid)

    def as_dict(self) -> dict[str, int]:
        return {
            "received": self.received,
            "malformed": self.malformed,
            "unknown": self.unknown,
            "rejected": self.rejected,
            "wrong_target": self.wrong_target,
            "invalid": self.invalid,
            "dropped": self.dropped,
        }


@dataclass
class Endpoint:
    url: str
    scheme: str
    sock: socket.socket
    parser: mav.MAVLink
    destination: tuple[str, int] | None = None  # udpout
    peers: dict[tuple[str, int], float] = field(default_factory=dict)  # udpin: addr -> heard
    clients: list[tuple[socket.socket, mav.MAVLink]] = field(default_factory=list)  # tcpin

    @property
    def local_port(self) -> int:
        return self.sock.getsockname()[1]


class GcsLink:
    def __init__(
        self, urls: list[str], signing: Signing | None = None, sysid: int = 1, compid: int = 1
    ) -> None:
        self.sysid, self.compid = sysid, compid
        self.signing = signing
        self.counters = Counters()
        self.packer = self._new_mavlink()
        self.endpoints = [self._open(url) for url in urls]
        # the flight loop and the keepalive thread both send: one packer, one sequence
        self._lock = threading.Lock()
        self.heartbeat: mav.MAVLink_message | None = None  # the newest sent, and when
        self.heartbeat_sent_s: float | None = None
        self.signing_saved_s = 0.0
        self.keepalive = Keepalive(lambda: self.heartbeat_sent_s, self._resend_heartbeat)
        if self.endpoints:
            self.keepalive.start()

    def _new_mavlink(self) -> mav.MAVLink:
        link = SignedMAVLink(None, srcSystem=self.sysid, srcComponent=self.compid)
        link.robust_parsing = True
        if self.signing is not None:
            if hasattr(self, "packer"):
                link.signing = self.packer.signing  # one key, one timestamp, one stream table
            else:
                self.signing.apply(link)
        return link

    def _open(self, url: str) -> Endpoint:
        scheme, host, port = parse_url(url)
        try:
            if scheme == "tcpin":
                sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                sock.bind((host, port))
                sock.listen(4)
            else:
                sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
                if scheme == "udpin":
                    # no SO_REUSEADDR: with it a second vehicle on this port starts silently
                    # and takes the first one's ground-station traffic
                    sock.bind((host, port))
                else:
                    sock.bind(("0.0.0.0", 0))
        except OSError as e:
            held = ""
            if e.errno == errno.EADDRINUSE:
                owner = port_owner(port, "tcp" if scheme == "tcpin" else "udp")
                held = f" (held by {owner})" if owner else ""
            raise ConfigError(f"{url}: cannot open port {port}: {e.strerror}{held}") from None
        sock.setblocking(False)
        destination = (host, port) if scheme == "udpout" else None
        return Endpoint(url, scheme, sock, self._new_mavlink(), destination)

    # --- receiving -------------------------------------------------------------------------

    def poll(self, wall_s: float) -> list[mav.MAVLink_message]:
        """Every message waiting now, addressed to this vehicle or to all."""
        out: list[mav.MAVLink_message] = []
        for ep in self.endpoints:
            if ep.scheme == "tcpin":
                with self._lock:  # the client list is the sender's too
                    self._poll_tcp(ep, out)
                continue
            for _ in range(MAX_DATAGRAMS_PER_POLL):
                try:
                    data, addr = ep.sock.recvfrom(65536)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:  # ICMP port unreachable from a peer that went away
                    continue
                if ep.scheme == "udpin":
                    ep.peers[addr] = wall_s
                self._parse(ep.parser, data, out, datagram=True)
        return out

    def _poll_tcp(self, ep: Endpoint, out: list[mav.MAVLink_message]) -> None:
        while True:
            try:
                client, _ = ep.sock.accept()
            except (BlockingIOError, InterruptedError):
                break
            client.setblocking(False)
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            ep.clients.append((client, self._new_mavlink()))
        for client, parser in list(ep.clients):
            try:
                data = client.recv(65536)
            except (BlockingIOError, InterruptedError):
                continue
            except OSError:
                data = b""
            if not data:
                client.close()
                ep.clients.remove((client, parser))
                continue
            self._parse(parser, data, out, datagram=False)

    def _parse(
        self, parser: mav.MAVLink, data: bytes, out: list[mav.MAVLink_message], datagram: bool
    ) -> None:
        try:
            messages = parser.parse_buffer(data) or []
        except Exception:  # pymavlink raising on input it cannot even frame
            messages = []
            self.counters.malformed += 1
        if datagram and parser.buf_len() > 0:
            # A frame never spans datagrams: what is left is a truncated frame.
            self.counters.malformed += 1
            parser.buf, parser.buf_index = bytearray(), 0
            parser.expected_length = mav.HEADER_LEN_V1 + 2
        for m in messages:
            kind = m.get_type()
            if kind == "BAD_DATA":
                if "signature" in str(getattr(m, "reason", "")):
                    self.counters.rejected += 1
                else:
                    self.counters.malformed += 1
                continue
            if kind == "UNKNOWN" or kind.startswith("UNKNOWN"):
                self.counters.unknown += 1
                continue
            if not self._for_us(m):
                self.counters.wrong_target += 1
                continue
            self.counters.received += 1
            out.append(m)

    def _for_us(self, m: Any) -> bool:
        target_system = getattr(m, "target_system", 0)
        target_component = getattr(m, "target_component", 0)
        return target_system in (0, self.sysid) and target_component in (0, self.compid)

    # --- sending ---------------------------------------------------------------------------

    def send(self, message: mav.MAVLink_message, wall_s: float) -> None:
        """Pack (and sign) once; send to every peer of every endpoint."""
        with self._lock:
            self._send(message, wall_s)
            if message.get_msgId() == mav.MAVLINK_MSG_ID_HEARTBEAT:
                self.heartbeat, self.heartbeat_sent_s = message, wall_s

    def _resend_heartbeat(self, wall_s: float) -> bool:
        with self._lock:
            if self.heartbeat is None:
                return False
            self._send(self.heartbeat, wall_s)
            self.heartbeat_sent_s = wall_s
            return True

    def _send(self, message: mav.MAVLink_message, wall_s: float) -> None:
        data = message.pack(self.packer)
        for ep in self.endpoints:
            if ep.scheme == "udpout":
                self._sendto(ep, data, ep.destination)
            elif ep.scheme == "udpin":
                for addr, heard in list(ep.peers.items()):
                    if wall_s - heard > PEER_FORGET_S:
                        del ep.peers[addr]
                    else:
                        self._sendto(ep, data, addr)
            else:
                for client, parser in list(ep.clients):
                    try:
                        client.send(data)
                    except (BlockingIOError, InterruptedError):
                        pass  # a client too slow to read loses telemetry, not the vehicle
                    except OSError:
                        client.close()
                        ep.clients.remove((client, parser))

    @staticmethod
    def _sendto(ep: Endpoint, data: bytes, addr: tuple[str, int] | None) -> None:
        if addr is None:
            return
        with contextlib.suppress(OSError):  # nobody listening (yet): fire and forget
            ep.sock.sendto(data, addr)

    @property
    def signing_timestamp(self) -> int:
        return int(self.packer.signing.timestamp)

    def keep_signing(self, wall_s: float) -> None:
        """Save the signing timestamp now and then: a restart must never reuse one."""
        if self.signing is not None and wall_s - self.signing_saved_s > SIGNING_SAVE_S:
            self.save_signing(wall_s)

    def save_signing(self, wall_s: float) -> None:
        if self.signing is not None:
            self.signing.save(self.signing_timestamp)
            self.signing_saved_s = wall_s

    def describe(self, *more: str) -> str:
        """The link as a ground station meets it: its endpoints, and whether it signs."""
        urls = ", ".join(ep.url for ep in self.endpoints)
        signing = "on" if self.signing is not None else "off"
        return "; ".join((f"ground stations {urls}", *more, f"signing {signing}"))

    def close(self) -> None:
        self.keepalive.stop()
        for ep in self.endpoints:
            for client, _ in ep.clients:
                client.close()
            ep.sock.close()
