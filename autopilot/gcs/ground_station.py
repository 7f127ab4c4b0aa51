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
from autopilot.commander.modes import FlightMode, decode_mode
from autopilot.gcs import telemetry
from autopilot.gcs.link import GcsLink
from autopilot.gcs.mission_protocol import MissionProtocol, Outcome
from autopilot.gcs.param_protocol import ftp_nak, handle_param
from autopilot.params import ParamStore
from autopilot.types import FlightState
from simbridge.frames import euler_from_quat, local_to_geodetic
from simbridge.hil import mavlink as mav

ACCEPTED, DENIED = mav.MAV_RESULT_ACCEPTED, mav.MAV_RESULT_DENIED
UNSUPPORTED, FAILED = mav.MAV_RESULT_UNSUPPORTED, mav.MAV_RESULT_FAILED
FORCE_MAGIC = 21196  # ARM_DISARM param2: arm or disarm whatever the checks say
SIGNING_SAVE_S = 10.0  # wall seconds between saves of the signing timestamp
REFUSAL_REPEAT_S = 5.0  # wall seconds before the same refused setpoint is explained again
MAX_REFUSALS = 64
GUIDED_ITEM = 2  # MISSION_ITEM.current 2: ArduPilot's guided target, not a mission item


@dataclass
class StepInput:
    time_s: float
    wall_s: float
    state: FlightState
    height_m: float
    resting_height_m: float
    position_lost: str | None = None  # the estimator's word: which position source went quiet


@dataclass
class GroundStation:
    link: GcsLink
    params: ParamStore
    identity: str
    origin: tuple[float, float, float]
    on_event: Callable[[float, str], None] = lambda t, text: None
    items: tuple[MissionItem, ...] = ()
    streams: telemetry.Streams = field(default_factory=telemetry.Streams)
    failsafes: Failsafes = field(default_factory=Failsafes)
    initial_home_m: tuple[float, float, float] | None = None
    signing_saved_wall_s: float = 0.0
    last_mission_current: tuple[int, int, int] | None = None
    surface_z: float | None = None  # local z of the surface under the vehicle on the ground
    last_status: tuple[Any, ...] | None = None
    text_id: int = 0
    refusals: dict[str, float] = field(default_factory=dict)  # setpoint refusal -> wall time

    def __post_init__(self) -> None:
        self.protocol = MissionProtocol(self.identity)

    # --- the per-step entry points ---------------------------------------------------------

    def before_step(self, cmd: CommanderState, inp: StepInput) -> CommanderState:
        """Apply what the ground stations asked since the last step; check the failsafes."""
        self._first_position(inp)
        hold_mode = FlightMode.GUIDED if self.identity == "ardupilot" else FlightMode.HOLD
        if cmd.hold_mode != hold_mode:  # ArduCopter holds in Guided after a guided take-off
            cmd = requests.dataclasses.replace(cmd, hold_mode=hold_mode)
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
        due = self.streams.due(inp.time_s)
        status = (snap.phase, snap.mode, snap.armed)
        if status != self.last_status:  # tell at once, not at the next 1 Hz heartbeat
            self.last_status = status
            due = [*due, "HEARTBEAT", "EXTENDED_SYS_STATE"]
        for name in dict.fromkeys(due):
            self._send_named(name, snap, cmd, inp)
        current = self._mission_current_key(cmd)
        if current != self.last_mission_current:
            self._send_named("MISSION_CURRENT", snap, cmd, inp)
        if (
            self.link.signing is not None
            and inp.wall_s - self.signing_saved_wall_s > SIGNING_SAVE_S
        ):
            self.save_signing(inp.wall_s)

    def _first_position(self, inp: StepInput) -> None:
        """Home until one is set: where the vehicle was at the first step."""
        if self.initial_home_m is None:
            self.initial_home_m = inp.state.position_m

    def save_signing(self, wall_s: float) -> None:
        if self.link.signing is not None:
            self.link.signing.save(self.link.signing_timestamp)
            self.signing_saved_wall_s = wall_s

    # --- sending ---------------------------------------------------------------------------

    def send(self, message: Any, inp: StepInput) -> None:
        self.link.send(message, inp.wall_s)

    def _text(self, inp: StepInput, text: str, severity: int = mav.MAV_SEVERITY_INFO) -> None:
        """STATUSTEXT; a text over 50 bytes goes in chunks sharing an id (MAVLink 2)."""
        self.on_event(inp.time_s, text)
        data = text.encode()[: 50 * 20]
        chunks = [data[i : i + 50] for i in range(0, len(data), 50)] or [b""]
        text_id = 0
        if len(chunks) > 1:
            self.text_id = self.text_id % 65535 + 1
            text_id = self.text_id
        for seq, chunk in enumerate(chunks):
            self.send(mav.MAVLink_statustext_message(severity, chunk, text_id, seq), inp)

    def _snapshot(self, cmd: CommanderState, inp: StepInput) -> telemetry.Snapshot:
        home = cmd.home_m if cmd.home_m is not None else self.initial_home_m
        return telemetry.Snapshot(
            time_s=inp.time_s,
            state=inp.state,
            origin=self.origin,
            home_m=home,
            phase=cmd.phase,
            mode=cmd.mode,
            armed=cmd.phase not in (Phase.DISARMED, Phase.LANDED),
            ready=self._not_ready(cmd, inp) is None,
            identity=self.identity,
            fence_on=self.params.geofence() != Geofence(),
            fence_breached=self.failsafes.fence_breached,
        )

    def _mission_current_key(self, cmd: CommanderState) -> tuple[int, int, int]:
        if not self.items:
            state = mav.MISSION_STATE_NO_MISSION
        elif cmd.mission_done:
            state = mav.MISSION_STATE_COMPLETE
        elif cmd.mode == FlightMode.MISSION and cmd.phase in AIRBORNE_PHASES:
            state = mav.MISSION_STATE_ACTIVE
        elif cmd.mode == FlightMode.MISSION:
            state = mav.MISSION_STATE_NOT_STARTED
        else:
            state = mav.MISSION_STATE_PAUSED if cmd.current > 0 else mav.MISSION_STATE_NOT_STARTED
        seq = cmd.plan[cmd.current].seq if cmd.plan and cmd.current < len(cmd.plan) else 0
        if cmd.mission_done:
            seq = len(self.items)  # past the last item, as PX4 reports a finished mission
        return seq, len(self.items), state

    def _send_named(
        self, name: str, snap: telemetry.Snapshot, cmd: CommanderState, inp: StepInput
    ) -> None:
        if name == "MISSION_CURRENT":
            seq, total, state = self._mission_current_key(cmd)
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
            message = telemetry.autopilot_version(self.identity)
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
        if kind == "HEARTBEAT":
            if m.type == mav.MAV_TYPE_GCS or m.get_srcComponent() != self.link.compid:
                self.failsafes.gcs_seen = True
                self.failsafes.gcs_heard_wall_s = inp.wall_s
                if self.failsafes.gcs_lost:
                    self.failsafes.gcs_lost = False
                    self._text(inp, "ground station link regained")
            return cmd
        if kind in ("COMMAND_LONG", "COMMAND_INT"):
            return self._command(m, cmd, inp)
        if kind == "SET_MODE":
            mode = decode_mode(self.identity, int(m.custom_mode))
            peer = (m.get_srcSystem(), m.get_srcComponent())
            return self._mode(cmd, mode, inp, 11, peer, f"custom mode {int(m.custom_mode)}")
        if kind.startswith("PARAM_"):
            return self._param(m, cmd, inp)
        if kind in ("MISSION_ITEM", "MISSION_ITEM_INT") and m.current == GUIDED_ITEM:
            return self._guided_item(m, cmd, inp)
        if kind.startswith("MISSION_") and kind != "MISSION_SET_CURRENT":
            return self._mission(m, cmd, inp)
        if kind == "MISSION_SET_CURRENT":
            cmd, verdict = self._set_current(cmd, int(m.seq))
            if not verdict.accepted:
                self._text(inp, verdict.reason, mav.MAV_SEVERITY_WARNING)
            return cmd
        if kind in ("SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT"):
            cmd, refused = guided.setpoint(m, cmd, self._context(cmd, inp))
            if refused is not None:
                self.link.counters.invalid += 1
                if inp.wall_s - self.refusals.get(refused, -math.inf) > REFUSAL_REPEAT_S:
                    if len(self.refusals) > MAX_REFUSALS:  # hostile input: bounded all the same
                        self.refusals.clear()
                    self.refusals[refused] = inp.wall_s  # a stream's refusal, said once
                    self._text(inp, refused, mav.MAV_SEVERITY_WARNING)
            return cmd
        if kind == "REQUEST_DATA_STREAM":
            ids = telemetry.DATA_STREAMS.keys() if m.req_stream_id == 0 else [m.req_stream_id]
            for stream_id in ids:
                for name in telemetry.DATA_STREAMS.get(stream_id, ()):
                    self.streams.set_rate(name, float(m.req_message_rate) if m.start_stop else 0.0)
            return cmd
        if kind == "FILE_TRANSFER_PROTOCOL":
            self.send(ftp_nak(m), inp)
            return cmd
        return cmd

    def _ack(self, m: Any, command: int, result: int, inp: StepInput, reason: str = "") -> None:
        if reason:
            self._text(inp, reason, mav.MAV_SEVERITY_WARNING)
        self.send(
            mav.MAVLink_command_ack_message(
                command, result, 0, 0, m.get_srcSystem(), m.get_srcComponent()
            ),
            inp,
        )

    def _not_ready(self, cmd: CommanderState, inp: StepInput) -> str | None:
        if inp.time_s < 0.2:
            return "sensors not ready"
        if inp.height_m > inp.resting_height_m + 0.02:
            return "not on the ground"
        return None

    def _command(self, m: Any, cmd: CommanderState, inp: StepInput) -> CommanderState:
        c = int(m.command)
        p = [m.param1, m.param2, m.param3, m.param4]
        position = inp.state.position_m
        t = inp.time_s
        params = self.params.commander()
        verdict = requests.OK
        if c == mav.MAV_CMD_COMPONENT_ARM_DISARM:
            force = round(p[1]) == FORCE_MAGIC if math.isfinite(p[1]) else False
            if p[0] == 1.0:
                cmd, verdict = requests.arm(cmd, t, position, self._not_ready(cmd, inp), force)
                if verdict.accepted:
                    self.on_event(t, "armed by the ground station")
            elif p[0] == 0.0:
                cmd, verdict = requests.disarm(cmd, t, force)
                if verdict.accepted:
                    self.on_event(t, "disarmed by the ground station")
            else:
                verdict = requests.Verdict(DENIED, f"ARM_DISARM param1 {p[0]:g}: expected 0 or 1")
        elif c == mav.MAV_CMD_NAV_TAKEOFF:
            if requests.airborne(cmd):  # as ArduCopter: never left climbing in a take-off mode
                verdict = requests.Verdict(DENIED, "take-off denied: already flying")
            elif cmd.phase != Phase.ARMED:
                verdict = requests.Verdict(DENIED, "take-off denied: arm first")
            else:
                altitude = None
                z = m.param7 if m.get_type() == "COMMAND_LONG" else m.z
                if self.identity == "ardupilot" and math.isfinite(z) and z > 0.0:
                    altitude = float(z)
                if self.identity == "ardupilot" and altitude is None:
                    # ArduCopter takes off to the command's altitude, above where it stands
                    verdict = requests.Verdict(DENIED, "take-off denied: param 7 altitude <= 0")
                else:
                    cmd = requests.dataclasses.replace(cmd, takeoff_altitude_m=altitude)
                    cmd, verdict = requests.set_mode(cmd, FlightMode.TAKEOFF, t, position, params)
        elif c == mav.MAV_CMD_NAV_LAND:
            cmd, verdict = requests.set_mode(cmd, FlightMode.LAND, t, position, params)
        elif c == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            cmd, verdict = requests.set_mode(cmd, FlightMode.RETURN, t, position, params)
        elif c == mav.MAV_CMD_DO_SET_MODE:
            if not int(p[0]) & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                verdict = requests.Verdict(DENIED, "set mode: only custom modes (param1 bit 0)")
            else:
                sub = int(p[2]) if self.identity == "px4" and math.isfinite(p[2]) else 0
                mode = decode_mode(self.identity, int(p[1]), sub)
                asked = f"main mode {int(p[1])} sub {sub}" if self.identity == "px4" else ""
                peer = (m.get_srcSystem(), m.get_srcComponent())
                return self._mode(cmd, mode, inp, c, peer, asked or f"custom mode {int(p[1])}")
        elif c == mav.MAV_CMD_MISSION_START:
            if math.isfinite(p[0]) and p[0] > 0 and cmd.plan:
                cmd, verdict = self._set_current(cmd, int(p[0]))
            if verdict.accepted:
                if cmd.mode == FlightMode.MISSION and cmd.mission_done:
                    cmd = requests.dataclasses.replace(cmd, mode=FlightMode.HOLD)
                cmd, verdict = requests.set_mode(cmd, FlightMode.MISSION, t, position, params)
        elif c == mav.MAV_CMD_DO_REPOSITION:
            cmd, verdict = guided.reposition(m, cmd, self._context(cmd, inp))
        elif c == mav.MAV_CMD_DO_CHANGE_SPEED:
            cmd, verdict = requests.change_speed(cmd, float(p[1]))
        elif c == mav.MAV_CMD_DO_SET_MISSION_CURRENT:
            cmd, verdict = self._set_current(cmd, int(p[0]))
        elif c == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
            name = mav.mavlink_map[int(p[0])].msgname if int(p[0]) in mav.mavlink_map else None
            if name is None or (
                name not in telemetry.DEFAULT_RATES_HZ and name not in telemetry.ONE_SHOT.values()
            ):
                verdict = requests.Verdict(UNSUPPORTED)
            else:
                interval_us = p[1]
                hz = None if interval_us == 0 else (0.0 if interval_us < 0 else 1e6 / interval_us)
                self.streams.set_rate(name, hz)
        elif c in (
            mav.MAV_CMD_REQUEST_MESSAGE,
            mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
            mav.MAV_CMD_GET_HOME_POSITION,
        ):
            wanted = {
                mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
                mav.MAV_CMD_GET_HOME_POSITION: mav.MAVLINK_MSG_ID_HOME_POSITION,
            }.get(c, int(p[0]) if math.isfinite(p[0]) else -1)
            name = telemetry.ONE_SHOT.get(wanted)
            if name is None:
                verdict = requests.Verdict(UNSUPPORTED)
            else:
                self._ack(m, c, ACCEPTED, inp)
                self._send_named(name, self._snapshot(cmd, inp), cmd, inp)
                return cmd
        else:
            verdict = requests.Verdict(UNSUPPORTED)
        self._ack(m, c, verdict.result, inp, verdict.reason)
        return cmd

    def _mode(
        self,
        cmd: CommanderState,
        mode: FlightMode | None,
        inp: StepInput,
        command: int,
        peer: tuple[int, int],
        asked: str,
    ) -> CommanderState:
        if mode is None:
            verdict = requests.Verdict(DENIED, f"set mode: this vehicle has no {asked}")
        else:
            params = self.params.commander()
            position = inp.state.position_m
            before = cmd.mode
            cmd, verdict = requests.set_mode(cmd, mode, inp.time_s, position, params)
            if verdict.accepted and cmd.mode != before:
                self.on_event(inp.time_s, f"mode {cmd.mode}")
        if verdict.reason:
            self._text(inp, verdict.reason, mav.MAV_SEVERITY_WARNING)
        self.send(mav.MAVLink_command_ack_message(command, verdict.result, 0, 0, *peer), inp)
        return cmd

    def _set_current(
        self, cmd: CommanderState, seq: int
    ) -> tuple[CommanderState, requests.Verdict]:
        for index, step in enumerate(cmd.plan):
            if step.seq == seq:
                return requests.set_current(cmd, index)
        return cmd, requests.Verdict(DENIED, f"no mission item {seq}")

    def _context(self, cmd: CommanderState, inp: StepInput) -> guided.Context:
        home = cmd.home_m if cmd.home_m is not None else self.initial_home_m
        return guided.Context(
            identity=self.identity,
            origin=self.origin,
            home_m=home,
            home_up_m=self.ground_z(home),
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
        if outcome.refused:
            self._text(inp, outcome.refused, mav.MAV_SEVERITY_WARNING)
        if outcome.changed:
            self.on_event(inp.time_s, outcome.changed)
        for reply in outcome.replies:
            self.send(reply, inp)
        return cmd

    # --- missions --------------------------------------------------------------------------

    def home(self, cmd: CommanderState) -> Home:
        home = cmd.home_m if cmd.home_m is not None else self.initial_home_m
        lat, lon = local_to_geodetic(self.origin[0], self.origin[1], home[0], home[1])
        return Home(lat, lon, self.origin[2] + self.ground_z(home))

    def ground_z(self, home_m: tuple[float, float, float]) -> float:
        """The surface under home, which relative altitudes count from (a box top, say)."""
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
        home = cmd.home_m if cmd.home_m is not None else self.initial_home_m
        origin = Home(*self.origin)
        steps = plan_steps(items, origin, self.ground_z(home))
        if self.identity == "ardupilot" and steps and is_home_row(items[0], self.home(cmd)):
            steps = steps[1:]  # ArduPilot's item 0 is home, not a place to fly to
        return steps

    # --- failsafes -------------------------------------------------------------------------

    def _failsafes(self, cmd: CommanderState, inp: StepInput) -> CommanderState:
        home = cmd.home_m if cmd.home_m is not None else self.initial_home_m
        cmd, texts = check_failsafes(
            self.failsafes, cmd, self.params.failsafe(), self.params.geofence(),
            self.params.commander(), inp.time_s, inp.wall_s, inp.state.position_m, home,
            inp.position_lost,
        )  # fmt: skip
        for text in texts:
            self._text(inp, text, mav.MAV_SEVERITY_CRITICAL)
        return cmd
