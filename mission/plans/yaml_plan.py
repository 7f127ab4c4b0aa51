"""YAML missions in local metres (the format of mission/examples) to and from MAVLink items.

    home: {lat_deg: 59.3498, lon_deg: 18.0707, alt_m: 28.0}  # optional: the local origin
    takeoff_altitude_m: 1.0     # NAV_TAKEOFF where the vehicle stands, to 1 m above home
    waypoints:                  # NAV_WAYPOINTs, metres from home: x east, y north, z up
      - {position_m: [0.5, 0.0, 1.0], hold_s: 1.0, speed_m_s: 0.5}  # DO_CHANGE_SPEED first
      - {position_m: [0.0, 0.0, 0.03], hold_s: 6.0, acceptance_radius_m: 0.01, timeout_s: 8.0}
    land: true                  # NAV_LAND below the last waypoint; or `return: true` (RTL)

Reading loses: sub-centimetre positions (latitude and longitude snap to the degE7 grid, about
1.1 cm north and 0.6 cm east here); per-waypoint timeouts (the largest becomes the mission's
`waypoint_timeout_s`); `name` and comments. A missing `yaw_deg` is NaN, the vehicle's choice.
Writing keeps only what `yaml_form` keeps and refuses, naming the item and the field, any
item the format cannot hold; what it writes reads back to exactly those items. Positions are
written as the roundest metres (at most 4 decimals) in their degE7 cell: 0.5, not 0.4994,
and a YAML 0.123 that shares its cell with 0.12 comes back as 0.12.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import yaml

from autopilot.commander.mission_items import (
    DO_CHANGE_SPEED,
    FRAME_MISSION,
    GLOBAL_FRAMES,
    MSL_FRAMES,
    NAV_LAND,
    NAV_RETURN_TO_LAUNCH,
    NAV_TAKEOFF,
    NAV_WAYPOINT,
    NO_POSITION,
    Home,
    MissionItem,
    item_at,
    speed_item,
)
from mission.plans.doc import (
    MissionDoc,
    ParsedMission,
    default_home,
    flip_yaw_deg,
    roundest,
    wrap_deg,
)
from simbridge.config import ConfigError, build, param
from simbridge.frames import Vec3, geodetic_to_local
from simbridge.hil import mavlink as mav

RELATIVE_FRAME = mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT  # what `item_at` writes
DEFAULT_ACCEPTANCE_M = 0.05  # the old format's default, kept so existing files mean the same
YAW_TOLERANCE_DEG = 1e-9  # yaw's conversion may move the last bit of a float; nothing more


@dataclass(frozen=True)
class YamlHome:
    lat_deg: float = param(unit="deg", lo=-90.0, hi=90.0, doc="latitude of x = y = 0")
    lon_deg: float = param(unit="deg", lo=-180.0, hi=180.0, doc="longitude of x = y = 0")
    alt_m: float = param(unit="m", lo=-500.0, hi=9000.0, doc="ground altitude AMSL at home")


@dataclass(frozen=True)
class YamlHead:
    name: str = param("", doc="a label; not kept in .plan or .waypoints")
    takeoff_altitude_m: float = param(1.0, unit="m", lo=0.05, hi=100.0, doc="above home")
    land: bool = param(True, doc="land below the last waypoint")
    home: YamlHome | None = param(None, doc="the local origin (default: the given origin)")


@dataclass(frozen=True)
class YamlWaypoint:
    position_m: Vec3 = param(unit="m", lo=-1000.0, hi=1000.0, doc="x east, y north, z up")
    hold_s: float = param(0.0, unit="s", lo=0.0, hi=3600.0, doc="time to hold once reached")
    acceptance_radius_m: float = param(
        DEFAULT_ACCEPTANCE_M, unit="m", lo=0.0, hi=100.0, doc="reached within; 0: vehicle default"
    )
    yaw_deg: float | None = param(
        None, unit="deg", lo=-180.0, hi=180.0, doc="from east, counter-clockwise; null: free"
    )
    timeout_s: float | None = param(
        None, unit="s", lo=0.0, hi=3600.0, doc="not reached this long after setting out: hold it"
    )
    speed_m_s: float | None = param(
        None, unit="m/s", lo=0.0, lo_open=True, hi=20.0, doc="DO_CHANGE_SPEED before this waypoint"
    )


def return_item() -> MissionItem:
    return MissionItem(NAV_RETURN_TO_LAUNCH, frame=FRAME_MISSION)


def parse_yaml(data: dict[str, Any], where: str, origin: Home) -> ParsedMission:
    """Items from a YAML mapping; `origin` is home unless the file names its own."""
    data = dict(data)
    entries = data.pop("waypoints", None)
    rtl = data.pop("return", False)
    if not isinstance(rtl, bool):
        raise ConfigError(f"{where}.return: expected true or false, got {rtl!r}")
    head = build(YamlHead, data, where)
    if rtl and data.get("land") is True:
        raise ConfigError(f"{where}: land and return: choose one (return: true lands at home)")
    if not isinstance(entries, list) or not entries:
        raise ConfigError(f"{where}: waypoints: expected a non-empty list of waypoints")
    waypoints = [build(YamlWaypoint, e, f"{where}: waypoints[{i}]") for i, e in enumerate(entries)]
    home = origin if head.home is None else Home(**dataclasses.asdict(head.home))

    items = [MissionItem(NAV_TAKEOFF, z=head.takeoff_altitude_m)]
    locations = ["takeoff_altitude_m"]
    for i, wp in enumerate(waypoints):
        if wp.speed_m_s is not None:
            items.append(speed_item(wp.speed_m_s))
            locations.append(f"waypoints[{i}].speed_m_s")
        yaw = math.nan if wp.yaw_deg is None else flip_yaw_deg(wp.yaw_deg)
        items.append(
            item_at(
                NAV_WAYPOINT, home, wp.position_m, wp.hold_s, wp.acceptance_radius_m, param4=yaw
            )
        )
        locations.append(f"waypoints[{i}]")
    if rtl:
        items.append(return_item())
        locations.append("return")
    elif head.land:
        east, north, _ = waypoints[-1].position_m
        items.append(item_at(NAV_LAND, home, (east, north, 0.0)))
        locations.append("land")
    timeouts = [wp.timeout_s for wp in waypoints if wp.timeout_s is not None]
    doc = MissionDoc(tuple(items), home, max(timeouts) if timeouts else None)
    return ParsedMission(doc, tuple(locations), {})


def yaml_form(items: tuple[MissionItem, ...], home: Home) -> tuple[MissionItem, ...]:
    """The items as the YAML format keeps them. It drops: the frame (every position becomes
    relative to home, MSL altitudes less home's); a take-off's position when it is home's and
    its params 1-3 (minimum pitch: fixed wings); DO_CHANGE_SPEED's speed type and throttle
    (param1, param3); RTL's params; a yaw's turns (kept in (-180, 180]). A NAV_LAND with no
    position lands below the waypoint before it, where the vehicle is."""
    home_xy = (round(home.lat_deg * 1e7), round(home.lon_deg * 1e7))
    kept: list[MissionItem] = []
    last_xy: tuple[int, int] | None = None
    for item in items:
        if item.command == DO_CHANGE_SPEED:
            kept.append(speed_item(item.param2))
            continue
        if item.command == NAV_RETURN_TO_LAUNCH:
            kept.append(return_item())
            continue
        if item.frame in GLOBAL_FRAMES:
            z = item.z
            if item.frame in MSL_FRAMES:
                z = roundest(item.z - home.alt_m, lambda r, item=item: r + home.alt_m == item.z)
            item = dataclasses.replace(item, frame=RELATIVE_FRAME, z=z)
        item = dataclasses.replace(item, param4=wrap_deg(item.param4))
        if item.command == NAV_TAKEOFF:
            xy = (NO_POSITION, NO_POSITION) if (item.x, item.y) == home_xy else (item.x, item.y)
            item = dataclasses.replace(item, param1=0.0, param2=0.0, param3=0.0, x=xy[0], y=xy[1])
        no_position = (item.x, item.y) == (NO_POSITION, NO_POSITION)
        if item.command == NAV_LAND and no_position and last_xy is not None:
            item = dataclasses.replace(item, x=last_xy[0], y=last_xy[1])
        if item.command == NAV_WAYPOINT:
            last_xy = (item.x, item.y)
        kept.append(item)
    return tuple(kept)


class _FlowList(list):
    """Written on one line: `[0.5, 0.0, 1.0]`."""


class _FlowMap(dict):
    """Written on one line: `{position_m: [...], hold_s: 1.0}`, as in the examples."""


class _Dumper(yaml.SafeDumper):
    def increase_indent(self, flow: bool = False, indentless: bool = False) -> None:
        # "  - {...}" under "waypoints:", as the hand-written examples have it
        return super().increase_indent(flow, False)


_Dumper.add_representer(
    _FlowMap, lambda d, m: d.represent_mapping("tag:yaml.org,2002:map", m, flow_style=True)
)
_Dumper.add_representer(
    _FlowList, lambda d, s: d.represent_sequence("tag:yaml.org,2002:seq", s, flow_style=True)
)

HEADER = (
    "# groundfx mission: metres from home, x east, y north, z up (see mission/plans/yaml_plan.py)\n"
)


def _no_yaml(seq: int, item: MissionItem, why: str) -> ConfigError:
    return ConfigError(
        f"item {seq} ({item.name}): {why}; save as .plan or .waypoints to keep this mission"
    )


def _exact(value: float) -> float:
    return roundest(value, lambda r: r == value)


def _waypoint(item: MissionItem, home: Home, speed_m_s: float | None) -> dict[str, Any]:
    east, north = geodetic_to_local(home.lat_deg, home.lon_deg, item.x * 1e-7, item.y * 1e-7)

    def same_cell(e: float, n: float) -> bool:
        again = item_at(NAV_WAYPOINT, home, (e, n, 0.0))
        return (again.x, again.y) == (item.x, item.y)

    east = roundest(east, lambda e: same_cell(e, north))
    north = roundest(north, lambda n: same_cell(east, n))
    entry: dict[str, Any] = {
        "position_m": _FlowList([east, north, _exact(item.z)]),
        "hold_s": _exact(item.param1),
    }
    if item.param2 != DEFAULT_ACCEPTANCE_M:
        entry["acceptance_radius_m"] = _exact(item.param2)
    if not math.isnan(item.param4):
        yaw = flip_yaw_deg(item.param4)
        entry["yaw_deg"] = roundest(yaw, lambda r: flip_yaw_deg(r) == item.param4, 6)
    if speed_m_s is not None:
        entry["speed_m_s"] = _exact(speed_m_s)
    return entry


def _mapping(items: tuple[MissionItem, ...], doc: MissionDoc) -> dict[str, Any]:
    if not items or items[0].command != NAV_TAKEOFF:
        first = f"item 0 ({items[0].name})" if items else "an empty mission"
        raise ConfigError(
            f"{first}: a YAML mission begins with NAV_TAKEOFF; save as .plan or .waypoints"
        )
    mapping: dict[str, Any] = {}
    if doc.home != default_home():
        mapping["home"] = _FlowMap(dataclasses.asdict(doc.home))
    mapping["takeoff_altitude_m"] = _exact(items[0].z)
    waypoints: list[dict[str, Any]] = []
    speed: float | None = None
    end: int | None = None
    for seq, item in enumerate(items[1:], start=1):
        if end is not None:
            raise _no_yaml(seq, item, "YAML ends with its land or return")
        if item.command == DO_CHANGE_SPEED:
            if speed is not None:
                raise _no_yaml(seq, item, "YAML holds one speed change before each waypoint")
            speed = item.param2
        elif item.command == NAV_WAYPOINT:
            waypoints.append(_waypoint(item, doc.home, speed))
            speed = None
        elif item.command in (NAV_LAND, NAV_RETURN_TO_LAUNCH):
            end = item.command
        else:
            raise _no_yaml(seq, item, "YAML takes off once, as its first item")
    if speed is not None:
        raise _no_yaml(len(items) - 1, items[-1], "in YAML a speed change precedes a waypoint")
    if not waypoints:
        raise ConfigError("a YAML mission needs a NAV_WAYPOINT; save as .plan or .waypoints")
    if doc.waypoint_timeout_s is not None:
        waypoints[-1]["timeout_s"] = _exact(doc.waypoint_timeout_s)
    mapping["waypoints"] = [_FlowMap(w) for w in waypoints]
    if end == NAV_RETURN_TO_LAUNCH:
        mapping["return"] = True
    else:
        mapping["land"] = end == NAV_LAND
    return mapping


def _difference(a: MissionItem, b: MissionItem) -> str | None:
    """The first field in which two items differ (NaN equal to NaN), or None."""
    for f in dataclasses.fields(MissionItem):
        u, v = getattr(a, f.name), getattr(b, f.name)
        if u == v or (isinstance(u, float) and math.isnan(u) and math.isnan(v)):
            continue
        if f.name == "param4" and abs(u - v) <= YAW_TOLERANCE_DEG:
            continue
        return f.name
    return None


def dump_yaml(doc: MissionDoc) -> str:
    """The mission as YAML text; ConfigError naming the item if YAML cannot hold it."""
    items = yaml_form(doc.items, doc.home)
    text = HEADER + yaml.dump(_mapping(items, doc), Dumper=_Dumper, sort_keys=False, width=1000)
    try:
        back = parse_yaml(yaml.safe_load(text), "YAML", doc.home).doc
    except ConfigError as err:  # e.g. a DO_CHANGE_SPEED of -1 (no change): out of YAML's range
        raise ConfigError(f"no YAML form: {err}; save as .plan or .waypoints") from None
    for seq, (want, got) in enumerate(zip(items, back.items, strict=True)):
        field = _difference(want, got)
        if field is not None:
            raise _no_yaml(
                seq,
                want,
                f"{field}: YAML cannot hold {getattr(want, field)!r} "
                f"(it would read back as {getattr(got, field)!r})",
            )
    return text
