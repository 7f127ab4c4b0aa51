"""The commander: arming, take-off, waypoints, landing, touchdown and disarm, as a pure function.

DISARMED -> ARMED (sensors healthy for `arm_delay_s`) -> TAKING_OFF (to the take-off altitude
above the start) -> FLYING / HOLDING (the navigator's waypoints) -> LANDING (a setpoint
descending at `land_speed_m_s`) -> LANDED (touchdown held for `touchdown_s`: rotors off).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from enum import StrEnum

from autopilot.controller import Setpoint
from autopilot.navigator import NavigatorState, Waypoint, navigate
from simbridge.config import param
from simbridge.frames import Vec3


class Mode(StrEnum):
    DISARMED = "disarmed"
    ARMED = "armed"
    TAKING_OFF = "taking_off"
    FLYING = "flying"
    HOLDING = "holding"
    LANDING = "landing"
    LANDED = "landed"


@dataclass(frozen=True)
class CommanderParams:
    arm_delay_s: float = param(0.1, unit="s", lo=0.0, hi=60.0, doc="healthy sensors before arming")
    spin_up_s: float = param(
        0.2, unit="s", lo=0.0, hi=10.0, doc="armed on the ground before take-off"
    )
    takeoff_altitude_m: float = param(1.0, unit="m", lo=0.05, hi=100.0, doc="above the start")
    takeoff_acceptance_m: float = param(
        0.05, unit="m", lo=0.001, hi=10.0, doc="take-off reached within"
    )
    land_speed_m_s: float = param(
        0.1, unit="m/s", lo=0.01, hi=3.0, doc="descent rate of the landing setpoint"
    )
    touchdown_margin_m: float = param(
        0.004, unit="m", lo=0.0, hi=0.1, doc="height above resting that counts as down"
    )
    touchdown_s: float = param(
        0.1, unit="s", lo=0.0, hi=5.0, doc="down this long: touchdown, disarm"
    )


@dataclass(frozen=True)
class Mission:
    waypoints: tuple[Waypoint, ...]
    land: bool = True


@dataclass(frozen=True)
class CommanderState:
    mode: Mode = Mode.DISARMED
    since_s: float = 0.0  # when the mode began
    nav: NavigatorState = NavigatorState()
    origin_m: Vec3 | None = None  # where the vehicle stood when it armed
    landing_from_m: Vec3 | None = None  # where the landing began
    down_since_s: float | None = None  # touchdown condition first met
    touchdown_s: float | None = None  # when it disarmed


@dataclass(frozen=True)
class Command:
    state: CommanderState
    setpoint: Setpoint | None  # None: rotors off
    armed: bool


def _to(state: CommanderState, mode: Mode, time_s: float, **changes: object) -> CommanderState:
    return dataclasses.replace(state, mode=mode, since_s=time_s, **changes)


def command(
    state: CommanderState,
    mission: Mission,
    params: CommanderParams,
    time_s: float,
    position_m: Vec3,
    height_m: float,
    resting_height_m: float,
) -> Command:
    """One commander step at `time_s` from the vehicle's position and height above the surface."""
    mode = state.mode
    if mode == Mode.DISARMED:
        if time_s - state.since_s >= params.arm_delay_s:
            return Command(_to(state, Mode.ARMED, time_s, origin_m=position_m), None, True)
        return Command(state, None, False)
    if mode == Mode.LANDED:
        return Command(state, None, False)
    origin = state.origin_m or position_m
    if mode == Mode.ARMED:
        if time_s - state.since_s >= params.spin_up_s:
            state = _to(state, Mode.TAKING_OFF, time_s)
        else:
            return Command(state, None, True)
    if state.mode == Mode.TAKING_OFF:
        target = (origin[0], origin[1], origin[2] + params.takeoff_altitude_m)
        if abs(position_m[2] - target[2]) > params.takeoff_acceptance_m:
            return Command(state, Setpoint(target), True)
        state = _to(state, Mode.FLYING, time_s)
    if state.mode in (Mode.FLYING, Mode.HOLDING):
        nav = navigate(state.nav, mission.waypoints, position_m, time_s)
        if not nav.done or not mission.land:
            mode = Mode.HOLDING if nav.holding else Mode.FLYING
            if mode != state.mode:
                state = _to(state, mode, time_s)
            return Command(dataclasses.replace(state, nav=nav.state), nav.setpoint, True)
        state = _to(state, Mode.LANDING, time_s, nav=nav.state, landing_from_m=position_m)
    # LANDING: a setpoint sinking at the landing speed until the vehicle is down.
    start = state.landing_from_m or position_m
    sink = params.land_speed_m_s
    target = (start[0], start[1], start[2] - sink * (time_s - state.since_s))
    setpoint = Setpoint(target, velocity_m_s=(0.0, 0.0, -sink))
    if height_m <= resting_height_m + params.touchdown_margin_m:
        down_since = state.down_since_s if state.down_since_s is not None else time_s
        if time_s - down_since >= params.touchdown_s:
            return Command(_to(state, Mode.LANDED, time_s, touchdown_s=time_s), None, False)
        return Command(dataclasses.replace(state, down_since_s=down_since), setpoint, True)
    return Command(dataclasses.replace(state, down_since_s=None), setpoint, True)
