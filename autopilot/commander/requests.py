"""What a ground station may ask of the commander, as pure functions.

Each returns the new commander state and a `Verdict`: the MAV_RESULT for COMMAND_ACK and, when
refused, why (sent as STATUSTEXT). Asking for what is already so is accepted and changes
nothing, so that a retried command (MAVSDK retries 4 times) is harmless.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from autopilot.commander.commander import AIRBORNE_PHASES, CommanderState, Phase, go_to
from autopilot.commander.commander_params import CommanderParams
from autopilot.commander.mission_items import PlanStep
from autopilot.commander.offboard import Target
from autopilot.types import FlightMode
from simbridge.frames import Vec3
from simbridge.hil import mavlink as mav

ACCEPTED = mav.MAV_RESULT_ACCEPTED
DENIED = mav.MAV_RESULT_DENIED


@dataclass(frozen=True)
class Verdict:
    result: int
    reason: str = ""

    @property
    def accepted(self) -> bool:
        return self.result == ACCEPTED


OK = Verdict(ACCEPTED)


def airborne(state: CommanderState) -> bool:
    return state.phase in AIRBORNE_PHASES


def arm(
    state: CommanderState, time_s: float, position_m: Vec3, ready: str | None, force: bool
) -> tuple[CommanderState, Verdict]:
    """Arm on the ground; `ready` is None when the pre-arm checks pass, else why not."""
    if state.phase not in (Phase.DISARMED, Phase.LANDED):
        return state, OK
    if ready is not None and not force:
        return state, Verdict(DENIED, f"arming denied: {ready}")
    armed = dataclasses.replace(
        state,
        phase=Phase.ARMED,
        since_s=time_s,
        home_m=position_m,
        target_m=None,
        carrot_m=None,
        reached_s=None,
        touchdown_s=None,
        down_since_s=None,
    )
    if state.mode in (FlightMode.LAND, FlightMode.RETURN):
        armed = dataclasses.replace(armed, mode=FlightMode.HOLD)
    return armed, OK


def disarm(state: CommanderState, time_s: float, force: bool) -> tuple[CommanderState, Verdict]:
    if state.phase in (Phase.DISARMED, Phase.LANDED):
        return state, OK
    if airborne(state) and not force:
        return state, Verdict(DENIED, "disarming denied: in the air (land first, or force)")
    return dataclasses.replace(state, phase=Phase.DISARMED, since_s=time_s, target_m=None), OK


def set_mode(
    state: CommanderState,
    mode: FlightMode,
    time_s: float,
    position_m: Vec3,
    params: CommanderParams,
) -> tuple[CommanderState, Verdict]:
    """Switch flight mode; the vehicle's targets follow from it."""
    if mode == state.mode:
        return state, OK
    if mode == FlightMode.GUIDED and state.mode in (FlightMode.TAKEOFF, FlightMode.OFFBOARD):
        return state, OK  # ArduCopter flies both in Guided: already so
    if mode == FlightMode.MISSION and not state.plan:
        return state, Verdict(DENIED, "mission mode denied: no mission uploaded")
    if mode == FlightMode.OFFBOARD and time_s - state.offboard_s > params.offboard_timeout_s:
        return state, Verdict(DENIED, "offboard denied: no recent setpoints (send them first)")
    if mode in (FlightMode.LAND, FlightMode.RETURN) and not airborne(state):
        return state, Verdict(DENIED, f"{mode} denied: not flying")
    changed = dataclasses.replace(
        state, mode=mode, target_m=None, reached_s=None, offboard_track=None
    )
    if mode == FlightMode.MISSION and state.mission_done:
        changed = dataclasses.replace(changed, mission_done=False, current=0)
    if mode == FlightMode.TAKEOFF and airborne(state):
        home = state.home_m or position_m
        target = (position_m[0], position_m[1], home[2] + params.takeoff_altitude_m)
        changed = go_to(changed, target, position_m)
    if state.phase == Phase.LANDING and mode not in (FlightMode.LAND, FlightMode.RETURN):
        changed = dataclasses.replace(changed, phase=Phase.FLYING, since_s=time_s)
    return changed, OK


def load_plan(state: CommanderState, plan: tuple[PlanStep, ...]) -> CommanderState:
    """A new mission replaces the old one; one being flown restarts at its first item."""
    changed = dataclasses.replace(state, plan=plan, current=0, mission_done=False, target_m=None)
    if state.mode == FlightMode.MISSION and not plan:
        changed = dataclasses.replace(changed, mode=FlightMode.HOLD)
    return changed


def set_current(state: CommanderState, seq: int) -> tuple[CommanderState, Verdict]:
    """Fly the mission item numbered `seq` (its number in the uploaded mission) next."""
    index = next((i for i, step in enumerate(state.plan) if step.seq == seq), None)
    if index is None:
        return state, Verdict(DENIED, f"no mission item {seq}")
    if index == state.current and not state.mission_done:
        return state, OK
    return dataclasses.replace(
        state, current=index, mission_done=False, target_m=None, reached_s=None
    ), OK


SENSORS_SETTLE_S = 0.2  # simulated time the estimator's sensors take to give a position


def position_problem(time_s: float, position_lost: str | None) -> str | None:
    """Why the estimator has no position to fly on, or None: what ground stations show as
    the position's health, and the first of the pre-arm checks."""
    if time_s < SENSORS_SETTLE_S:
        return "sensors not ready"
    if position_lost is not None:
        return f"no position: {position_lost}"
    return None


def not_ready(
    time_s: float, height_m: float, resting_height_m: float, position_lost: str | None = None
) -> str | None:
    """Why the pre-arm checks fail, or None when they pass (arming would be accepted)."""
    problem = position_problem(time_s, position_lost)
    if problem is not None:
        return problem
    if height_m > resting_height_m + 0.02:
        return "not on the ground"
    return None


def change_speed(state: CommanderState, speed_m_s: float) -> tuple[CommanderState, Verdict]:
    if speed_m_s == -1.0:
        return state, OK
    if not 0.0 < speed_m_s <= 20.0:
        return state, Verdict(DENIED, f"speed {speed_m_s:g} m/s outside (0, 20]")
    return dataclasses.replace(state, speed_m_s=speed_m_s), OK


def offboard_setpoint(state: CommanderState, target: Target, time_s: float) -> CommanderState:
    return dataclasses.replace(state, offboard=target, offboard_s=time_s)


def reposition(
    state: CommanderState,
    target_m: Vec3,
    yaw_deg: float | None,
    mode: FlightMode,
    change_mode: bool,
    time_s: float,
    position_m: Vec3,
) -> tuple[CommanderState, Verdict]:
    """Go to `target_m` and hold there, in `mode` (PX4: hold, whose AUTO.LOITER flies a
    reposition; ArduCopter: Guided). Only in the air; in another mode only if the request
    allows a change of mode (DO_REPOSITION's flag 1)."""
    if not airborne(state):
        return state, Verdict(DENIED, "go-to denied: not flying (take off first)")
    if state.mode != mode and not change_mode:
        return state, Verdict(DENIED, f"go-to denied: in {state.mode} mode (switch to {mode})")
    changed = dataclasses.replace(state, mode=mode, reached_s=None, offboard_track=None)
    if state.phase in (Phase.LANDING, Phase.TAKING_OFF):
        changed = dataclasses.replace(changed, phase=Phase.FLYING, since_s=time_s)
    return go_to(changed, target_m, position_m, yaw_deg), OK
