"""What every room of the autopilot passes around: the vehicle's state, a setpoint, the flight
mode, and one lockstep step's messages from the simulator."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from simbridge.frames import Quat, Vec3


@dataclass(frozen=True)
class FlightState:
    position_m: Vec3  # world x east, y north, z up
    velocity_m_s: Vec3  # world frame
    quaternion: Quat  # (w, x, y, z), body to world
    angular_velocity_body_rad_s: Vec3  # body x forward, y left, z up


@dataclass(frozen=True)
class Setpoint:
    position_m: Vec3
    velocity_m_s: Vec3 = (0.0, 0.0, 0.0)
    acceleration_m_s2: Vec3 = (0.0, 0.0, 0.0)
    yaw_rad: float = 0.0


class FlightMode(StrEnum):
    """What a ground station chose; each identity encodes it in HEARTBEAT.custom_mode
    (autopilot/identity.py)."""

    HOLD = "hold"  # hold position (on the ground: wait)
    MISSION = "mission"
    TAKEOFF = "takeoff"
    LAND = "land"
    RETURN = "return"
    OFFBOARD = "offboard"
    GUIDED = "guided"  # go to a target, then hold there (ArduCopter's Guided; PX4's reposition)


@dataclass
class Step:
    """The latest message of each kind, as fields, when a HIL_SENSOR closed the step."""

    sensor: dict[str, Any]
    latest: dict[str, dict[str, Any]] = field(default_factory=dict)
    new: set[str] = field(default_factory=set)  # kinds that arrived during this step
