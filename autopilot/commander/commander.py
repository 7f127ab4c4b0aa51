"""The commander: flight modes, arming, missions, take-off, landing, as pure functions.

Two things describe the vehicle. The flight mode is what a ground station chose (hold, mission,
takeoff, land, return, offboard, guided; `autopilot.types.FlightMode`). The phase is what the
vehicle is doing: DISARMED -> ARMED (idling on the ground) -> TAKING_OFF -> FLYING / HOLDING ->
LANDING -> LANDED (touchdown held for `touchdown_s`: rotors off, disarmed). Requests from a ground
station (`requests.py`) change the state; `command` steps it once per control step, each mode by
its step in `MODE_STEPS`.

Setpoints lead the vehicle towards their target by at most what the mission speeds allow
(`limited_setpoint`), so DO_CHANGE_SPEED and MPC_XY_CRUISE mean what they say.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from typing import NamedTuple

from autopilot.commander.commander_params import CommanderParams
from autopilot.commander.landing_profile import LandingProfile
from autopilot.commander.mission_items import PlanStep
from autopilot.commander.offboard import Target, Track, follow
from autopilot.types import FlightMode, Setpoint
from simbridge.frames import Vec3


class Phase(StrEnum):
    DISARMED = "disarmed"
    ARMED = "armed"
    TAKING_OFF = "taking_off"
    FLYING = "flying"
    HOLDING = "holding"
    LANDING = "landing"
    LANDED = "landed"


AIRBORNE_PHASES = (Phase.TAKING_OFF, Phase.FLYING, Phase.HOLDING, Phase.LANDING)


@dataclass(frozen=True)
class CommanderState:
    phase: Phase = Phase.DISARMED
    since_s: float = 0.0  # when the phase began
    mode: FlightMode = FlightMode.HOLD
    plan: tuple[PlanStep, ...] = ()
    current: int = 0  # index into plan of the item being flown
    mission_done: bool = False
    home_m: Vec3 | None = None  # where the vehicle stood when it armed
    speed_m_s: float | None = None  # a DO_CHANGE_SPEED in force (None: cruise speed)
    target_m: Vec3 | None = None  # where the setpoint is going
    yaw_deg: float = 0.0  # heading setpoint, from east counter-clockwise
    carrot_m: Vec3 | None = None  # the last setpoint position, on the way to target_m
    arrived_s: float | None = None  # when the setpoint reached the target
    reached_s: float | None = None  # when the vehicle reached the target
    landing_from_m: Vec3 | None = None
    landing_height_m: float | None = None  # above resting when the landing began
    down_since_s: float | None = None
    touchdown_s: float | None = None
    takeoff_altitude_m: float | None = None  # a take-off command's own altitude
    offboard: Target | None = None
    offboard_s: float = -math.inf  # when the last offboard setpoint came
    offboard_track: Track | None = None  # where the offboard setpoint has got to
    hold_mode: FlightMode = FlightMode.HOLD  # after a take-off, or offboard setpoints stop

    def evolve(self, **changes: object) -> CommanderState:
        """`dataclasses.replace` at a sixth of its cost (it calls `__init__`, which sets each
        of the 21 fields through `object.__setattr__`): the commander replaces its state once
        or twice a control step, on the control path. No field has a check to skip."""
        unknown = changes.keys() - _STATE_FIELDS
        if unknown:
            raise TypeError(f"CommanderState has no field {sorted(unknown)[0]!r}")
        new = object.__new__(CommanderState)
        fields = new.__dict__
        fields.update(self.__dict__)
        fields.update(changes)
        return new


_STATE_FIELDS = frozenset(f.name for f in dataclasses.fields(CommanderState))
assert not hasattr(CommanderState, "__post_init__")  # evolve would skip it


@dataclass(frozen=True)
class Command:
    state: CommanderState
    setpoint: Setpoint | None  # None: rotors off (or idling on the ground)
    armed: bool
    reached: tuple[int, ...] = ()  # mission items (plan indices) reached in this step
    events: tuple[str, ...] = ()  # what changed, for the ground station and the log


def phase_to(
    state: CommanderState, phase: Phase, time_s: float, **changes: object
) -> CommanderState:
    return state.evolve(phase=phase, since_s=time_s, **changes)


def go_to(
    state: CommanderState, target: Vec3, position: Vec3, yaw_deg: float | None = None
) -> CommanderState:
    """Head for `target`, the setpoint starting from where it is (or from the vehicle)."""
    return state.evolve(
        target_m=target,
        carrot_m=state.carrot_m if state.carrot_m is not None else position,
        arrived_s=None,
        reached_s=None,
        yaw_deg=state.yaw_deg if yaw_deg is None else yaw_deg,
    )


def limited_setpoint(
    position: Vec3,
    target: Vec3,
    lead_s: float,
    horizontal_m_s: float,
    up_m_s: float,
    down_m_s: float,
    vertical_lead_s: float | None = None,
) -> Vec3:
    """The target, pulled to within `lead_s` (horizontally; `vertical_lead_s` vertically,
    by default the same) times the speed limits of the vehicle.

    The position loop's steady speed for an error e is e a0 / a1 (equation 3.7 with zero
    desired velocity), so an error clipped to speed * a1 / a0 (`lead_s`) cruises at that
    speed; moves shorter than the clip are the thesis's plain step, with no overshoot. A
    setpoint ramping at the speed instead would overshoot by about speed / a0 when it stops:
    near the ground, into the ground.
    """
    lead_z = vertical_lead_s if vertical_lead_s is not None else lead_s
    dx, dy, dz = (target[0] - position[0], target[1] - position[1], target[2] - position[2])
    horizontal = math.hypot(dx, dy)
    reach = horizontal_m_s * lead_s
    if horizontal <= reach and -down_m_s * lead_z <= dz <= up_m_s * lead_z:
        # the target itself, not position + (target - position), which rounding leaves a few
        # ulp off: the waypoint timeout starts when the setpoint equals the target
        return target
    if horizontal > reach:
        dx, dy = dx * reach / horizontal, dy * reach / horizontal
    dz = min(dz, up_m_s * lead_z) if dz > 0.0 else max(dz, -down_m_s * lead_z)
    return (position[0] + dx, position[1] + dy, position[2] + dz)


def _skip_where_it_stands(
    state: CommanderState, params: CommanderParams, position: Vec3
) -> tuple[CommanderState, tuple[int, ...]]:
    """Waypoints at the very spot the vehicle stands on when the mission starts are reached
    already: a QGC WPL file's home row, which MAVProxy uploads as item 0."""
    skipped: list[int] = []
    while not state.mission_done:
        step = state.plan[state.current]
        radius = step.acceptance_m or params.acceptance_radius_m
        if step.kind != "waypoint" or math.dist(position, step.position_m) > radius:
            break
        skipped.append(state.current)
        state = _next_item(state, 0.0, position)
    return state, tuple(skipped)


def _climb_first(state: CommanderState) -> bool:
    """A mission starting on the ground with no take-off item climbs to the take-off altitude
    first, as PX4 does."""
    return (
        state.mode == FlightMode.MISSION
        and state.phase == Phase.TAKING_OFF
        and not state.mission_done
        and state.plan[state.current].kind != "takeoff"
    )


def start_landing(
    state: CommanderState, time_s: float, position: Vec3, over_m: Vec3 | None = None
) -> CommanderState:
    """Descend from here; horizontally towards `over_m` (a landing item's or home's position,
    once within the acceptance radius of it), else straight down."""
    xy = over_m[:2] if over_m is not None else position[:2]
    return phase_to(
        state,
        Phase.LANDING,
        time_s,
        landing_from_m=(xy[0], xy[1], position[2]),
        landing_height_m=None,  # the first landing step measures it
        down_since_s=None,
        target_m=None,
    )


def _next_item(state: CommanderState, time_s: float, position: Vec3) -> CommanderState:
    """Move on to the next mission item; past the last one the mission is done: hold."""
    if state.current + 1 >= len(state.plan):
        return state.evolve(
            mission_done=True, mode=FlightMode.HOLD, target_m=state.target_m or position
        )
    return state.evolve(current=state.current + 1, target_m=None, reached_s=None)


def _return_target(state: CommanderState, params: CommanderParams, position: Vec3) -> Vec3:
    """Over home, at the higher of here and the return altitude above home."""
    home = state.home_m or position
    return (home[0], home[1], max(position[2], home[2] + params.return_altitude_m))


def _mission_target(
    state: CommanderState, params: CommanderParams, step: PlanStep, position: Vec3
) -> CommanderState:
    """Aim the setpoint at the mission item `step` (once, when it becomes current)."""
    if step.kind == "takeoff":
        home = state.home_m or position
        xy = step.position_m[:2] if step.position_m is not None else position[:2]
        altitude = step.altitude_m if step.altitude_m > 0.0 else params.takeoff_altitude_m
        return go_to(state, (xy[0], xy[1], home[2] + altitude), position, step.yaw_deg)
    if step.kind == "waypoint":
        return go_to(state, step.position_m, position, step.yaw_deg)
    if step.kind == "land":
        xy = step.position_m[:2] if step.position_m is not None else position[:2]
        return go_to(state, (xy[0], xy[1], position[2]), position, step.yaw_deg)
    return go_to(state, _return_target(state, params, position), position)


def _fly_mission(
    state: CommanderState, params: CommanderParams, time_s: float, position: Vec3
) -> tuple[CommanderState, tuple[int, ...]]:
    """Advance the mission; returns the state and the items reached in this step."""
    reached: list[int] = []
    for _ in range(len(state.plan) + 1):  # at most every item once per step
        if state.mission_done:
            break
        step = state.plan[state.current]
        if step.kind == "speed":
            reached.append(state.current)
            state = _next_item(state.evolve(speed_m_s=step.speed_m_s), time_s, position)
            continue
        if state.target_m is None:
            state = _mission_target(state, params, step, position)
        if state.reached_s is None:
            break
        if step.kind in ("land", "return"):
            state = start_landing(state, time_s, position, state.target_m)  # reached at touchdown
            break
        if time_s - state.reached_s < step.hold_s:
            break
        reached.append(state.current)
        state = _next_item(state, time_s, position)
    return state, tuple(reached)


def _reached(
    state: CommanderState, params: CommanderParams, time_s: float, position: Vec3
) -> CommanderState:
    """Mark the target reached when the vehicle is within the acceptance radius of it (or the
    setpoint has been there longer than the waypoint timeout)."""
    if state.target_m is None or state.reached_s is not None:
        return state
    if state.arrived_s is None and state.carrot_m == state.target_m:
        state = state.evolve(arrived_s=time_s)
    radius = params.acceptance_radius_m
    step = state.plan[state.current] if state.mode == FlightMode.MISSION and state.plan else None
    if step is not None and step.acceptance_m > 0.0:
        radius = step.acceptance_m
    if (step is not None and step.kind == "takeoff") or state.phase == Phase.TAKING_OFF:
        close = abs(position[2] - state.target_m[2]) <= params.takeoff_acceptance_m
    else:
        close = math.dist(position, state.target_m) <= radius
    late = (
        params.waypoint_timeout_s > 0.0
        and state.arrived_s is not None
        and time_s - state.arrived_s >= params.waypoint_timeout_s
    )
    if close or late:
        return state.evolve(reached_s=time_s)
    return state


class Now(NamedTuple):
    """What one commander step knows of the vehicle."""

    time_s: float
    position_m: Vec3
    height_m: float  # above the surface under the vehicle
    resting_height_m: float  # the height the vehicle rests at on the ground
    ground_contact: bool  # the land detector's verdict (autopilot/control/land_detector.py)


def command(
    state: CommanderState,
    params: CommanderParams,
    time_s: float,
    position_m: Vec3,
    height_m: float,
    resting_height_m: float,
    lead_s: float = 2.0,
    ground_contact: bool = False,
    vertical_lead_s: float | None = None,
) -> Command:
    """One commander step at `time_s` from the vehicle's position and height above the surface;
    `ground_contact`: the land detector's verdict (autopilot/control/land_detector.py)."""
    if state.phase in (Phase.DISARMED, Phase.LANDED):
        return Command(state, None, False)
    now = Now(time_s, position_m, height_m, resting_height_m, ground_contact)
    events: list[str] = []
    reached: tuple[int, ...] = ()
    if state.phase == Phase.ARMED:
        state, on_ground, reached = _leave_ground(state, params, now, events)
        if on_ground is not None:
            return on_ground
    if state.phase == Phase.LANDING:
        return _land(state, params, now, events)
    if state.mode == FlightMode.OFFBOARD:
        state, following = _offboard(state, params, now, events)
        if following is not None:
            return following
    state, flown, texts = MODE_STEPS[state.mode](state, params, now)
    if state.phase == Phase.LANDING:
        return _land(state, params, now, events)
    events += texts
    horizontal, up, down = (
        state.speed_m_s or params.cruise_speed_m_s,
        params.climb_speed_m_s,
        params.descent_speed_m_s,
    )
    carrot = limited_setpoint(
        position_m, state.target_m, lead_s, horizontal, up, down, vertical_lead_s
    )
    state = _progress(_reached(state.evolve(carrot_m=carrot), params, time_s, position_m), now)
    if state.mode == FlightMode.TAKEOFF and state.reached_s is not None:
        # also a take-off mode chosen in the air: it climbs to the altitude, then holds
        state = state.evolve(mode=state.hold_mode)
        events.append(f"take-off complete: holding in {state.hold_mode}")
    setpoint = Setpoint(carrot, yaw_rad=math.radians(state.yaw_deg))
    return Command(state, setpoint, True, reached + flown, tuple(events))


def _leave_ground(
    state: CommanderState, params: CommanderParams, now: Now, events: list[str]
) -> tuple[CommanderState, Command | None, tuple[int, ...]]:
    """ARMED: stay on the ground (a Command) until a mode that flies has spun the rotors up
    for `spin_up_s`, then take off; also returns the mission items reached on the ground."""
    wants_air = state.mode in (FlightMode.TAKEOFF, FlightMode.MISSION, FlightMode.OFFBOARD)
    if state.mode == FlightMode.MISSION and state.mission_done:
        wants_air = False
    if not wants_air or now.time_s - state.since_s < params.spin_up_s:
        return state, Command(state, None, True), ()
    skipped: tuple[int, ...] = ()
    if state.mode == FlightMode.MISSION:
        state, skipped = _skip_where_it_stands(state, params, now.position_m)
        if state.mission_done:
            return state, Command(state, None, True, skipped, ("mission complete",)), skipped
    position = now.position_m
    state = phase_to(state, Phase.TAKING_OFF, now.time_s, carrot_m=position, target_m=None)
    if state.mode == FlightMode.TAKEOFF or _climb_first(state):
        home = state.home_m or position
        altitude = state.takeoff_altitude_m or params.takeoff_altitude_m
        state = go_to(state, (position[0], position[1], home[2] + altitude), position)
    events.append("taking off")
    return state, None, skipped


def _offboard(
    state: CommanderState, params: CommanderParams, now: Now, events: list[str]
) -> tuple[CommanderState, Command | None]:
    """OFFBOARD: follow the setpoints while they keep coming (a Command); once they stop,
    hold where the vehicle is, in the identity's hold mode."""
    position = now.position_m
    if now.time_s - state.offboard_s <= params.offboard_timeout_s and state.offboard is not None:
        phase = Phase.FLYING if state.phase != Phase.TAKING_OFF or position[2] > (
            (state.home_m or position)[2] + params.takeoff_acceptance_m
        ) else Phase.TAKING_OFF  # fmt: skip
        if phase != state.phase:
            state = phase_to(state, phase, now.time_s)
        setpoint, track = follow(
            state.offboard, state.offboard_track, position, math.radians(state.yaw_deg), now.time_s
        )
        state = state.evolve(
            carrot_m=setpoint.position_m,
            offboard_track=track,
            yaw_deg=math.degrees(setpoint.yaw_rad),
        )
        return state, Command(state, setpoint, True, events=tuple(events))
    state = go_to(
        state.evolve(mode=state.hold_mode, target_m=position, carrot_m=None, offboard_track=None),
        position,
        position,
    )
    events.append(f"offboard setpoints stopped: holding in {state.hold_mode}")
    return state, None


# A mode's step: the new state (LANDING: the landing takes over), the mission items it
# reached and what it has to say.
ModeStep = tuple[CommanderState, tuple[int, ...], tuple[str, ...]]


def _hold_step(state: CommanderState, params: CommanderParams, now: Now) -> ModeStep:
    """Go to the target; without one, hold where the vehicle is."""
    if state.target_m is None:
        state = go_to(state, now.position_m, now.position_m)
    return state, (), ()


def _mission_step(state: CommanderState, params: CommanderParams, now: Now) -> ModeStep:
    if _climb_first(state):
        return _hold_step(state, params, now)  # to the take-off altitude first
    state, flown = _fly_mission(state, params, now.time_s, now.position_m)
    return state, flown, ("mission complete",) if state.mission_done else ()


def _land_step(state: CommanderState, params: CommanderParams, now: Now) -> ModeStep:
    return start_landing(state, now.time_s, now.position_m), (), ()


def _return_step(state: CommanderState, params: CommanderParams, now: Now) -> ModeStep:
    """Fly home at the return altitude, then land there."""
    if state.target_m is None:
        state = go_to(state, _return_target(state, params, now.position_m), now.position_m)
    if state.reached_s is not None:
        state = start_landing(state, now.time_s, now.position_m, state.target_m)
    return state, (), ()


MODE_STEPS: dict[FlightMode, Callable[[CommanderState, CommanderParams, Now], ModeStep]] = {
    FlightMode.MISSION: _mission_step,
    FlightMode.LAND: _land_step,
    FlightMode.RETURN: _return_step,
    FlightMode.HOLD: _hold_step,
    FlightMode.GUIDED: _hold_step,
    FlightMode.TAKEOFF: _hold_step,
    FlightMode.OFFBOARD: _hold_step,  # setpoints stopped: held, in the hold mode, by then
}


def _progress(state: CommanderState, now: Now) -> CommanderState:
    """The phase that follows from the target being reached: a take-off ends (a mission on
    to its item 1), flying turns to holding and back."""
    if state.phase == Phase.TAKING_OFF and state.reached_s is not None:
        state = phase_to(state, Phase.FLYING, now.time_s)
        if state.mode == FlightMode.MISSION and state.plan[state.current].kind != "takeoff":
            state = state.evolve(target_m=None, reached_s=None)  # on to item 1
    if state.phase in (Phase.FLYING, Phase.HOLDING):
        phase = Phase.HOLDING if state.reached_s is not None else Phase.FLYING
        if phase != state.phase:
            state = phase_to(state, phase, now.time_s)
    return state


def landing_profile(params: CommanderParams) -> LandingProfile:
    return LandingProfile(
        params.descent_speed_m_s,
        params.land_speed_m_s,
        params.land_blend_from_m,
        params.land_slow_below_m,
    )


def _land(state: CommanderState, params: CommanderParams, now: Now, events: list[str]) -> Command:
    """LANDING: a setpoint sinking (at the descent speed high up, the landing speed near the
    ground: `landing_profile`) until the vehicle is down, never further than
    `landing_floor_m` below where the vehicle would rest."""
    time_s, height_m, resting_height_m = now.time_s, now.height_m, now.resting_height_m
    start = state.landing_from_m or now.position_m
    if state.landing_height_m is None:
        state = state.evolve(landing_height_m=max(height_m - resting_height_m, 0.0))
    profile = landing_profile(params)
    h0 = state.landing_height_m or 0.0
    h = profile.height_m(h0, time_s - state.since_s)
    floor = now.position_m[2] - (height_m - resting_height_m) - params.landing_floor_m
    z = start[2] - (h0 - h)
    sinking = z > floor
    target = (start[0], start[1], max(z, floor))
    setpoint = Setpoint(
        target,
        velocity_m_s=(0.0, 0.0, -profile.speed_m_s(h) if sinking else 0.0),
        yaw_rad=math.radians(state.yaw_deg),
    )
    if height_m <= resting_height_m + params.touchdown_margin_m or now.ground_contact:
        down_since = state.down_since_s if state.down_since_s is not None else time_s
        if time_s - down_since >= params.touchdown_s or now.ground_contact:
            reached: tuple[int, ...] = ()
            if state.mode == FlightMode.MISSION and state.plan and not state.mission_done:
                reached = (state.current,)
                state = state.evolve(mission_done=True)
            landed = phase_to(
                state, Phase.LANDED, time_s, touchdown_s=time_s, target_m=None, carrot_m=None
            )
            return Command(landed, None, False, reached, (*events, "landed: disarmed"))
        state = state.evolve(down_since_s=down_since, carrot_m=target)
        return Command(state, setpoint, True, events=tuple(events))
    state = state.evolve(down_since_s=None, carrot_m=target)
    return Command(state, setpoint, True, events=tuple(events))
