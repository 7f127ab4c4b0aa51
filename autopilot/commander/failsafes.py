"""Failsafes: the ground station lost, the position source lost, the geofence breached.

`check` runs once per control step; each failsafe acts once when its condition begins (the
flag in `Failsafes` remembers it) and only in the air, with the action its parameter names.
"""

from __future__ import annotations

from dataclasses import dataclass

from autopilot.commander import requests
from autopilot.commander.commander import AIRBORNE_PHASES, CommanderState
from autopilot.commander.commander_params import CommanderParams
from autopilot.commander.mission_items import Geofence
from autopilot.types import FlightMode
from simbridge.config import param
from simbridge.frames import Vec3

# failsafe actions, PX4's numbering for NAV_DLL_ACT and GF_ACTION
ACTION_NONE, ACTION_WARN, ACTION_HOLD, ACTION_RETURN, ACTION_LAND = 0, 1, 2, 3, 5
ACTION_NAMES = {0: "none", 1: "warn", 2: "hold", 3: "return", 5: "land"}


@dataclass(frozen=True)
class FailsafeParams:
    gcs_loss_action: int = param(
        ACTION_NONE,
        lo=0,
        hi=5,
        doc="ground station lost in flight: 0 none, 2 hold, 3 return, 5 land",
    )
    gcs_loss_timeout_s: float = param(
        5.0, unit="s", lo=0.5, hi=300.0, doc="no ground-station heartbeat this long (wall clock)"
    )
    fence_action: int = param(
        ACTION_RETURN, lo=0, hi=5, doc="geofence breached: 0 none, 1 warn, 2 hold, 3 return, 5 land"
    )


@dataclass
class Failsafes:
    gcs_seen: bool = False  # a ground station has sent a heartbeat
    gcs_heard_wall_s: float = 0.0
    gcs_lost: bool = False
    fence_breached: bool = False
    position_lost: bool = False


ACTION_MODES = {
    ACTION_HOLD: FlightMode.HOLD,
    ACTION_RETURN: FlightMode.RETURN,
    ACTION_LAND: FlightMode.LAND,
}


def act(
    cmd: CommanderState,
    action: int,
    why: str,
    time_s: float,
    position_m: Vec3,
    params: CommanderParams,
) -> tuple[CommanderState, str]:
    """Take the failsafe `action`; returns the state and the text that says so."""
    text = f"failsafe: {why}: {ACTION_NAMES.get(action, action)}"
    mode = ACTION_MODES.get(action)
    if mode is None or cmd.mode == mode:
        return cmd, text
    cmd, _ = requests.set_mode(cmd, mode, time_s, position_m, params)
    return cmd, text


def check_failsafes(
    fs: Failsafes,
    cmd: CommanderState,
    settings: FailsafeParams,
    fence: Geofence,
    params: CommanderParams,
    time_s: float,
    wall_s: float,
    position_m: Vec3,
    home_m: Vec3,
    position_lost: str | None,
) -> tuple[CommanderState, list[str]]:
    """Check the failsafes once; returns the state and the texts to send (critical)."""
    texts: list[str] = []
    flying = cmd.phase in AIRBORNE_PHASES

    def take(action: int, why: str) -> None:
        nonlocal cmd
        cmd, text = act(cmd, action, why, time_s, position_m, params)
        texts.append(text)

    lost = fs.gcs_seen and wall_s - fs.gcs_heard_wall_s > settings.gcs_loss_timeout_s
    if lost and not fs.gcs_lost:
        fs.gcs_lost = True
        if flying and settings.gcs_loss_action != ACTION_NONE:
            take(settings.gcs_loss_action, "ground station lost")
        else:  # said all the same, as PX4 does with NAV_DLL_ACT 0
            texts.append("ground station lost (no failsafe action: NAV_DLL_ACT 0 or on the ground)")
    if position_lost is not None and not fs.position_lost:
        fs.position_lost = True  # PX4: position loss in flight lands (COM_POSCTL_NAVL)
        if flying:
            take(ACTION_LAND, f"{position_lost} in flight")
    elif position_lost is None:
        fs.position_lost = False
    p, home = position_m, home_m
    breach = fence.breach(p[0] - home[0], p[1] - home[1], p[2] - home[2]) if flying else None
    if breach is not None and not fs.fence_breached:
        fs.fence_breached = True
        take(settings.fence_action, f"geofence: {breach}")
    elif breach is None:
        fs.fence_breached = False
    return cmd, texts
