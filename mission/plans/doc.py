"""A mission document: MAVLink items with their planned home, as every mission file holds them.

The three file formats (`plan_yaml`, `plan_qgc`, `plan_wpl`) each turn text into a
`ParsedMission` and a `MissionDoc` back into text; `formats` picks the format and validates.
The numeric helpers here are shared so that each format writes numbers that read back exactly.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from autopilot.commander.mission_items import FRAME_MISSION, POSITIONLESS, Home, MissionItem
from simbridge.config import ConfigError

DEGE7_PER_DEG = 10_000_000


@dataclass(frozen=True)
class MissionDoc:
    items: tuple[MissionItem, ...]
    home: Home  # the planned home, also the local origin of YAML's metres
    # The largest per-waypoint `timeout_s` of a YAML mission: MAVLink has no field for it (the
    # vehicle has a parameter), so it travels beside the items. None: wait forever.
    waypoint_timeout_s: float | None = None


@dataclass(frozen=True)
class ParsedMission:
    doc: MissionDoc
    # Where each item came from in the file (e.g. "mission.items[2]", "line 4"), so that a
    # validation error can point there; and how the file names MissionItem's fields.
    locations: tuple[str, ...]
    field_names: dict[str, str]


@functools.cache
def default_home() -> Home:
    """The default world's geodetic origin: where `groundfx sim` puts the local frame."""
    from simbridge.world import load_world

    origin = load_world("default").origin
    return Home(origin.lat_deg, origin.lon_deg, origin.alt_m)


def check_home(home: Home, where: str) -> Home:
    """Refuse a home that is no place on Earth, naming the field and the range."""
    for name, value, lo, hi in (
        ("lat_deg", home.lat_deg, -90.0, 90.0),
        ("lon_deg", home.lon_deg, -180.0, 180.0),
        ("alt_m", home.alt_m, -500.0, 9000.0),
    ):
        if not (math.isfinite(value) and lo <= value <= hi):
            raise ConfigError(
                f"{where}: {name}: {value!r} is outside the allowed range [{lo:g}, {hi:g}]"
            )
    return home


def roundest(value: float, same: Callable[[float], bool], max_decimals: int = 4) -> float:
    """`value` with the fewest decimals (0 to `max_decimals`) that `same` accepts, else `value`.

    Files then say 0.5 rather than 0.49999999999999994 while every number still reads back
    to the very item it was written from (`same` checks that)."""
    for decimals in range(max_decimals + 1):
        candidate = round(value, decimals) + 0.0  # + 0.0: no "-0.0" in files
        if same(candidate):
            return candidate
    return value


def wrap_deg(angle_deg: float) -> float:
    """The same angle in (-180, 180]."""
    wrapped = math.fmod(angle_deg, 360.0)
    if wrapped > 180.0:
        wrapped -= 360.0
    elif wrapped <= -180.0:
        wrapped += 360.0
    return wrapped


def flip_yaw_deg(yaw_deg: float) -> float:
    """ENU yaw (from east, counter-clockwise) <-> MAVLink yaw (from north, clockwise).

    The map is its own inverse: both are 90 degrees minus the other. NaN stays NaN."""
    return wrap_deg(90.0 - yaw_deg)


def dege7_to_deg(value_dege7: int) -> float:
    """Degrees, 8 decimals, that readers which round and readers which truncate both take back
    to the same degE7: MAVProxy (`int(x * 1e7)`) truncates, so 59.3498123 may come back as
    593498122. A fifth of a unit away from zero (2 mm at most) lands both on the integer."""
    if value_dege7 == 0:
        return 0.0
    tenths = abs(value_dege7) * 10 + 2  # units of 1e-8 degree
    return math.copysign(tenths / (10 * DEGE7_PER_DEG), value_dege7)


def deg_to_dege7(value_deg: float, where: str) -> int:
    if not math.isfinite(value_deg):
        raise ConfigError(f"{where}: {value_deg!r} is not a finite angle in degrees")
    return round(value_deg * DEGE7_PER_DEG)


def carries_position(command: int, frame: int) -> bool:
    """Whether x and y are latitude and longitude (degE7) rather than plain numbers: MAVSDK and
    QGroundControl take them raw in the mission frame, MAVProxy for commands without a place."""
    return frame != FRAME_MISSION and command not in POSITIONLESS


def number(value: Any, where: str) -> float:
    """A JSON or text number as a float; null is NaN, as QGroundControl writes it."""
    if value is None:
        return math.nan
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{where}: expected a number or null, got {value!r}")
    return float(value)


def integer(value: Any, where: str, what: str) -> int:
    whole = isinstance(value, float) and value.is_integer()
    if not whole and (isinstance(value, bool) or not isinstance(value, int)):
        raise ConfigError(f"{where}: expected an integer ({what}), got {value!r}")
    return int(value)
