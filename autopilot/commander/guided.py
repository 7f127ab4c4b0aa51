"""Go-to and guided flight requests, as pure functions: DO_REPOSITION (PX4, MAVSDK's
goto_location, MAVProxy's `guided`), ArduPilot's guided MISSION_ITEM (current = 2), and the
setpoint messages SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT.

PX4 flies a reposition in hold (AUTO.LOITER) and takes setpoints in offboard; ArduCopter
flies all of them in Guided, where a position alone is a place to go to (MAVProxy's
`position`) and velocities and accelerations are followed until they stop coming
(GUID_TIMEOUT, our COM_OF_LOSS_T), then it holds, still in Guided.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from autopilot.commander import requests
from autopilot.commander.commander import CommanderState
from autopilot.commander.commander_params import CommanderParams
from autopilot.commander.mission_items import Geofence
from autopilot.commander.offboard import (
    Refused,
    Target,
    global_position,
    global_target,
    local_target,
)
from autopilot.identity import Identity
from autopilot.types import FlightMode
from simbridge.frames import Vec3
from simbridge.hil import mavlink as mav

DENIED = mav.MAV_RESULT_DENIED
GO_TO_FRAMES = (
    mav.MAV_FRAME_GLOBAL,
    mav.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    mav.MAV_FRAME_GLOBAL_INT,
    mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    mav.MAV_FRAME_GLOBAL_TERRAIN_ALT,
    mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
)
UNSET = 2**31 - 1  # INT32_MAX: COMMAND_INT's x or y not given


@dataclass(frozen=True)
class Context:
    identity: Identity
    origin: tuple[float, float, float]  # the local frame's geodetic origin
    home_m: Vec3
    home_up_m: float  # local z of the surface at home: relative altitudes count from it
    position_m: Vec3
    heading_rad: float  # ours: from east, counter-clockwise
    fence: Geofence
    time_s: float


def _fenced(target: Vec3, ctx: Context) -> str | None:
    home = ctx.home_m
    why = ctx.fence.breach(target[0] - home[0], target[1] - home[1], target[2] - home[2])
    return None if why is None else f"go-to denied: outside the geofence: {why}"


def _go(
    cmd: CommanderState, target: Vec3, yaw_deg: float | None, change_mode: bool, ctx: Context
) -> tuple[CommanderState, requests.Verdict]:
    if target[2] < ctx.home_up_m:
        return cmd, requests.Verdict(DENIED, "go-to denied: the target is below home")
    fenced = _fenced(target, ctx)
    if fenced is not None:
        return cmd, requests.Verdict(DENIED, fenced)
    if cmd.mode in ctx.identity.guided_modes:
        change_mode = True  # already in Guided
    return requests.reposition(
        cmd, target, yaw_deg, ctx.identity.hold_mode, change_mode, ctx.time_s, ctx.position_m
    )


def reposition(
    m: Any, cmd: CommanderState, ctx: Context
) -> tuple[CommanderState, requests.Verdict]:
    """MAV_CMD_DO_REPOSITION as COMMAND_INT (x, y degE7 in its frame) or COMMAND_LONG (p5, p6
    degrees, p7 altitude MSL); NaN: the vehicle's own. p4 yaw: PX4 radians (as MAVSDK sends
    it), ignored under ArduCopter, as ArduCopter does."""
    if m.get_type() == "COMMAND_INT":
        frame, lat, lon, alt = int(m.frame), m.x * 1e-7, m.y * 1e-7, float(m.z)
        if (m.x, m.y) == (0, 0) or UNSET in (m.x, m.y):
            lat = lon = math.nan  # no position: here
    else:
        frame, lat, lon, alt = mav.MAV_FRAME_GLOBAL, m.param5, m.param6, m.param7
    if frame not in GO_TO_FRAMES:
        return cmd, requests.Verdict(DENIED, f"go-to denied: frame {frame} is not global")
    try:
        target = global_position(frame, lat, lon, alt, ctx.origin, ctx.home_up_m, ctx.position_m)
    except Refused as e:
        return cmd, requests.Verdict(DENIED, str(e))
    yaw = None
    if ctx.identity.reposition_yaw and math.isfinite(m.param4):
        yaw = 90.0 - math.degrees(m.param4)
    flags = int(m.param2) if math.isfinite(m.param2) else 0
    change = bool(flags & mav.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE)
    return _go(cmd, target, yaw, change, ctx)


def guided_item(
    m: Any, cmd: CommanderState, ctx: Context
) -> tuple[CommanderState, requests.Verdict]:
    """ArduPilot's guided MISSION_ITEM(_INT) with current = 2: go there, in Guided only."""
    if int(m.command) != mav.MAV_CMD_NAV_WAYPOINT:
        return cmd, requests.Verdict(DENIED, "guided item denied: only NAV_WAYPOINT")
    if m.get_type() == "MISSION_ITEM_INT":
        lat, lon = m.x * 1e-7, m.y * 1e-7
    else:
        lat, lon = float(m.x), float(m.y)
    try:
        target = global_position(
            int(m.frame), lat, lon, float(m.z), ctx.origin, ctx.home_up_m, ctx.position_m
        )
    except Refused as e:
        return cmd, requests.Verdict(DENIED, str(e))
    # without a Guided mode the item switches to the go-to mode itself
    return _go(cmd, target, None, not ctx.identity.guided_modes, ctx)


def setpoint(m: Any, cmd: CommanderState, ctx: Context) -> tuple[CommanderState, str | None]:
    """SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT; returns the state and why the setpoint was
    refused (None: taken)."""
    try:
        target = _target(m, ctx)
    except Refused as e:
        return cmd, str(e)
    if not ctx.identity.guided_modes:
        return requests.offboard_setpoint(cmd, target, ctx.time_s), None  # flown in offboard
    if cmd.mode not in ctx.identity.guided_modes:
        return cmd, f"setpoint ignored: in {cmd.mode} mode (switch to GUIDED)"
    if target.position_only:
        cmd, verdict = _go(cmd, target.position_m, _yaw_deg(target), True, ctx)
        return cmd, verdict.reason or None
    cmd = requests.offboard_setpoint(cmd, target, ctx.time_s)
    if cmd.mode != FlightMode.OFFBOARD:
        if not requests.airborne(cmd):
            return cmd, "setpoint ignored: not flying (take off first)"
        # the setpoint has just come: any offboard timeout lets the mode in
        params = CommanderParams()
        cmd, _ = requests.set_mode(cmd, FlightMode.OFFBOARD, ctx.time_s, ctx.position_m, params)
    return cmd, None


def _yaw_deg(target: Target) -> float | None:
    return math.degrees(target.yaw_rad) if math.isfinite(target.yaw_rad) else None


def _target(m: Any, ctx: Context) -> Target:
    if m.get_type() == "SET_POSITION_TARGET_GLOBAL_INT":
        fields = (m.alt, m.vx, m.vy, m.vz, m.afx, m.afy, m.afz, m.yaw, m.yaw_rate)
        return global_target(
            int(m.coordinate_frame), int(m.type_mask), int(m.lat_int), int(m.lon_int),
            fields, ctx.origin, ctx.home_up_m, ctx.position_m,
        )  # fmt: skip
    fields = (m.x, m.y, m.z, m.vx, m.vy, m.vz, m.afx, m.afy, m.afz, m.yaw, m.yaw_rate)
    return local_target(
        int(m.coordinate_frame), int(m.type_mask), fields, ctx.position_m, ctx.heading_rad
    )
