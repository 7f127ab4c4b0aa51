"""Mission files: the minimal YAML form (local waypoints), validated into mission items.

takeoff_altitude_m: 1.0          # above the start point
waypoints:
  - {position_m: [0.5, 0.0, 1.0], hold_s: 1.0, acceptance_radius_m: 0.05}
  - {position_m: [0.5, 0.0, 0.03], hold_s: 4.0}
land: true                       # land below the last waypoint when done
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from autopilot.mission_items import Home, MissionItem, Waypoint, waypoint_items
from simbridge.config import ConfigError, build, load_yaml, param


@dataclass(frozen=True)
class MissionFile:
    takeoff_altitude_m: float = param(1.0, unit="m", lo=0.05, hi=100.0, doc="above the start")
    land: bool = param(True, doc="land below the last waypoint")


@dataclass(frozen=True)
class LocalMission:
    waypoints: tuple[Waypoint, ...]
    takeoff_altitude_m: float
    land: bool

    def items(self, origin: Home) -> tuple[MissionItem, ...]:
        return waypoint_items(self.waypoints, self.takeoff_altitude_m, self.land, origin)

    @property
    def waypoint_timeout_s(self) -> float | None:
        """The longest waypoint timeout: MAVLink items have no field for it, the vehicle has
        a parameter (GFX_WP_TIMEOUT)."""
        timeouts = [w.timeout_s for w in self.waypoints if w.timeout_s is not None]
        return max(timeouts) if timeouts else None


def parse_mission(data: dict[str, Any], where: str) -> LocalMission:
    data = dict(data)
    entries = data.pop("waypoints", None)
    head = build(MissionFile, {k: v for k, v in data.items() if k != "name"}, where)
    if not isinstance(entries, list) or not entries:
        raise ConfigError(f"{where}: waypoints: expected a non-empty list of waypoints")
    waypoints = tuple(build(Waypoint, e, f"{where}: waypoints[{i}]") for i, e in enumerate(entries))
    return LocalMission(waypoints, head.takeoff_altitude_m, head.land)


def load_mission(path: str | Path) -> LocalMission:
    return parse_mission(load_yaml(Path(path)), str(path))
