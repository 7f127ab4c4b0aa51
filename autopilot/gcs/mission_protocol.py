"""The MAVLink mission protocol, vehicle side: upload, download, clear.

Upload: MISSION_COUNT -> the vehicle asks for each item with MISSION_REQUEST_INT (again after
`RETRY_S` without an answer, up to `RETRIES` times) -> MISSION_ITEM_INT (or legacy
MISSION_ITEM) -> MISSION_ACK after the last. Each item is validated as it arrives: the first
bad one ends the transfer with a MISSION_ACK naming the problem's class and a STATUSTEXT
naming item and field, and the mission the vehicle had stays. Download: MISSION_REQUEST_LIST
-> MISSION_COUNT -> MISSION_REQUEST_INT per item -> MISSION_ITEM_INT -> the station's ACK.
Fence and rally lists are empty: they download as zero items and uploads are refused.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from autopilot.commander.mission_items import (
    Geofence,
    Home,
    MissionError,
    MissionItem,
    degrees_e7,
    validate_item,
)
from autopilot.identity import Identity
from simbridge.hil import mavlink as mav

RETRY_S = 0.5
RETRIES = 5
MAX_ITEMS = 500
MISSION = mav.MAV_MISSION_TYPE_MISSION


@dataclass
class Upload:
    count: int
    peer: tuple[int, int]  # (sysid, compid) of the station uploading
    items: list[MissionItem] = field(default_factory=list)
    asked_s: float = 0.0
    tries: int = 0


@dataclass(frozen=True)
class Outcome:
    """What one message did: replies to send, and a new mission if an upload completed."""

    replies: tuple[Any, ...] = ()
    text: str | None = None  # a STATUSTEXT to send (why something was refused)
    mission: tuple[MissionItem, ...] | None = None  # a complete, validated upload
    cleared: bool = False


def item_from_message(m: Any) -> MissionItem:
    """A MISSION_ITEM_INT or a legacy MISSION_ITEM (degrees as floats) as a MissionItem;
    MissionError for a legacy item's coordinate that is not a number."""
    item = MissionItem(
        command=int(m.command),
        frame=int(m.frame),
        param1=float(m.param1),
        param2=float(m.param2),
        param3=float(m.param3),
        param4=float(m.param4),
        z=float(m.z),
        autocontinue=int(m.autocontinue),
    )
    if m.get_type() == "MISSION_ITEM":
        x = degrees_e7(int(m.seq), item, "x", float(m.x))
        y = degrees_e7(int(m.seq), item, "y", float(m.y))
    else:
        x, y = int(m.x), int(m.y)
    return dataclasses.replace(item, x=x, y=y)


def item_message(item: MissionItem, seq: int, current: bool, target: tuple[int, int]) -> Any:
    return mav.MAVLink_mission_item_int_message(
        target[0], target[1], seq, item.frame, item.command, int(current), item.autocontinue,
        item.param1, item.param2, item.param3, item.param4, item.x, item.y, item.z, MISSION,
    )  # fmt: skip


class MissionProtocol:
    def __init__(self, identity: Identity) -> None:
        self.identity = identity
        self.items: tuple[MissionItem, ...] = ()
        self.upload: Upload | None = None

    def ack(self, peer: tuple[int, int], result: int, mission_type: int = MISSION) -> Any:
        return mav.MAVLink_mission_ack_message(peer[0], peer[1], result, mission_type)

    def handle(
        self,
        m: Any,
        wall_s: float,
        home: Callable[[], Home],
        fence: Geofence,
        current: int,
    ) -> Outcome:
        kind = m.get_type()
        peer = (m.get_srcSystem(), m.get_srcComponent())
        mission_type = getattr(m, "mission_type", MISSION)
        if kind == "MISSION_COUNT":
            if mission_type != MISSION:
                return Outcome((self.ack(peer, mav.MAV_MISSION_UNSUPPORTED, mission_type),))
            if m.count > MAX_ITEMS:
                return Outcome(
                    (self.ack(peer, mav.MAV_MISSION_NO_SPACE),),
                    f"mission refused: {m.count} items, at most {MAX_ITEMS}",
                )
            if m.count == 0:
                self.upload = None
                self.items = ()
                return Outcome((self.ack(peer, mav.MAV_MISSION_ACCEPTED),), cleared=True)
            self.upload = Upload(m.count, peer, asked_s=wall_s)
            return Outcome((self._request(0, peer),))
        if kind in ("MISSION_ITEM_INT", "MISSION_ITEM"):
            return self._item(m, peer, wall_s, home, fence)
        if kind == "MISSION_REQUEST_LIST":
            count = len(self.items) if mission_type == MISSION else 0
            return Outcome(
                (mav.MAVLink_mission_count_message(peer[0], peer[1], count, mission_type),)
            )
        if kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            if kind == "MISSION_REQUEST" and not self.identity.legacy_mission_request:
                return Outcome((self.ack(peer, mav.MAV_MISSION_UNSUPPORTED),))
            if mission_type != MISSION or not 0 <= m.seq < len(self.items):
                return Outcome(
                    (self.ack(peer, mav.MAV_MISSION_INVALID_SEQUENCE, mission_type),),
                    f"no mission item {m.seq}",
                )
            item = self.items[m.seq]
            if kind == "MISSION_REQUEST":
                return Outcome((legacy_item_message(item, m.seq, m.seq == current, peer),))
            return Outcome((item_message(item, m.seq, m.seq == current, peer),))
        if kind == "MISSION_CLEAR_ALL":
            if mission_type != MISSION:
                return Outcome((self.ack(peer, mav.MAV_MISSION_ACCEPTED, mission_type),))
            self.items, self.upload = (), None
            return Outcome((self.ack(peer, mav.MAV_MISSION_ACCEPTED),), cleared=True)
        return Outcome()

    def _request(self, seq: int, peer: tuple[int, int]) -> Any:
        return mav.MAVLink_mission_request_int_message(peer[0], peer[1], seq, MISSION)

    def _item(
        self,
        m: Any,
        peer: tuple[int, int],
        wall_s: float,
        home: Callable[[], Home],
        fence: Geofence,
    ) -> Outcome:
        up = self.upload
        if up is None or peer != up.peer or getattr(m, "mission_type", MISSION) != MISSION:
            return Outcome()  # a stray or repeated item: the transfer it belonged to is over
        if m.seq != len(up.items):
            if m.seq < len(up.items):
                return Outcome()  # a duplicate of an item already taken
            return Outcome((self._request(len(up.items), peer),))
        try:
            item = item_from_message(m)
            validate_item(m.seq, item, home(), fence)
        except MissionError as e:
            self.upload = None
            return Outcome((self.ack(peer, e.result),), f"mission refused: {e}")
        up.items.append(item)
        if len(up.items) < up.count:
            up.asked_s, up.tries = wall_s, 0
            return Outcome((self._request(len(up.items), peer),))
        self.items = tuple(up.items)
        self.upload = None
        return Outcome((self.ack(peer, mav.MAV_MISSION_ACCEPTED),), mission=self.items)

    def tick(self, wall_s: float) -> Outcome:
        """Ask again for an item that has not come; give up after RETRIES."""
        up = self.upload
        if up is None or wall_s - up.asked_s < RETRY_S:
            return Outcome()
        if up.tries >= RETRIES:
            self.upload = None
            return Outcome(
                (self.ack(up.peer, mav.MAV_MISSION_OPERATION_CANCELLED),),
                f"mission upload timed out waiting for item {len(up.items)}",
            )
        up.asked_s, up.tries = wall_s, up.tries + 1
        return Outcome((self._request(len(up.items), up.peer),))


def legacy_item_message(item: MissionItem, seq: int, current: bool, target: tuple[int, int]) -> Any:
    return mav.MAVLink_mission_item_message(
        target[0], target[1], seq, item.frame, item.command, int(current), item.autocontinue,
        item.param1, item.param2, item.param3, item.param4, item.x * 1e-7, item.y * 1e-7, item.z,
        MISSION,
    )  # fmt: skip
