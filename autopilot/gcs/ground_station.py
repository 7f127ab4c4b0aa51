"""The vehicle's side of the ground-station link: commands, parameters, missions, telemetry,
failsafes. Called by the flight loop once per control step; never blocks.

Simulated time paces telemetry (as in PX4's lockstep SITL); the wall clock paces what lives
in the ground station's world: mission-transfer retries and the heartbeat-loss failsafe.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from autopilot.commander import guided, requests
from autopilot.commander.commander import AIRBORNE_PHASES, CommanderState, Phase
from autopilot.commander.failsafes import Failsafes, check_failsafes
from autopilot.commander.mission_items import Geofence, Home, MissionItem, is_home_row, plan_steps
from autopilot.gcs import telemetry
from autopilot.gcs.link import GcsLink
from autopilot.gcs.mission_protocol import MissionProtocol, Outcome
from autopilot.gcs.param_protocol import ftp_nak, handle_param
from autopilot.gcs.refusals import RefusalLimiter
from autopilot.identity import Identity
from autopilot.params import ParamStore
from autopilot.types import FlightMode, FlightState
from simbridge.frames import Vec3, euler_from_quat, local_to_geodetic
from simbridge.hil import mavlink as mav

DENIED, UNSUPPORTED = mav.MAV_RESULT_DENIED, mav.MAV_RESULT_UNSUPPORTED
FORCE_MAGIC = 21196  # ARM_DISARM param2: arm or disarm whatever the checks say
GUIDED_ITEM = 2  # MISSION_ITEM.current 2: ArduPilot's guided target, not a mission item


@dataclass
class StepInput:
    time_s: float
    wall_s: float
    state: FlightState
    height_m: float
    resting_height_m: float
    position_lost: str | None = None  # the estimator's word: which position source went quiet

    def not_ready(self) -> str | None:
        """Why arming would be refused; also what SYS_STATUS's pre-arm health says."""
        s = self
        return requests.not_ready(s.time_s, s.height_m, s.resting_height_m, s.position_lost)


# a command's handler: the new state and the verdict to ack with (None: it answered itself)
Handled = tuple[CommanderState, "requests.Verdict | None"]
CommandHandler = Callable[["GroundStation", Any, CommanderState, StepInput], Handled]


@dataclass
class GroundStation:
    link: GcsLink
    params: ParamStore
    identity: Identity
    origin: tuple[float, float, float]
    on_event: Callable[[float, str], None] = lambda t, text: None
    # told once, the first time arming would be accepted: where ground stations connect
    on_ready: Callable[[str], None] = lambda text: None
    ready_told: bool = False
    items: tuple[MissionItem, ...] = ()
    streams: telemetry.Streams = field(default_factory=telemetry.Streams)
    failsafes: Failsafes = field(default_factory=Failsafes)
    initial_home_m: tuple[float, float, float] | None = None
    last_mission_current: tuple[int, int, int] | None = None
    surface_z: float | None = None  # local z of the surface under the vehicle on the ground
    last_status: tuple[Any, ...] | None = None
    text_id: int = 0
    refusals: RefusalLimiter = field(default_factory=RefusalLimiter)
    # MAV_CMD -> its handler: `COMMANDS`, which one station's table may add to
    commands: dict[int, CommandHandler] = field(default_factory=lambda: dict(COMMANDS))

    def __post_init__(self) -> None:
        self.protocol = MissionProtocol(self.identity)

    # --- the per-step entry points ---------------------------------------------------------

    def before_step(self, cmd: CommanderState, inp: StepInput) -> CommanderState:
        """Apply what the ground stations asked since the last step; check the failsafes."""
        self._first_position(inp)
        if cmd.hold_mode != self.identity.hold_mode:
            cmd = requests.dataclasses.replace(cmd, hold_mode=self.identity.hold_mode)
        if cmd.phase not in AIRBORNE_PHASES:
            self.surface_z = inp.state.position_m[2] - inp.height_m
        for m in self.link.poll(inp.wall_s):
            try:
                cmd = self._handle(m, cmd, inp)
            except (ValueError, TypeError, OverflowError) as e:  # well-formed, nonsensical
                self.link.counters.invalid += 1
                self._text(inp, f"ignored {m.get_type()}: {e}", mav.MAV_SEVERITY_WARNING)
        self._send_outcome(self.protocol.tick(inp.wall_s), inp)
        return self._failsafes(cmd, inp)

    def after_step(
        self, cmd: CommanderState, inp: StepInput, reached: tuple[int, ...], events: tuple[str, ...]
    ) -> None:
        """Report what the step did, and the telemetry that is due."""
        self._first_position(inp)
        for index in reached:
            self.on_event(inp.time_s, f"mission item {cmd.plan[index].seq} reached")
            self.send(mav.MAVLink_mission_item_reached_message(cmd.plan[index].seq), inp)
        for text in events:
            self._text(inp, text)
        if not self.link.endpoints:
            return
        snap = self._snapshot(cmd, inp)
        if snap.ready and not self.ready_told:
            self.ready_told = True
            self.on_event(inp.time_s, "ready to arm")
            self.on_ready(self.link.describe(f"{self.identity.name} identity"))
        due = self.streams.due(inp.time_s)
        status = (snap.phase, snap.mode, snap.armed, snap.ready, snap.position_ok)
        if status != self.last_status:  # tell at once, not at the next 1 Hz heartbeat
            self.last_status = status
            due = [*due, "HEARTBEAT", "EXTENDED_SYS_STATE", "SYS_STATUS"]
        for name in dict.fromkeys(due):
            self._send_named(name, snap, cmd, inp)
        current = telemetry.mission_current(cmd, len(self.items))
        if current != self.last_mission_current:
            self._send_named("MISSION_CURRENT", snap, cmd, inp)
        self.link.keep_signing(inp.wall_s)

    def _first_position(self, inp: StepInput) -> None:
        """Home until one is set: where the vehicle was at the first step."""
        if self.initial_home_m is None:
            self.initial_home_m = inp.state.position_m

    def _home_m(self, cmd: CommanderState) -> Vec3:
        """Where it armed, else where it was at the first step, else the home given (origin)."""
        return cmd.home_m or self.initial_home_m or (0.0, 0.0, 0.0)

    # --- sending ---------------------------------------------------------------------------

    def send(self, message: Any, inp: StepInput) -> None:
        self.link.send(message, inp.wall_s)

    def _text(self, inp: StepInput, text: str, severity: int = mav.MAV_SEVERITY_INFO) -> None:
        self.say(text, inp.time_s, inp.wall_s, severity)

    def say(self, text: str, time_s: float, wall_s: float, severity: int) -> None:
        """STATUSTEXT; a text over 50 bytes goes in chunks sharing an id (MAVLink 2)."""
        self.on_event(time_s, text)
        messages = telemetry.statustext(text, severity, self.text_id % 65535 + 1)
        if len(messages) > 1:
            self.text_id = self.text_id % 65535 + 1
        for message in messages:
            self.link.send(message, wall_s)

    def _snapshot(self, cmd: CommanderState, inp: StepInput) -> telemetry.Snapshot:
        return telemetry.Snapshot(
            time_s=inp.time_s,
            state=inp.state,
            origin=self.origin,
            home_m=self._home_m(cmd),
            phase=cmd.phase,
            mode=cmd.mode,
            armed=cmd.phase not in (Phase.DISARMED, Phase.LANDED),
            ready=inp.not_ready() is None,
            position_ok=requests.position_problem(inp.time_s, inp.position_lost) is None,
            identity=self.identity,
            fence_on=self.params.geofence() != Geofence(),
            fence_breached=self.failsafes.fence_breached,
        )

    def _send_named(
        self, name: str, snap: telemetry.Snapshot, cmd: CommanderState, inp: StepInput
    ) -> None:
        if name == "MISSION_CURRENT":
            seq, total, state = telemetry.mission_current(cmd, len(self.items))
            self.last_mission_current = (seq, total, state)
            mode = int(cmd.mode == FlightMode.MISSION)
            self.send(mav.MAVLink_mission_current_message(seq, total, state, mode), inp)
            return
        if name == "SYS_STATUS":
            c = self.link.counters
            total = c.received + c.dropped
            message = telemetry.sys_status(
                snap, 100.0 * c.dropped / total if total else 0.0, c.dropped
            )
        elif name == "AUTOPILOT_VERSION":
            message = telemetry.autopilot_version()
        else:
            builder = {
                "HEARTBEAT": telemetry.heartbeat,
                "EXTENDED_SYS_STATE": telemetry.extended_sys_state,
                "GLOBAL_POSITION_INT": telemetry.global_position_int,
                "LOCAL_POSITION_NED": telemetry.local_position_ned,
                "ATTITUDE": telemetry.attitude,
                "HOME_POSITION": telemetry.home_position,
            }[name]
            message = builder(snap)
        if message is not None:
            self.send(message, inp)

    def _send_outcome(self, outcome: Outcome, inp: StepInput) -> None:
        if outcome.text:  # the reason first, so that it is there when the ack arrives
            self._text(inp, outcome.text, mav.MAV_SEVERITY_WARNING)
        for reply in outcome.replies:
            self.send(reply, inp)

    # --- receiving -------------------------------------------------------------------------

    def _handle(self, m: Any, cmd: CommanderState, inp: StepInput) -> CommanderState:
        kind = m.get_type()
        if kind in ("MISSION_ITEM", "MISSION_ITEM_INT") and m.current == GUIDED_ITEM:
            return self._guided_item(m, cmd, inp)
        handler = MESSAGES.get(kind)
        if handler is None and kind.startswith("PARAM_"):
            handler = GroundStation._param
        elif handler is None and kind.startswith("MISSION_"):
            handler = GroundStation._mission
        return cmd if handler is None else handler(self, m, cmd, inp)

    def _heartbeat(self, m: Any, cmd: CommanderState, inp: StepInput) -> CommanderState:
        if m.type == mav.MAV_TYPE_GCS or m.get_srcComponent() != self.link.compid:
            self.failsafes.gcs_seen = True
            self.failsafes.gcs_heard_wall_s = inp.wall_s
            if self.failsafes.gcs_lost:
                self.failsafes.gcs_lost = False
                self._text(inp, "ground station link regained")
        return cmd

    def _set_mode_message(self, m: Any, cmd: CommanderState, inp: StepInput) -> CommanderState:
        mode = self.identity.decode_mode(int(m.custom_mode), None)
        cmd, verdict = self._mode(cmd, mode, inp, f"custom mode {int(m.custom_mode)}")
        self._ack(m, mav.MAVLINK_MSG_ID_SET_MODE, verdict, inp)
        return cmd

    def _mission_set_current(self, m: Any, cmd: CommanderState, inp: StepInput) -> CommanderState:
        cmd, verdict = requests.set_current(cmd, int(m.seq))
        if not verdict.accepted:
            self._text(inp, verdict.reason, mav.MAV_SEVERITY_WARNING)
        return cmd

    def _setpoint(self, m: Any, cmd: CommanderState, inp: StepInput) -> CommanderState:
        cmd, refused = guided.setpoint(m, cmd, self._context(cmd, inp))
        if refused is not None:
            self.link.counters.invalid += 1
            if self.refusals.due(refused, inp.wall_s):
                self._text(inp, refused, mav.MAV_SEVERITY_WARNING)
        return cmd

    def _request_data_stream(self, m: Any, cmd: CommanderState, inp: StepInput) -> CommanderState:
        ids = telemetry.DATA_STREAMS.keys() if m.req_stream_id == 0 else [m.req_stream_id]
        for stream_id in ids:
            for name in telemetry.DATA_STREAMS.get(stream_id, ()):
                self.streams.set_rate(name, float(m.req_message_rate) if m.start_stop else 0.0)
        return cmd

    def _ftp(self, m: Any, cmd: CommanderState, inp: StepInput) -> CommanderState:
        self.send(ftp_nak(m), inp)
        return cmd

    def _ack(self, m: Any, command: int, verdict: requests.Verdict, inp: StepInput) -> None:
        """COMMAND_ACK to the sender; the reason of a refusal first, as STATUSTEXT."""
        if verdict.reason:
            self._text(inp, verdict.reason, mav.MAV_SEVERITY_WARNING)
        self.send(
            mav.MAVLink_command_ack_message(
                command, verdict.result, 0, 0, m.get_srcSystem(), m.get_srcComponent()
            ),
            inp,
        )

    # --- commands: one handler per MAV_CMD, in `COMMANDS` ----------------------------------

    def _command(self, m: Any, cmd: CommanderState, inp: StepInput) -> CommanderState:
        """COMMAND_LONG / COMMAND_INT: the handler `commands` has for it, acked with its verdict
        (a handler that answers itself returns None); a command without one is unsupported."""
        command = int(m.command)
        handler = self.commands.get(command)
        if handler is None:
            verdict: requests.Verdict | None = requests.Verdict(UNSUPPORTED)
        else:
            cmd, verdict = handler(self, m, cmd, inp)
        if verdict is not None:
            self._ack(m, command, verdict, inp)
        return cmd

    def _set_mode(
        self, cmd: CommanderState, mode: FlightMode, inp: StepInput
    ) -> tuple[CommanderState, requests.Verdict]:
        params = self.params.commander()
        return requests.set_mode(cmd, mode, inp.time_s, inp.state.position_m, params)

    def _arm_disarm(self, m: Any, cmd: CommanderState, inp: StepInput) -> Handled:
        force = round(m.param2) == FORCE_MAGIC if math.isfinite(m.param2) else False
        t = inp.time_s
        if m.param1 == 1.0:
            ready = inp.not_ready()
            cmd, verdict = requests.arm(cmd, t, inp.state.position_m, ready, force)
            if verdict.accepted:
                self.on_event(t, "armed by the ground station")
        elif m.param1 == 0.0:
            cmd, verdict = requests.disarm(cmd, t, force)
            if verdict.accepted:
                self.on_event(t, "disarmed by the ground station")
        else:
            verdict = requests.Verdict(DENIED, f"ARM_DISARM param1 {m.param1:g}: expected 0 or 1")
        return cmd, verdict

    def _takeoff(self, m: Any, cmd: CommanderState, inp: StepInput) -> Handled:
        if requests.airborne(cmd):  # as ArduCopter: never left climbing in a take-off mode
            return cmd, requests.Verdict(DENIED, "take-off denied: already flying")
        if cmd.phase != Phase.ARMED:
            return cmd, requests.Verdict(DENIED, "take-off denied: arm first")
        altitude = None
        if self.identity.takeoff_to_command_altitude:
            # ArduCopter takes off to the command's altitude, above where it stands
            z = m.param7 if m.get_type() == "COMMAND_LONG" else m.z
            if not (math.isfinite(z) and z > 0.0):
                return cmd, requests.Verdict(DENIED, "take-off denied: param 7 altitude <= 0")
            altitude = float(z)
        cmd = requests.dataclasses.replace(cmd, takeoff_altitude_m=altitude)
        return self._set_mode(cmd, FlightMode.TAKEOFF, inp)

    def _do_set_mode(self, m: Any, cmd: CommanderState, inp: StepInput) -> Handled:
        if not int(m.param1) & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return cmd, requests.Verdict(DENIED, "set mode: only custom modes (param1 bit 0)")
        mode, asked = self.identity.mode_from_command(m.param2, m.param3)
        return self._mode(cmd, mode, inp, asked)

    def _mission_start(self, m: Any, cmd: CommanderState, inp: StepInput) -> Handled:
        verdict = requests.OK
        if math.isfinite(m.param1) and m.param1 > 0 and cmd.plan:
            cmd, verdict = requests.set_current(cmd, int(m.param1))
        if not verdict.accepted:
            return cmd, verdict
        if cmd.mode == FlightMode.MISSION and cmd.mission_done:
            cmd = requests.dataclasses.replace(cmd, mode=FlightMode.HOLD)
        return self._set_mode(cmd, FlightMode.MISSION, inp)

    def _reposition(self, m: Any, cmd: CommanderState, inp: StepInput) -> Handled:
        return guided.reposition(m, cmd, self._context(cmd, inp))

    def _change_speed(self, m: Any, cmd: CommanderState, inp: StepInput) -> Handled:
        return requests.change_speed(cmd, float(m.param2))

    def _set_mission_current(self, m: Any, cmd: CommanderState, inp: StepInput) -> Handled:
        return requests.set_current(cmd, int(m.param1))

    def _set_message_interval(self, m: Any, cmd: CommanderState, inp: StepInput) -> Handled:
        msg_id = int(m.param1)
        name = mav.mavlink_map[msg_id].msgname if msg_id in mav.mavlink_map else None
        if name not in telemetry.DEFAULT_RATES_HZ and name not in telemetry.ONE_SHOT.values():
            return cmd, requests.Verdict(UNSUPPORTED)
        interval_us = m.param2
        hz = None if interval_us == 0 else (0.0 if interval_us < 0 else 1e6 / interval_us)
        self.streams.set_rate(name, hz)
        return cmd, requests.OK

    def _request_message(self, m: Any, cmd: CommanderState, inp: StepInput) -> Handled:
        """REQUEST_MESSAGE and the older commands that ask for one message: acked, then sent."""
        command = int(m.command)
        wanted = REQUESTED_MESSAGE.get(command, int(m.param1) if math.isfinite(m.param1) else -1)
        name = telemetry.ONE_SHOT.get(wanted)
        if name is None:
            return cmd, requests.Verdict(UNSUPPORTED)
        self._ack(m, command, requests.OK, inp)
        self._send_named(name, self._snapshot(cmd, inp), cmd, inp)
        return cmd, None

    def _mode(
        self, cmd: CommanderState, mode: FlightMode | None, inp: StepInput, asked: str
    ) -> tuple[CommanderState, requests.Verdict]:
        """SET_MODE or DO_SET_MODE asking for `mode` (None: one this identity does not have)."""
        if mode is None:
            return cmd, requests.Verdict(DENIED, f"set mode: this vehicle has no {asked}")
        before = cmd.mode
        cmd, verdict = self._set_mode(cmd, mode, inp)
        if verdict.accepted and cmd.mode != before:
            self.on_event(inp.time_s, f"mode {cmd.mode}")
        return cmd, verdict

    def _context(self, cmd: CommanderState, inp: StepInput) -> guided.Context:
        return guided.Context(
            identity=self.identity,
            origin=self.origin,
            home_m=self._home_m(cmd),
            home_up_m=self.ground_z(),
            position_m=inp.state.position_m,
            heading_rad=euler_from_quat(inp.state.quaternion)[2],
            fence=self.params.geofence(),
            time_s=inp.time_s,
        )

    def _guided_item(self, m: Any, cmd: CommanderState, inp: StepInput) -> CommanderState:
        """ArduPilot's guided item (MISSION_ITEM with current = 2), answered by MISSION_ACK."""
        cmd, verdict = guided.guided_item(m, cmd, self._context(cmd, inp))
        if verdict.reason:
            self._text(inp, verdict.reason, mav.MAV_SEVERITY_WARNING)
        result = mav.MAV_MISSION_ACCEPTED if verdict.accepted else mav.MAV_MISSION_ERROR
        peer = (m.get_srcSystem(), m.get_srcComponent())
        self.send(self.protocol.ack(peer, result), inp)
        if verdict.accepted:
            self.on_event(inp.time_s, "guided target")
        return cmd

    def _param(self, m: Any, cmd: CommanderState, inp: StepInput) -> CommanderState:
        outcome = handle_param(self.params, m)
        if outcome.invalid:
            self.link.counters.invalid += 1
        if outcome.refused and self.refusals.due(outcome.refusal_kind, inp.wall_s):
            self._text(inp, outcome.refused, mav.MAV_SEVERITY_WARNING)
        if outcome.changed:
            self.on_event(inp.time_s, outcome.changed)
        for reply in outcome.replies:
            self.send(reply, inp)
        return cmd

    # --- missions --------------------------------------------------------------------------

    def home(self, cmd: CommanderState) -> Home:
        home = self._home_m(cmd)
        lat, lon = local_to_geodetic(self.origin[0], self.origin[1], home[0], home[1])
        return Home(lat, lon, self.origin[2] + self.ground_z())

    def ground_z(self) -> float:
        """The surface the vehicle last stood on, home's once it armed there (a box top, say),
        which relative altitudes count from; 0 before the first step."""
        return self.surface_z if self.surface_z is not None else 0.0

    def _mission(self, m: Any, cmd: CommanderState, inp: StepInput) -> CommanderState:
        outcome = self.protocol.handle(
            m, inp.wall_s, lambda: self.home(cmd), self.params.geofence(), cmd.current
        )
        self._send_outcome(outcome, inp)
        if outcome.mission is not None or outcome.cleared:
            self.items = outcome.mission or ()
            cmd = requests.load_plan(cmd, self._plan(cmd, self.items))
            self.on_event(inp.time_s, f"mission of {len(self.items)} items")
        return cmd

    def load_mission(self, cmd: CommanderState, items: tuple[MissionItem, ...]) -> CommanderState:
        """A mission given on the command line, as if uploaded."""
        self.items = self.protocol.items = items
        return requests.load_plan(cmd, self._plan(cmd, items))

    def _plan(self, cmd: CommanderState, items: tuple[MissionItem, ...]) -> tuple:
        steps = plan_steps(items, Home(*self.origin), self.ground_z())
        if self.identity.home_is_item_0 and steps and is_home_row(items[0], self.home(cmd)):
            steps = steps[1:]
        return steps

    # --- failsafes -------------------------------------------------------------------------

    def _failsafes(self, cmd: CommanderState, inp: StepInput) -> CommanderState:
        cmd, texts = check_failsafes(
            self.failsafes, cmd, self.params.failsafe(), self.params.geofence(),
            self.params.commander(), inp.time_s, inp.wall_s, inp.state.position_m,
            self._home_m(cmd),
            inp.position_lost,
        )  # fmt: skip
        for text in texts:
            self._text(inp, text, mav.MAV_SEVERITY_CRITICAL)
        return cmd


# What a message or a command does: a handler a table names, as telemetry names its builders.
def _switch_to(mode: FlightMode) -> CommandHandler:
    """The handler of a command that only switches to `mode`."""
    return lambda station, m, cmd, inp: station._set_mode(cmd, mode, inp)


MessageHandler = Callable[[GroundStation, Any, CommanderState, StepInput], CommanderState]
MESSAGES: dict[str, MessageHandler] = {
    "HEARTBEAT": GroundStation._heartbeat,
    "COMMAND_LONG": GroundStation._command,
    "COMMAND_INT": GroundStation._command,
    "SET_MODE": GroundStation._set_mode_message,
    "MISSION_SET_CURRENT": GroundStation._mission_set_current,
    "SET_POSITION_TARGET_LOCAL_NED": GroundStation._setpoint,
    "SET_POSITION_TARGET_GLOBAL_INT": GroundStation._setpoint,
    "REQUEST_DATA_STREAM": GroundStation._request_data_stream,
    "FILE_TRANSFER_PROTOCOL": GroundStation._ftp,
}
COMMANDS: dict[int, CommandHandler] = {
    mav.MAV_CMD_COMPONENT_ARM_DISARM: GroundStation._arm_disarm,
    mav.MAV_CMD_NAV_TAKEOFF: GroundStation._takeoff,
    mav.MAV_CMD_NAV_LAND: _switch_to(FlightMode.LAND),
    mav.MAV_CMD_NAV_RETURN_TO_LAUNCH: _switch_to(FlightMode.RETURN),
    mav.MAV_CMD_DO_SET_MODE: GroundStation._do_set_mode,
    mav.MAV_CMD_MISSION_START: GroundStation._mission_start,
    mav.MAV_CMD_DO_REPOSITION: GroundStation._reposition,
    mav.MAV_CMD_DO_CHANGE_SPEED: GroundStation._change_speed,
    mav.MAV_CMD_DO_SET_MISSION_CURRENT: GroundStation._set_mission_current,
    mav.MAV_CMD_SET_MESSAGE_INTERVAL: GroundStation._set_message_interval,
    mav.MAV_CMD_REQUEST_MESSAGE: GroundStation._request_message,
    mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: GroundStation._request_message,
    mav.MAV_CMD_GET_HOME_POSITION: GroundStation._request_message,
}
# the older commands that each ask for one message (REQUEST_MESSAGE names it in param1)
REQUESTED_MESSAGE = {
    mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
    mav.MAV_CMD_GET_HOME_POSITION: mav.MAVLINK_MSG_ID_HOME_POSITION,
}
