"""A minimal ground station on pymavlink: what `groundfx fly` uses to fly a mission exactly as
QGroundControl or a MAVSDK script would (upload, arm, start, follow, see the disarm).

Every wait is bounded and says what it waited for; heartbeats go out at 1 Hz while waiting,
as a real ground station's do (the vehicle's link-loss failsafe listens for them).
"""

from __future__ import annotations

import contextlib
import os
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
# the dialect the vehicle speaks; mavutil's default ("all") costs a tenth of a second to load
os.environ.setdefault("MAVLINK_DIALECT", "ardupilotmega")
from pymavlink import mavutil

from autopilot.commander.mission_items import MissionItem
from autopilot.gcs.mission_protocol import item_from_message, item_message

mav = mavutil.mavlink
GCS_SYSID, GCS_COMPID = 255, 190
FORCE = 21196


class GroundStationError(RuntimeError):
    """The vehicle refused or did not answer; the message says what and why."""


class VehicleEnded(GroundStationError):
    """The vehicle's process (when this station started it) is gone."""


@dataclass
class Progress:
    reached: list[int] = field(default_factory=list)
    texts: list[str] = field(default_factory=list)
    armed: bool = False
    was_armed: bool = False
    landed_state: int = 0
    mission_state: int = 0


class GroundStation:
    def __init__(self, url: str, signing_key: bytes | None = None) -> None:
        self.conn = mavutil.mavlink_connection(
            url, source_system=GCS_SYSID, source_component=GCS_COMPID, dialect="ardupilotmega"
        )
        if signing_key is not None:
            self.conn.setup_signing(signing_key, sign_outgoing=True, link_id=0)
        self.target = (1, 1)
        self.progress = Progress()
        self.heartbeat_due = 0.0
        self.partial: dict[int, str] = {}  # STATUSTEXT chunks by id
        self.on_text: Callable[[str], None] = lambda text: None
        self.vehicle_alive: Callable[[], bool] = lambda: True
        # telemetry at 30x real time must not overflow the socket while this process is busy
        with contextlib.suppress(AttributeError, OSError):
            self.conn.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)

    def close(self) -> None:
        self.conn.close()

    # --- the receive loop ------------------------------------------------------------------

    def _heartbeat(self) -> None:
        """1 Hz, from the first moment there is someone to send to (listening on udpin, the
        vehicle's address is known once it has been heard: a beat before is lost)."""
        now = time.monotonic()
        listening = getattr(self.conn, "udp_server", False)  # pymavlink's udpin
        if now >= self.heartbeat_due and (not listening or self.conn.clients):
            self.conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            self.heartbeat_due = now + 1.0

    def receive(self, timeout_s: float) -> Any | None:
        """The next message from the vehicle (tracking progress on the way), or None."""
        self._heartbeat()
        m = self.conn.recv_match(blocking=True, timeout=min(timeout_s, 0.2))
        self._heartbeat()  # at once when this was the first message heard
        return self._track(m)

    def _track(self, m: Any | None) -> Any | None:
        """`m` if it is the vehicle's, the progress it tells taken in; else None."""
        if m is None or m.get_srcSystem() != self.target[0]:
            return None
        kind = m.get_type()
        p = self.progress
        if kind == "HEARTBEAT" and m.get_srcComponent() == self.target[1]:
            p.armed = bool(m.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
            p.was_armed |= p.armed
        elif kind == "MISSION_ITEM_REACHED":
            if m.seq not in p.reached:
                p.reached.append(m.seq)
        elif kind == "EXTENDED_SYS_STATE":
            p.landed_state = m.landed_state
        elif kind == "MISSION_CURRENT":
            p.mission_state = m.mission_state
        elif kind == "STATUSTEXT":
            text = m.text if isinstance(m.text, str) else m.text.decode(errors="replace")
            if m.id == 0:
                p.texts.append(text)
                self.on_text(text)
            elif m.chunk_seq == 0:
                self.partial = {m.id: text}
            elif m.id in self.partial:
                self.partial[m.id] += text
            if m.id != 0 and len(text) < 50 and m.id in self.partial:  # the last chunk
                whole = self.partial.pop(m.id)
                p.texts.append(whole)
                self.on_text(whole)
        return m

    def wait_for(self, what: str, test: Callable[[Any], bool], timeout_s: float) -> Any:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if not self.vehicle_alive():
                # what it sent before it ended may still be waiting here
                while (m := self.conn.recv_match(blocking=False)) is not None:
                    if self._track(m) is not None and test(m):
                        return m
                raise VehicleEnded(f"the vehicle's process ended while waiting for {what}")
            m = self.receive(deadline - time.monotonic())
            if m is not None and test(m):
                return m
        raise GroundStationError(f"no {what} within {timeout_s:g} s")

    def connect(self, timeout_s: float = 10.0) -> None:
        self.wait_for(
            "heartbeat from the vehicle",
            lambda m: m.get_type() == "HEARTBEAT" and m.get_srcComponent() == 1,
            timeout_s,
        )

    # --- commands and parameters -----------------------------------------------------------

    def command(self, command: int, *params: float, timeout_s: float = 3.0) -> int:
        """COMMAND_LONG, retried every 0.5 s as MAVSDK does; the COMMAND_ACK's result."""
        values = [*params, *([0.0] * (7 - len(params)))]
        deadline = time.monotonic() + timeout_s
        confirmation = 0
        while time.monotonic() < deadline:
            self.conn.mav.command_long_send(*self.target, command, confirmation, *values)
            try:
                ack = self.wait_for(
                    f"COMMAND_ACK for command {command}",
                    lambda m: m.get_type() == "COMMAND_ACK" and m.command == command,
                    min(0.5, max(deadline - time.monotonic(), 0.01)),
                )
                return int(ack.result)
            except GroundStationError:
                confirmation += 1
        raise GroundStationError(f"command {command} not acknowledged within {timeout_s:g} s")

    def stop_streams(self, *names: str) -> None:
        """Asks the vehicle not to stream these messages (MAV_CMD_SET_MESSAGE_INTERVAL -1, as
        a ground station asks for what it shows): each would cost both ends a decode and a
        wake-up many times a wall second in a flight faster than real time."""
        for name in names:
            msg_id = getattr(mav, f"MAVLINK_MSG_ID_{name}")
            self.require(mav.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, -1, what=f"stopping {name}")

    def require(self, command: int, *params: float, what: str) -> None:
        result = self.command(command, *params)
        if result != mav.MAV_RESULT_ACCEPTED:
            why = self.progress.texts[-1] if self.progress.texts else ""
            name = (
                mav.enums["MAV_RESULT"][result].name
                if result in mav.enums["MAV_RESULT"]
                else result
            )
            raise GroundStationError(f"{what} refused ({name}){': ' + why if why else ''}")

    def set_param(self, name: str, value: float, timeout_s: float = 3.0) -> float:
        """PARAM_SET; the value the vehicle says is in force afterwards."""
        self.conn.mav.param_set_send(*self.target, name.encode(), value, mav.MAV_PARAM_TYPE_REAL32)
        m = self.wait_for(
            f"PARAM_VALUE {name}",
            lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == name,
            timeout_s,
        )
        return float(m.param_value)

    def get_param(self, name: str, timeout_s: float = 3.0) -> Any:
        self.conn.mav.param_request_read_send(*self.target, name.encode(), -1)
        return self.wait_for(
            f"PARAM_VALUE {name}",
            lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == name,
            timeout_s,
        )

    # --- missions ----------------------------------------------------------------------------

    def upload(self, items: tuple[MissionItem, ...], timeout_s: float = 10.0) -> None:
        """The mission protocol: count, answer each request, the vehicle's ack."""
        self.conn.mav.mission_count_send(*self.target, len(items), mav.MAV_MISSION_TYPE_MISSION)
        deadline = time.monotonic() + timeout_s
        while True:
            m = self.wait_for(
                "MISSION_REQUEST_INT or MISSION_ACK",
                lambda m: m.get_type() in ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"),
                max(deadline - time.monotonic(), 0.01),
            )
            if m.get_type() == "MISSION_ACK":
                if m.type != mav.MAV_MISSION_ACCEPTED:
                    why = self.progress.texts[-1] if self.progress.texts else ""
                    name = mav.enums["MAV_MISSION_RESULT"][m.type].name
                    raise GroundStationError(f"mission refused ({name}): {why}")
                return
            if 0 <= m.seq < len(items):
                self.conn.mav.send(item_message(items[m.seq], m.seq, m.seq == 0, self.target))

    def download(self, timeout_s: float = 10.0) -> tuple[MissionItem, ...]:
        self.conn.mav.mission_request_list_send(*self.target, mav.MAV_MISSION_TYPE_MISSION)
        count = self.wait_for(
            "MISSION_COUNT", lambda m: m.get_type() == "MISSION_COUNT", timeout_s
        ).count
        items = []
        for seq in range(count):
            self.conn.mav.mission_request_int_send(*self.target, seq, mav.MAV_MISSION_TYPE_MISSION)
            m = self.wait_for(
                f"MISSION_ITEM_INT {seq}",
                lambda m, seq=seq: m.get_type() == "MISSION_ITEM_INT" and m.seq == seq,
                timeout_s,
            )
            items.append(item_from_message(m))
        self.conn.mav.mission_ack_send(*self.target, mav.MAV_MISSION_ACCEPTED, 0)
        return tuple(items)

    # --- a whole flight ------------------------------------------------------------------------

    def wait_armable(self, timeout_s: float = 10.0) -> None:
        self.wait_for(
            "pre-arm checks passing",
            lambda m: (
                m.get_type() == "SYS_STATUS"
                and m.onboard_control_sensors_health & mav.MAV_SYS_STATUS_PREARM_CHECK
            ),
            timeout_s,
        )

    def fly_mission(self, items: tuple[MissionItem, ...], timeout_s: float) -> Progress:
        """Upload, arm, start; follow until the vehicle has landed and disarmed."""
        self.upload(items)
        self.wait_armable()
        self.require(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, what="arming")
        self.require(mav.MAV_CMD_MISSION_START, 0, 0, what="mission start")
        p = self.progress
        self.wait_for(
            "disarm after landing",
            lambda m: p.was_armed and not p.armed,
            timeout_s,
        )
        return p
