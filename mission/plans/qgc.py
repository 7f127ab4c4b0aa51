"""QGroundControl `.plan` files (JSON; plan version 1, mission version 2) to and from items.

Simple items only: a ComplexItem (survey, corridor or structure scan) is refused by name.
Frames are written as the items carry them, so nothing is lost (QGroundControl opens items in
the _INT frames 5 and 6 in its raw editor); NaN travels as null, as QGroundControl writes it;
latitude and longitude are degrees in params[4] and params[5] (`dege7_to_deg`). MAVLink has
no field for `waypoint_timeout_s`: it travels in a top-level `groundfx` object, which
QGroundControl and MAVSDK ignore. Written: firmwareType 12 (PX4), vehicleType 2 (quadrotor),
empty geoFence and rallyPoints.
"""

from __future__ import annotations

import json
import math
from typing import Any

from autopilot.commander.mission_items import GLOBAL_FRAMES, MSL_FRAMES, Home, MissionItem
from mission.plans.doc import (
    MissionDoc,
    ParsedMission,
    carries_position,
    check_home,
    deg_to_dege7,
    dege7_to_deg,
    integer,
    number,
)
from simbridge.config import ConfigError
from simbridge.hil import mavlink as mav

# How the file names MissionItem's fields, after the item's place (`mission.items[2]`)
PLAN_FIELDS = {
    "command": ".command",
    "frame": ".frame",
    "param1": ".params[0]",
    "param2": ".params[1]",
    "param3": ".params[2]",
    "param4": ".params[3]",
    "x": ".params[4]",
    "y": ".params[5]",
    "z": ".params[6]",
    "autocontinue": ".autoContinue",
}
# QGroundControl's AltitudeMode: 1 relative to home, 2 above mean sea level, 4 terrain frame
ALTITUDE_MODES = {mav.MAV_FRAME_GLOBAL_TERRAIN_ALT: 4} | {
    frame: 2 if frame in MSL_FRAMES else 1
    for frame in GLOBAL_FRAMES
    if frame != mav.MAV_FRAME_GLOBAL_TERRAIN_ALT
}
FIRMWARE_PX4 = 12
VEHICLE_QUADROTOR = 2


def _json_number(value: float) -> float | None:
    return None if math.isnan(value) else value


def _simple_item(seq: int, item: MissionItem) -> dict[str, Any]:
    if carries_position(item.command, item.frame):
        lat, lon = dege7_to_deg(item.x), dege7_to_deg(item.y)
    else:
        lat, lon = float(item.x), float(item.y)
    params = [item.param1, item.param2, item.param3, item.param4, lat, lon, item.z]
    entry: dict[str, Any] = {
        "autoContinue": bool(item.autocontinue),
        "command": item.command,
        "doJumpId": seq + 1,  # QGroundControl numbers items from 1
        "frame": item.frame,
        "params": [_json_number(p) for p in params],
        "type": "SimpleItem",
    }
    if carries_position(item.command, item.frame) and item.frame in ALTITUDE_MODES:
        entry["AMSLAltAboveTerrain"] = None  # only QGroundControl's terrain planning fills it
        entry["Altitude"] = _json_number(item.z)
        entry["AltitudeMode"] = ALTITUDE_MODES[item.frame]
    return entry


def dump_plan(doc: MissionDoc) -> str:
    plan: dict[str, Any] = {
        "fileType": "Plan",
        "geoFence": {"circles": [], "polygons": [], "version": 2},
        "groundStation": "groundfx",
        "mission": {
            "firmwareType": FIRMWARE_PX4,
            "items": [_simple_item(seq, item) for seq, item in enumerate(doc.items)],
            "plannedHomePosition": [doc.home.lat_deg, doc.home.lon_deg, doc.home.alt_m],
            "vehicleType": VEHICLE_QUADROTOR,
            "version": 2,
        },
        "rallyPoints": {"points": [], "version": 2},
        "version": 1,
    }
    if doc.waypoint_timeout_s is not None:
        plan["groundfx"] = {"waypoint_timeout_s": doc.waypoint_timeout_s}
    try:
        # sorted keys and 4-space indents: how QGroundControl (Qt) writes its files
        return json.dumps(plan, indent=4, sort_keys=True, allow_nan=False) + "\n"
    except ValueError:  # an infinity: JSON has no word for it
        raise ConfigError("a parameter is infinite; a .plan holds finite numbers or null") from None


def _get(mapping: Any, key: str, kind: type, where: str, what: str) -> Any:
    value = mapping.get(key) if isinstance(mapping, dict) else None
    if not isinstance(value, kind):
        raise ConfigError(f"{where}{key}: expected {what}, got {value!r}")
    return value


def _item(entry: Any, where: str) -> MissionItem:
    if not isinstance(entry, dict):
        raise ConfigError(f"{where}: expected an object (a SimpleItem), got {entry!r}")
    kind = entry.get("type")
    if kind == "ComplexItem":
        raise ConfigError(
            f"{where}: a ComplexItem ({entry.get('complexItemType', 'unknown kind')}) is not "
            "supported; groundfx reads SimpleItems only (waypoints, take-off, land, speed, RTL)"
        )
    if kind != "SimpleItem":
        raise ConfigError(f'{where}.type: expected "SimpleItem", got {kind!r}')
    command = integer(entry.get("command"), f"{where}.command", "a MAV_CMD")
    frame = integer(entry.get("frame"), f"{where}.frame", "a MAV_FRAME")
    params = entry.get("params")
    if not isinstance(params, list) or len(params) != 7:
        raise ConfigError(f"{where}.params: expected a list of 7 numbers or nulls, got {params!r}")
    p = [number(v, f"{where}.params[{i}]") for i, v in enumerate(params)]
    auto = entry.get("autoContinue", True)
    if not isinstance(auto, bool):
        raise ConfigError(f"{where}.autoContinue: expected true or false, got {auto!r}")
    if carries_position(command, frame):
        x = deg_to_dege7(p[4], f"{where}.params[4] (latitude)")
        y = deg_to_dege7(p[5], f"{where}.params[5] (longitude)")
    else:  # raw numbers, as MAVSDK reads them; null: 0
        x, y = (round(v) if math.isfinite(v) else 0 for v in (p[4], p[5]))
    return MissionItem(command, frame, p[0], p[1], p[2], p[3], x, y, p[6], int(auto))


def parse_plan(text: str, where: str) -> ParsedMission:
    try:
        data = json.loads(text)
    except json.JSONDecodeError as err:
        raise ConfigError(
            f"{where}: not valid JSON at line {err.lineno}, column {err.colno}: {err.msg}"
        ) from None
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: expected a JSON object at the top level")
    if data.get("fileType") != "Plan":
        raise ConfigError(f'{where}: fileType: expected "Plan", got {data.get("fileType")!r}')
    if data.get("version") != 1:
        raise ConfigError(f"{where}: version: expected 1, got {data.get('version')!r}")
    mission = _get(data, "mission", dict, f"{where}: ", "an object")
    if mission.get("version") != 2:
        raise ConfigError(f"{where}: mission.version: expected 2, got {mission.get('version')!r}")
    position = mission.get("plannedHomePosition")
    if not isinstance(position, list) or len(position) != 3:
        raise ConfigError(
            f"{where}: mission.plannedHomePosition: expected [lat, lon, alt], got {position!r}"
        )
    home_where = f"{where}: mission.plannedHomePosition"
    lat, lon, alt = (number(v, f"{home_where}[{i}]") for i, v in enumerate(position))
    home = check_home(Home(lat, lon, alt), home_where)
    entries = _get(mission, "items", list, f"{where}: mission.", "a list of items")
    locations = tuple(f"mission.items[{i}]" for i in range(len(entries)))
    items = tuple(_item(e, f"{where}: {loc}") for e, loc in zip(entries, locations, strict=True))
    extra = data.get("groundfx", {})
    timeout = extra.get("waypoint_timeout_s") if isinstance(extra, dict) else None
    if timeout is not None:
        timeout_where = f"{where}: groundfx.waypoint_timeout_s"
        timeout = number(timeout, timeout_where)
        if not 0.0 <= timeout <= 3600.0:
            raise ConfigError(
                f"{timeout_where}: {timeout!r} is outside the allowed range [0, 3600]"
            )
    doc = MissionDoc(items, home, timeout)
    return ParsedMission(doc, locations, PLAN_FIELDS)
