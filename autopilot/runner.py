"""The autopilot's flight loop: simulator link -> state -> commander -> model -> controller.

One control step per HIL_SENSOR, answered with exactly one HIL_ACTUATOR_CONTROLS; the
sensors' time is the only clock. The loop is the edge; every decision is a pure function:
the commander's in `commander`, ground contact beside the land detector, the control law,
anti-windup and bumpless handover in `control`, the learner's sample schedule in `online`,
the figures after the flight in `summary`.
"""

from __future__ import annotations

import dataclasses
import gc
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from autopilot.commander import requests
from autopilot.commander.commander import (
    AIRBORNE_PHASES,
    Command,
    CommanderState,
    Phase,
    command,
)
from autopilot.control.controller import (
    ControlOutput,
    control,
    integral_frozen,
    integrate,
    model_handover,
)
from autopilot.control.ground_models import (
    GroundEffectInputs,
    NeuralGroundEffect,
    fixed_point_step,
)
from autopilot.control.land_detector import (
    AIRBORNE_MARGIN_M,
    LandDetector,
    airborne,
    landing_contact,
)
from autopilot.estimation.navigation import Navigation
from autopilot.flight_config import AutopilotConfig, Flight
from autopilot.gcs.ground_station import GroundStation, StepInput
from autopilot.gcs.link import GcsLink
from autopilot.identity import identity_named
from autopilot.nav_metrics import estimation_error
from autopilot.online.learning_sample import learning_sample
from autopilot.online.online_control import OnlineControl, vertical_tracking_error
from autopilot.online.sample_schedule import SampleSchedule
from autopilot.recording.record_options import RecordOptions
from autopilot.recording.recorder import Recorder, open_recorder
from autopilot.simlink import LinkLost, SimLink, Stopped
from autopilot.summary import MODES, FlightTrace, flight_figures, trace_log
from autopilot.truth import true_height_m, true_state
from autopilot.tuning import Tuning
from autopilot.types import FlightMode, FlightState, Setpoint, Step
from simbridge.frames import Vec3
from simbridge.hil import mavlink as mav
from simbridge.rotors import Quad

AUTO_ARM_AFTER_S = 0.2  # --auto-start: arm once the sensors have been healthy this long
RESTING_PHASES = (Phase.DISARMED, Phase.ARMED, Phase.LANDED)  # the estimator may assume rest


@dataclass
class LoopState:
    """What the loop carries from one step to the next."""

    cmd: CommanderState = field(default_factory=CommanderState)
    detector: LandDetector = LandDetector()
    integral_m_s2: Vec3 = (0.0, 0.0, 0.0)  # the position loop's integral term
    speeds_rad_s: Quad = (0.0, 0.0, 0.0, 0.0)  # sent at the last step
    ge_n: Vec3 = (0.0, 0.0, 0.0)  # the ground-effect estimate the controller used
    output: ControlOutput | None = None  # the controller's, None with the rotors off
    last_t_s: float = 0.0
    last_setpoint_z_m: float = 0.0
    schedule: SampleSchedule = SampleSchedule()
    drawn_plan: tuple | None = None  # the plan the recording shows
    landed: CommanderState | None = None  # a long run's flight that has landed, until closed
    landing_closed: bool = False  # its figures kept: not again while it rests on that landing
    armed_s: float | None = None  # a long run's: when the vehicle last left the ground's rest


@dataclass
class Parts:
    """The flight's running components, opened before the loop and closed after it."""

    config: AutopilotConfig
    tuning: Tuning
    nav: Navigation
    recorder: Recorder
    online: OnlineControl
    gcs: GcsLink
    station: GroundStation
    link: SimLink
    on_event: Callable[[float, str], None]
    trace: FlightTrace
    resting_height_m: float


@dataclass(frozen=True)
class Estimate:
    state: FlightState
    height_m: float
    seconds: float  # the estimator's prediction, for the timings


@dataclass(frozen=True)
class Commanded:
    """The commander's answer this step, and whether the vehicle looked in ground contact."""

    result: Command
    contact: bool


def _recording_options(config: AutopilotConfig) -> RecordOptions | None:
    """The recording's options with which rows are airborne, for readers of the recording."""
    record = config.record
    if record is None:
        return None
    info = {
        "airborne_modes": [p.value for p in AIRBORNE_PHASES],
        "airborne_margin_m": AIRBORNE_MARGIN_M,
    }
    return dataclasses.replace(record, info={**(record.info or {}), **info})


def _open(config: AutopilotConfig, trace: FlightTrace) -> Parts:
    """The recorder first (the simulator's clock starts when the link connects), the learner,
    the ground stations, then the simulator link."""
    vehicle = config.vehicle
    resting_height = vehicle.body_size_m[2] / 2.0  # the range sensor sits at the centre of mass
    tuning = Tuning(config.params, vehicle, config.network)
    nav = Navigation(config.params.estimator(), config.origin, resting_height)
    recorder = open_recorder(_recording_options(config), vehicle, MODES)
    online_options = dataclasses.replace(config.online, on_report=recorder.learner)
    online = OnlineControl(online_options, config.params, config.network)
    online.refresh(tuning.model, 0.0)
    online.wait_ready()
    user_on_event = config.on_event or (lambda t, text: None)

    def on_event(t: float, text: str) -> None:
        user_on_event(t, text)
        if text.startswith("failsafe"):
            trace.failsafes.append(f"{text} at {t:.2f} s")
        recorder.event(text, "WARN" if text.startswith("failsafe") else "INFO", t)

    gcs = GcsLink(list(config.gcs_urls), config.signing)
    station = GroundStation(
        gcs, config.params, identity_named(config.identity), config.origin, on_event,
        on_ready=config.on_ready or (lambda text: None),
    )  # fmt: skip
    # before the link: the simulator's clock runs from the connection to the first reply
    gc.collect()
    gc.freeze()  # what exists now (modules, models, the world) is never scanned again
    try:
        link = SimLink(config.sim_url, config.link_timeout_s, stop=config.should_stop)
    except LinkLost as lost:
        recorder.close(str(lost))
        gcs.close()
        online.close([])
        raise
    recorder.watch_counters("sim", link.counters)
    recorder.watch_counters("gcs", gcs.counters.recorded)
    return Parts(
        config, tuning, nav, recorder, online, gcs, station, link, on_event, trace, resting_height
    )


def _estimate(p: Parts, s: LoopState, step: Step) -> Estimate | None:
    """The estimator's state at this step; None while it aligns (the rotors stay off)."""
    t_nav = time.perf_counter()
    if not p.nav.ready:  # aligning: on the tick's pose or fix, which follow its IMU
        p.link.rest_of_tick(step)
    p.nav.predict(step)
    seconds = time.perf_counter() - t_nav
    if not p.nav.ready:  # aligning: the first pose or fix has not come yet
        channels = p.config.vehicle.actuator_channels
        p.link.send(step.sensor["time_usec"], (0.0, 0.0, 0.0, 0.0), channels, False)
        return None
    if s.cmd.phase in RESTING_PHASES:
        p.nav.resting()
    return Estimate(p.nav.state(), p.nav.height_m(), seconds)


def _before_command(p: Parts, s: LoopState, t: float, state: FlightState) -> None:
    """A mission given on the command line, the auto-start, changed parameters."""
    config, tuning = p.config, p.tuning
    if not p.trace.rows and config.mission:
        s.cmd = p.station.load_mission(s.cmd, config.mission)
    if (
        config.auto_start
        and s.cmd.phase == Phase.DISARMED
        and t >= AUTO_ARM_AFTER_S
        and s.cmd.touchdown_s is None
        and not p.link.behind()  # caught up with a backlog of stand-time ticks
    ):
        s.cmd, _ = requests.arm(s.cmd, t, state.position_m, None, False)
        s.cmd, _ = requests.set_mode(
            s.cmd, FlightMode.MISSION, t, state.position_m, tuning.commander
        )
    if tuning.refresh():
        p.online.refresh(tuning.model, t)
        p.nav.params = config.params.estimator()


def _command(p: Parts, s: LoopState, t: float, estimate: Estimate) -> Commanded:
    """Ground contact, the land detector, then the commander's phase and setpoint."""
    tuning, state, height = p.tuning, estimate.state, estimate.height_m
    landing = s.cmd.phase == Phase.LANDING
    contact = landing_contact(
        height,
        p.resting_height_m,
        state.velocity_m_s[2],
        state.position_m[2],
        s.last_setpoint_z_m if landing else None,
        s.output.commanded_acceleration_m_s2[2] if s.output is not None else None,
        tuning.land_detector,
    )
    s.detector = s.detector.step(t, contact)
    cmd = command(
        s.cmd,
        tuning.commander,
        t,
        state.position_m,
        height,
        p.resting_height_m,
        tuning.lead_s,
        s.detector.landed(t, tuning.land_detector),
        tuning.vertical_lead_s,
    )
    s.cmd = cmd.state
    return Commanded(cmd, contact)


def _control(p: Parts, s: LoopState, t: float, estimate: Estimate, cmd: Command) -> Vec3 | None:
    """The ground-effect model's estimate and the controller's rotor speeds (off without a
    setpoint); returns the model's prediction, None with the rotors off."""
    if cmd.setpoint is None:
        s.speeds_rad_s, s.ge_n, s.output = (0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), None
        s.integral_m_s2 = (0.0, 0.0, 0.0)  # rotors off: the next flight starts afresh
        return None
    tuning, vehicle, state, speeds = p.tuning, p.config.vehicle, estimate.state, s.speeds_rad_s
    t0 = time.perf_counter()
    replaced = p.online.apply(tuning.model, t)
    v = p.online.model_velocity(s.cmd.phase, state.velocity_m_s, cmd.setpoint.velocity_m_s)
    inputs = GroundEffectInputs(estimate.height_m, v, state.quaternion, speeds)
    target = tuning.model.predict(inputs)
    if replaced is not None and tuning.controller.position_i > 0.0:
        old = NeuralGroundEffect(replaced).predict(inputs)
        s.integral_m_s2 = model_handover(s.integral_m_s2, target, old, vehicle.mass_kg)
    rotor_thrust = vehicle.thrust_coefficient_n_s2 * sum(n * n for n in speeds)
    s.ge_n = fixed_point_step(s.ge_n, target, rotor_thrust)
    term = s.output.position_term_m_s2 if s.output is not None else None
    s.output = control(
        state, cmd.setpoint, s.ge_n, vehicle, tuning.controller, s.integral_m_s2, term,
        t - s.last_t_s,
    )  # fmt: skip
    s.speeds_rad_s = s.output.rotor_speeds_rad_s
    s.last_setpoint_z_m = cmd.setpoint.position_m[2]
    p.trace.timings.append(time.perf_counter() - t0)
    p.trace.step_timings.append(p.trace.timings[-1] + estimate.seconds)
    return target


def _integrate(p: Parts, s: LoopState, t: float, height_m: float, contact: bool) -> None:
    """The integral for the next step, unless anti-windup holds it."""
    if s.output is None:
        return
    frozen = integral_frozen(
        s.cmd.phase in AIRBORNE_PHASES,
        s.cmd.phase == Phase.TAKING_OFF,
        height_m,
        p.resting_height_m,
        contact,
        s.output.saturated,
    )
    s.integral_m_s2 = integrate(
        s.integral_m_s2, s.output.pd_acceleration_m_s2, t - s.last_t_s, p.tuning.controller, frozen
    )


def _sample(
    p: Parts, s: LoopState, t: float, step: Step, estimate: Estimate, setpoint: Setpoint | None,
    applied: Quad, in_the_air: bool,
) -> bool:  # fmt: skip
    """A learning sample when one is due, to the learner and, when recording samples, to the
    trace; True once enough are recorded."""
    config = p.config
    rate_hz = config.record_hz or p.online.sample_hz
    if not s.schedule.due(t, rate_hz, in_the_air):
        return False
    state, vehicle = estimate.state, config.vehicle
    row = learning_sample(
        t, step, state, estimate.height_m, applied, vehicle, p.nav.accel_bias_m_s2()
    )
    p.online.submit(row, vertical_tracking_error(state, setpoint))
    samples = p.trace.samples
    if config.record_hz > 0.0:
        samples.append(row)
    s.schedule = s.schedule.after_sample(t, rate_hz)
    if config.on_sample is not None:
        config.on_sample(len(samples))
    return (
        config.record_hz > 0.0
        and config.stop_after_samples is not None
        and len(samples) >= config.stop_after_samples
    )


def _report(
    p: Parts, s: LoopState, t: float, step: Step, estimate: Estimate, cmd: Command, applied: Quad,
    in_the_air: bool, inp: StepInput,
) -> None:  # fmt: skip
    """The step's truth to the flight log, the ground stations, the recording and the trace."""
    config, nav, recorder = p.config, p.nav, p.recorder
    state = estimate.state
    flying = s.cmd.phase in AIRBORNE_PHASES
    actual = true_state(step, config.origin) or state
    true_height = true_height_m(step, actual, nav.terrain_m)
    # the flight log's rows: in the air by the truth, as the recording's reader judges
    if config.on_step is not None and airborne(true_height, p.resting_height_m) and flying:
        config.on_step(t, step, actual, applied)
    p.station.after_step(s.cmd, inp, cmd.reached, cmd.events)
    if s.cmd.plan is not s.drawn_plan:
        s.drawn_plan = s.cmd.plan
        recorder.mission(s.cmd.plan, state.position_m, s.cmd.home_m, t)
    nav_error = estimation_error(state, actual)
    if in_the_air and flying:
        p.trace.nav_errors.append(nav_error)
    recorder.estimator(t, nav_error, nav.quality.this_step)
    recorder.step(
        t, step, actual, true_height, s.cmd.phase, cmd.armed, cmd.setpoint, s.ge_n,
        s.speeds_rad_s, s.output, flight_mode=s.cmd.mode.value,
    )  # fmt: skip
    for text in nav.events:  # after the step: the recording opens with the mode
        p.on_event(t, text)
    nav.events.clear()
    zd = cmd.setpoint.position_m[2] if cmd.setpoint is not None else math.nan
    pos, v = actual.position_m, actual.velocity_m_s
    p.trace.rows.append((t, *pos, *v, zd, true_height, MODES.index(s.cmd.phase)))


def _bound_trace(p: Parts, s: LoopState, t: float) -> None:
    """A run that outlives its flights (no exit after landing: `sitl`) keeps each flight's
    figures, not its steps: once it has landed and settled, or is armed again first (a
    ground station flying missions back to back), or was disarmed without a landing."""
    phase, trace = s.cmd.phase, p.trace
    if p.config.exit_after_landing:
        return
    resting = phase in (Phase.DISARMED, Phase.LANDED)
    if not resting and s.armed_s is None:
        s.armed_s = t  # its time limit counts from here
    elif resting:
        s.armed_s = None
    if phase != Phase.LANDED:
        s.landing_closed = False
    elif s.landed is None and not s.landing_closed:
        s.landed = s.cmd  # the flight's own plan says where it meant to land
    ended = s.landed or (s.cmd if phase == Phase.DISARMED and trace.flew() else None)
    if ended is None:
        if resting:
            trace.trim_idle()
        return
    settled = t - (ended.touchdown_s or t) >= p.config.settle_after_landing_s
    if phase == Phase.LANDED and not settled:
        return
    figures = flight_figures(trace, trace_log(trace), ended, p.resting_height_m, 0.0, p.nav)
    figures = {k: v for k, v in figures.items() if k not in ("wall_s", "rtf")}
    trace.close_flight({**figures, "ended": "landed" if ended is s.landed else "disarmed"})
    s.landed = None
    s.landing_closed = phase == Phase.LANDED  # one flight, however long it rests after


def _ended(config: AutopilotConfig, s: LoopState, t: float) -> str | None:
    """Why the flight ends after this step, or None. The time limit counts from the start,
    or in a run that outlives its flights (`sitl`) from each arming."""
    cmd = s.cmd
    if (
        config.exit_after_landing
        and cmd.phase == Phase.LANDED
        and t - (cmd.touchdown_s or t) >= config.settle_after_landing_s
    ):
        return "landed"
    start_s = 0.0 if config.exit_after_landing else s.armed_s
    if start_s is not None and t - start_s >= config.max_flight_s:
        return "mission time limit"
    if config.should_stop():
        return "stopped"
    return None


def _step(p: Parts, s: LoopState) -> str | None:
    """One control step: link -> estimate -> command -> control -> send, then what is off
    the control path. Returns why the flight ends, or None."""
    step = p.link.receive_step()
    t_us = step.sensor["time_usec"]
    t = t_us * 1e-6
    estimate = _estimate(p, s, step)
    if estimate is None:
        return None
    _before_command(p, s, t, estimate.state)
    commanded = _command(p, s, t, estimate)
    cmd = commanded.result
    in_the_air = airborne(estimate.height_m, p.resting_height_m)
    applied = s.speeds_rad_s  # the rotor speeds of the interval that ended at t
    target = _control(p, s, t, estimate, cmd)
    n_max = p.config.vehicle.max_rotor_speed_rad_s
    channels = p.config.vehicle.actuator_channels
    p.link.send(t_us, tuple(n / n_max for n in s.speeds_rad_s), channels, cmd.armed)
    # off the control path from here: the simulator steps meanwhile
    _integrate(p, s, t, estimate.height_m, commanded.contact)
    s.last_t_s = t
    inp = StepInput(
        t, time.monotonic(), estimate.state, estimate.height_m, p.resting_height_m,
        p.nav.position_lost(t),
    )  # fmt: skip
    # the rest of the tick (its other sensors, then its truth) for the fusions
    p.link.receive_truth(step)
    t_nav = time.perf_counter()
    p.nav.correct(step)
    p.trace.correction_timings.append(time.perf_counter() - t_nav)
    truth = step.latest.get("DEBUG_VECT")
    if target is not None and in_the_air and truth is not None:
        p.trace.ge_pairs.append((t, estimate.height_m, target[2], truth["z"]))
    flying = in_the_air and s.cmd.phase in AIRBORNE_PHASES
    if _sample(p, s, t, step, estimate, cmd.setpoint, applied, flying):
        return "enough samples"
    _report(p, s, t, step, estimate, cmd, applied, in_the_air, inp)
    _bound_trace(p, s, t)
    # what the ground stations asked since, and the failsafes: for the next step (a real
    # autopilot's commander runs beside its control loop, not in it)
    s.cmd = p.station.before_step(s.cmd, inp)
    return _ended(p.config, s, t)


def _summary(
    p: Parts, s: LoopState, ended: str, wall_s: float, online_summary: dict[str, Any]
) -> tuple[np.ndarray, dict[str, Any]]:
    """The trajectory and the summary, with the links' counters and the learner's report."""
    summary: dict[str, Any] = {"ended": ended, "landed": ended == "landed"}
    log = trace_log(p.trace)
    summary.update(flight_figures(p.trace, log, s.cmd, p.resting_height_m, wall_s, p.nav))
    summary.update(
        model=p.tuning.model.name,
        malformed=p.link.malformed,
        unknown=p.link.unknown,
        # heartbeats_kept: sent on the wall clock while the loop stalled
        gcs={**p.gcs.counters.as_dict(), "heartbeats_kept": p.gcs.keepalive.resent},
        mission_items=len(p.station.items),
        touchdown_declared_s=s.cmd.touchdown_s,
        failsafes=p.trace.failsafes,
        **({"flights": p.trace.flights} if p.trace.flights else {}),
        **online_summary,
    )
    return log, summary


def fly_mission(config: AutopilotConfig) -> Flight:
    """Run the autopilot against the simulator at `config.sim_url` until the flight ends."""
    trace = FlightTrace()
    p = _open(config, trace)
    s = LoopState()
    ended: str | None = None
    wall0 = time.perf_counter()
    try:
        while ended is None:
            ended = _step(p, s)
    except Stopped:
        ended = "stopped"
    except LinkLost as lost:
        ended = str(lost)
        # the ground stations hear why, before the link to them closes too
        p.station.say(ended, s.last_t_s, time.monotonic(), mav.MAV_SEVERITY_CRITICAL)
    finally:
        # the loop's time: stopping the learner and closing links and files is not flying
        wall = time.perf_counter() - wall0
        p.link.close()
        online_summary = p.online.close(p.trace.timings)
        p.gcs.save_signing(time.monotonic())
        p.gcs.close()
        if sys.exc_info()[0] is not None:  # an exception on its way out ended the flight
            p.recorder.close("interrupted")
    assert ended is not None
    summary: dict[str, Any] = {"ended": ended, "landed": ended == "landed"}
    try:
        log, summary = _summary(p, s, ended, wall, online_summary)
    finally:
        p.recorder.close(ended, summary)  # the summary in the file too (a no-op if closed)
    summary.update(p.recorder.stats())
    data = np.asarray(trace.samples, dtype=float) if trace.samples else None
    return Flight(log=log, summary=summary, ended=ended, samples=data)
