"""The mission model: MAVLink mission items, their validation, and the plan the vehicle flies.

A mission is a tuple of `MissionItem`s exactly as they travel in MISSION_ITEM_INT (latitude
and longitude in degE7, altitude in metres, relative to home in the relative frames), so
that a mission downloaded is bit-for-bit the mission uploaded. `plan_steps` turns it into
local steps (x east, y north, z up, metres) for the commander.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from simbridge.config import param
from simbridge.frames import Vec3, geodetic_to_local, local_to_geodetic

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mav

NAV_WAYPOINT = mav.MAV_CMD_NAV_WAYPOINT
NAV_TAKEOFF = mav.MAV_CMD_NAV_TAKEOFF
NAV_LAND = mav.MAV_CMD_NAV_LAND
NAV_RETURN_TO_LAUNCH = mav.MAV_CMD_NAV_RETURN_TO_LAUNCH
DO_CHANGE_SPEED = mav.MAV_CMD_DO_CHANGE_SPEED

COMMAND_NAMES = {
    NAV_WAYPOINT: "NAV_WAYPOINT",
    NAV_TAKEOFF: "NAV_TAKEOFF",
    NAV_LAND: "NAV_LAND",
    NAV_RETURN_TO_LAUNCH: "NAV_RETURN_TO_LAUNCH",
    DO_CHANGE_SPEED: "DO_CHANGE_SPEED",
}
# Frames whose x, y are latitude and longitude in degE7; altitude MSL for 0 and 5, relative
# to home for 3 and 6, above terrain for 10 (flat ground here: the same as relative).
GLOBAL_FRAMES = {
    mav.MAV_FRAME_GLOBAL: "GLOBAL",
    mav.MAV_FRAME_GLOBAL_RELATIVE_ALT: "GLOBAL_RELATIVE_ALT",
    mav.MAV_FRAME_GLOBAL_INT: "GLOBAL_INT",
    mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: "GLOBAL_RELATIVE_ALT_INT",
    mav.MAV_FRAME_GLOBAL_TERRAIN_ALT: "GLOBAL_TERRAIN_ALT",
}
MSL_FRAMES = (mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_INT)
FRAME_MISSION = mav.MAV_FRAME_MISSION
FRAME_NAMES = {**GLOBAL_FRAMES, FRAME_MISSION: "MISSION"}
# Commands without a position may come in the mission frame or any global frame.
POSITIONLESS = (DO_CHANGE_SPEED, NAV_RETURN_TO_LAUNCH)
NO_POSITION = 0  # x = y = 0 on NAV_TAKEOFF / NAV_LAND: "where the vehicle is"


@dataclass(frozen=True)
class MissionItem:
    command: int
    frame: int = mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = math.nan
    x: int = 0  # latitude, degE7
    y: int = 0  # longitude, degE7
    z: float = 0.0  # altitude, m (relative to home, or MSL in frames 0 and 5)
    autocontinue: int = 1

    @property
    def name(self) -> str:
        return COMMAND_NAMES.get(self.command, f"command {self.command}")

    def same_as(self, other: MissionItem) -> bool:
        """Equal field by field, NaN equal to NaN (a yaw left to the vehicle)."""
        a, b = self.__dict__, other.__dict__
        return all(
            a[k] == b[k] or (isinstance(a[k], float) and math.isnan(a[k]) and math.isnan(b[k]))
            for k in a
        )


@dataclass(frozen=True)
class Home:
    lat_deg: float
    lon_deg: float
    alt_m: float  # MSL altitude of the surface the vehicle started from


@dataclass(frozen=True)
class Geofence:
    max_altitude_m: float = 0.0  # above home; 0: no limit
    max_radius_m: float = 0.0  # horizontal distance from home; 0: no limit

    def breach(self, east_m: float, north_m: float, up_m: float) -> str | None:
        """Why a point relative to home lies outside the fence, or None."""
        if self.max_altitude_m > 0.0 and up_m > self.max_altitude_m:
            return f"{up_m:.2f} m above home is over the maximum altitude {self.max_altitude_m:g} m"
        distance = math.hypot(east_m, north_m)
        if self.max_radius_m > 0.0 and distance > self.max_radius_m:
            return (
                f"{distance:.2f} m from home is beyond the maximum radius {self.max_radius_m:g} m"
            )
        return None


class MissionError(ValueError):
    """An item the vehicle refuses: `result` is the MAV_MISSION_RESULT to acknowledge with."""

    def __init__(self, seq: int, item: MissionItem, field: str, why: str, result: int) -> None:
        super().__init__(f"item {seq} ({item.name}): {field}: {why}")
        self.seq, self.field, self.result = seq, field, result


def _finite(seq: int, item: MissionItem, names: tuple[str, ...], nan_ok: bool = False) -> None:
    """`nan_ok`: an unused parameter may be NaN (MAVSDK's "not set"), never infinite."""
    results = {
        "param1": mav.MAV_MISSION_INVALID_PARAM1,
        "param2": mav.MAV_MISSION_INVALID_PARAM2,
        "param3": mav.MAV_MISSION_INVALID_PARAM3,
        "param4": mav.MAV_MISSION_INVALID_PARAM4,
        "z": mav.MAV_MISSION_INVALID_PARAM7,
    }
    for name in names:
        value = getattr(item, name)
        if math.isinf(value) or (math.isnan(value) and not nan_ok):
            raise MissionError(seq, item, name, f"{value} is not a finite number", results[name])


def degrees_e7(seq: int, item: MissionItem, field: str, degrees: float) -> int:
    """A latitude or longitude in degrees (MISSION_ITEM's floats) as degE7. NaN or inf is
    refused: rounded to an integer it would be a real place (0 deg: the equator)."""
    result = mav.MAV_MISSION_INVALID_PARAM5_X if field == "x" else mav.MAV_MISSION_INVALID_PARAM6_Y
    if not math.isfinite(degrees):
        raise MissionError(seq, item, field, f"{degrees} is not a finite number", result)
    # far outside any range, yet an int: the range check below names it
    return round(max(-1e12, min(1e12, degrees * 1e7)))


def local_offset(item: MissionItem, home: Home) -> Vec3:
    """The item's position relative to home: (east, north, up) in metres."""
    east, north = geodetic_to_local(home.lat_deg, home.lon_deg, item.x * 1e-7, item.y * 1e-7)
    up = item.z - home.alt_m if item.frame in MSL_FRAMES else item.z
    return (east, north, up)


def validate_item(seq: int, item: MissionItem, home: Home, fence: Geofence) -> None:
    """Raise MissionError naming the item and the field if the vehicle cannot fly it."""
    if item.command not in COMMAND_NAMES:
        raise MissionError(
            seq,
            item,
            "command",
            f"unsupported; the vehicle flies {', '.join(COMMAND_NAMES.values())}",
            mav.MAV_MISSION_UNSUPPORTED,
        )
    allowed = dict(FRAME_NAMES) if item.command in POSITIONLESS else dict(GLOBAL_FRAMES)
    if item.frame not in allowed:
        raise MissionError(
            seq,
            item,
            "frame",
            f"{item.frame} is not one of {sorted(allowed)} ({', '.join(allowed.values())})",
            mav.MAV_MISSION_UNSUPPORTED_FRAME,
        )
    _finite(seq, item, ("param1", "param2", "param3", "param4", "z"), nan_ok=True)
    if item.command == DO_CHANGE_SPEED:
        _finite(seq, item, ("param2",))
        if not 0.0 < item.param2 <= 20.0 and item.param2 != -1.0:
            raise MissionError(
                seq,
                item,
                "param2",
                f"speed {item.param2:g} m/s outside (0, 20] (or -1: no change)",
                mav.MAV_MISSION_INVALID_PARAM2,
            )
        return
    if item.command == NAV_RETURN_TO_LAUNCH:
        return
    # A take-off's param1 (pitch) and a landing's (abort altitude) are unused here; MAVSDK
    # leaves them NaN. A waypoint's (hold) must be a number.
    _finite(seq, item, ("z",))
    if item.command == NAV_WAYPOINT:
        _finite(seq, item, ("param1", "param2"))
        if not 0.0 <= item.param1 <= 3600.0:
            raise MissionError(
                seq, item, "param1", f"hold {item.param1:g} s outside [0, 3600]",
                mav.MAV_MISSION_INVALID_PARAM1,
            )  # fmt: skip
        if not 0.0 <= item.param2 <= 100.0:
            raise MissionError(
                seq, item, "param2", f"acceptance radius {item.param2:g} m outside [0, 100]",
                mav.MAV_MISSION_INVALID_PARAM2,
            )  # fmt: skip
    if not math.isnan(item.param4) and not -360.0 <= item.param4 <= 360.0:
        raise MissionError(
            seq, item, "param4", f"yaw {item.param4:g} deg outside [-360, 360] (or NaN)",
            mav.MAV_MISSION_INVALID_PARAM4,
        )  # fmt: skip
    positioned = item.command == NAV_WAYPOINT or (item.x, item.y) != (NO_POSITION, NO_POSITION)
    if positioned and not (-900_000_000 <= item.x <= 900_000_000):
        raise MissionError(
            seq, item, "x", f"latitude {item.x * 1e-7:g} deg outside [-90, 90]",
            mav.MAV_MISSION_INVALID_PARAM5_X,
        )  # fmt: skip
    if positioned and not (-1_800_000_000 <= item.y <= 1_800_000_000):
        raise MissionError(
            seq, item, "y", f"longitude {item.y * 1e-7:g} deg outside [-180, 180]",
            mav.MAV_MISSION_INVALID_PARAM6_Y,
        )  # fmt: skip
    if positioned:
        east, north, up = local_offset(item, home)
    else:
        east, north, up = 0.0, 0.0, item.z - home.alt_m if item.frame in MSL_FRAMES else item.z
    if item.command == NAV_LAND:
        up = 0.0  # a landing only descends
    why = fence.breach(east, north, up)
    if why is not None:
        field = "z" if "altitude" in why else "x"
        result = (
            mav.MAV_MISSION_INVALID_PARAM7 if field == "z" else mav.MAV_MISSION_INVALID_PARAM5_X
        )
        raise MissionError(seq, item, field, f"outside the geofence: {why}", result)


HOME_ROW_M = 1.0  # an item 0 this close to home (horizontally) is a home row


def is_home_row(item: MissionItem, home: Home) -> bool:
    """Whether item 0 of a mission is the home row ArduPilot keeps there, not a place to fly.

    Ground stations that know ArduPilot put home there: Mission Planner, QGroundControl,
    MAVProxy's WPL files (row 0), MAVSDK's mission_raw import (the plan's planned home); all
    as a waypoint in an MSL frame, or at home, or at 0, 0. MAVSDK's mission plugin does not:
    it sends its first waypoint as item 0, in the relative-altitude frame, and ArduCopter
    would overwrite it with home and never fly it. Here it is flown."""
    if item.command != NAV_WAYPOINT:
        return False
    if item.frame in MSL_FRAMES or (item.x, item.y) == (0, 0):
        return True
    east, north, _ = local_offset(item, home)
    return math.hypot(east, north) <= HOME_ROW_M


def validate_mission(items: tuple[MissionItem, ...], home: Home, fence: Geofence) -> None:
    for seq, item in enumerate(items):
        validate_item(seq, item, home, fence)


@dataclass(frozen=True)
class PlanStep:
    """One item as the commander flies it, in the local frame (x east, y north, z up)."""

    seq: int
    kind: str  # "waypoint", "takeoff", "land", "return", "speed"
    position_m: Vec3 | None = None  # None: where the vehicle is when the step begins
    altitude_m: float = 0.0  # takeoff: above home
    hold_s: float = 0.0
    acceptance_m: float = 0.0  # 0: the vehicle's default
    yaw_deg: float | None = None  # from east, counter-clockwise; None: keep the heading
    speed_m_s: float | None = None  # "speed": the new horizontal speed (None: unchanged)


KINDS = {
    NAV_WAYPOINT: "waypoint",
    NAV_TAKEOFF: "takeoff",
    NAV_LAND: "land",
    NAV_RETURN_TO_LAUNCH: "return",
    DO_CHANGE_SPEED: "speed",
}


def plan_steps(
    items: tuple[MissionItem, ...], origin: Home, home_up_m: float
) -> tuple[PlanStep, ...]:
    """The validated items as local steps. `origin` is the local frame's geodetic origin (its
    altitude that of z = 0); `home_up_m` the local z of home, which relative altitudes add to."""
    steps = []
    for seq, item in enumerate(items):
        kind = KINDS[item.command]
        # MAVLink yaw: degrees clockwise from north; ours: counter-clockwise from east
        yaw = None if math.isnan(item.param4) else 90.0 - item.param4
        up = item.z - origin.alt_m if item.frame in MSL_FRAMES else home_up_m + item.z
        if kind == "speed":
            speed = item.param2 if item.param2 > 0.0 else None
            steps.append(PlanStep(seq, kind, speed_m_s=speed))
            continue
        if kind == "return":
            steps.append(PlanStep(seq, kind))
            continue
        positioned = kind == "waypoint" or (item.x, item.y) != (NO_POSITION, NO_POSITION)
        position = None
        if positioned:
            east, north = geodetic_to_local(
                origin.lat_deg, origin.lon_deg, item.x * 1e-7, item.y * 1e-7
            )
            position = (east, north, up)
        if kind == "waypoint":
            steps.append(
                PlanStep(
                    seq, kind, position, hold_s=item.param1, acceptance_m=item.param2, yaw_deg=yaw
                )
            )
        elif kind == "takeoff":
            steps.append(PlanStep(seq, kind, position, altitude_m=up - home_up_m, yaw_deg=yaw))
        else:
            steps.append(PlanStep(seq, kind, position, yaw_deg=yaw))
    return tuple(steps)


def item_at(
    command: int,
    home: Home,
    offset_m: Vec3 | None,  # east, north, up of `home`
    param1: float = 0.0,
    param2: float = 0.0,
    param4: float = math.nan,
) -> MissionItem:
    """An item at `offset_m` (east, north, up of home), in the relative-altitude int frame;
    `offset_m` None: no position (take off or land where the vehicle is)."""
    if offset_m is None:
        return MissionItem(command, param1=param1, param2=param2, param4=param4)
    lat, lon = local_to_geodetic(home.lat_deg, home.lon_deg, offset_m[0], offset_m[1])
    return MissionItem(
        command,
        param1=param1,
        param2=param2,
        param4=param4,
        x=round(lat * 1e7),
        y=round(lon * 1e7),
        z=float(offset_m[2]),
    )


def speed_item(speed_m_s: float) -> MissionItem:
    """DO_CHANGE_SPEED: param1 1 ground speed, param2 the speed, param3 -1 throttle unchanged."""
    return MissionItem(
        DO_CHANGE_SPEED, frame=FRAME_MISSION, param1=1.0, param2=speed_m_s, param3=-1.0
    )


@dataclass(frozen=True)
class Waypoint:
    """A waypoint in the local frame, as mission YAML files and the data gatherer give them."""

    position_m: Vec3 = param(unit="m", lo=-1000.0, hi=1000.0, doc="local x east, y north, z up")
    acceptance_radius_m: float = param(0.05, unit="m", lo=0.001, hi=100.0, doc="reached within")
    hold_s: float = param(0.0, unit="s", lo=0.0, hi=3600.0, doc="time to hold once reached")
    yaw_deg: float = param(0.0, unit="deg", lo=-180.0, hi=180.0, doc="heading, from east")
    timeout_s: float | None = param(
        None,
        unit="s",
        lo=0.0,
        hi=3600.0,
        doc="the setpoint there this long but not the vehicle: hold it anyway (null: wait)",
    )


def waypoint_items(
    waypoints: tuple[Waypoint, ...], takeoff_altitude_m: float, land: bool, origin: Home
) -> tuple[MissionItem, ...]:
    """Take off, fly the local waypoints (`origin` at z = 0), land below the last one."""
    items = [item_at(NAV_TAKEOFF, origin, None, param4=math.nan)]
    items[0] = MissionItem(NAV_TAKEOFF, z=takeoff_altitude_m)
    for wp in waypoints:
        yaw = (90.0 - wp.yaw_deg + 180.0) % 360.0 - 180.0
        items.append(
            item_at(NAV_WAYPOINT, origin, wp.position_m, wp.hold_s, wp.acceptance_radius_m, yaw)
        )
    if land:
        last = waypoints[-1].position_m
        items.append(item_at(NAV_LAND, origin, (last[0], last[1], 0.0)))
    return tuple(items)
