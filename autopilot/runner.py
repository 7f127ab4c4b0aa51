"""The autopilot's flight loop: simulator link -> state -> commander -> model -> controller.

One control step per HIL_SENSOR, answered with exactly one HIL_ACTUATOR_CONTROLS; the
sensors' time is the only clock. The loop is the edge; every decision is a pure function.
"""

from __future__ import annotations

import dataclasses
import gc
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from autopilot.commander import requests
from autopilot.commander.commander import CommanderState, Phase, command
from autopilot.commander.mission_items import MissionItem
from autopilot.control.controller import control, handover, integrate
from autopilot.control.ground_models import (
    GroundEffectInputs,
    GroundEffectModel,
    NeuralGroundEffect,
    fixed_point_step,
    make_model,
)
from autopilot.control.land_detector import LandDetector, ground_contact
from autopilot.estimation.navigation import Navigation
from autopilot.gcs.ground_station import GroundStation, StepInput
from autopilot.gcs.link import GcsLink
from autopilot.gcs.signing import Signing
from autopilot.identity import identity_named
from autopilot.metrics import COLUMNS, flight_metrics, ge_error_metrics, trajectory_sha256
from autopilot.nav_metrics import estimation_error, estimator_metrics
from autopilot.online.learning_sample import learning_sample
from autopilot.online.online_control import OnlineControl, OnlineOptions, vertical_tracking_error
from autopilot.params import ParamStore
from autopilot.recording.record_options import RecordOptions
from autopilot.recording.recorder import open_recorder
from autopilot.simlink import LinkLost, SimLink
from autopilot.truth import true_height_m, true_state
from autopilot.types import FlightMode, FlightState, Step
from simbridge.rotors import Quad
from simbridge.vehicle import GRAVITY_M_S2, Vehicle

MODES = [p.value for p in Phase]
AUTO_ARM_AFTER_S = 0.2  # --auto-start: arm once the sensors have been healthy this long
INTEGRATE_ABOVE_M = 0.005  # the integral runs only this far above resting (not on the ground)


@dataclass(frozen=True)
class AutopilotConfig:
    sim_url: str
    vehicle: Vehicle
    params: ParamStore
    origin: tuple[float, float, float]  # lat deg, lon deg, alt m of the local frame's origin
    network: str | Path | None = None  # the neural model's weights (default: by rho)
    mission: tuple[MissionItem, ...] = ()  # loaded before any ground station speaks
    auto_start: bool = False  # arm and start the mission without a ground station
    exit_after_landing: bool = True  # end once a flight has landed and settled
    identity: str = "px4"
    gcs_urls: tuple[str, ...] = ()
    signing: Signing | None = None
    link_timeout_s: float = 1.0
    settle_after_landing_s: float = 0.5  # keep logging after disarm, to see any bounce
    max_flight_s: float = 900.0
    should_stop: Callable[[], bool] = lambda: False  # a signal asked the loop to end
    on_event: Callable[[float, str], None] | None = None  # modes, arming, failsafes
    record_hz: float = 0.0  # > 0: record learning samples at this rate (thesis: 100 Hz)
    stop_after_samples: int | None = None  # end the flight once this many are recorded
    on_sample: Callable[[int], None] | None = None  # told the count of recorded samples
    # told each airborne step (t, messages, the true state as a lab's motion capture would log
    # it, rotor speeds applied over the last period): the --flight-log of the gap diagnosis
    on_step: Callable[[float, Step, FlightState, Quad], None] | None = None
    online: OnlineOptions = OnlineOptions()  # online learning (GFX_OL_METHOD turns it on)
    record: RecordOptions | None = None  # the flight's rerun recording; None: off


@dataclass
class Flight:
    log: np.ndarray
    summary: dict[str, Any]
    ended: str  # "landed", "enough samples", "mission time limit", or the lost link's reason
    samples: np.ndarray | None = None  # learning samples, columns learner.dataset.COLUMNS


RECORDED_PHASES = (Phase.TAKING_OFF, Phase.FLYING, Phase.HOLDING, Phase.LANDING)
# Samples are taken in the air only: on the ground the contact force would pass for ground
# effect in equation 3.16.
AIRBORNE_MARGIN_M = 0.002


class Tuning:
    """The parameter-derived settings, rebuilt only when a parameter changes."""

    def __init__(self, config: AutopilotConfig) -> None:
        self.config = config
        self.version = -1  # the parameters' version these settings were built from
        self.model_key: tuple[str, float] | None = None
        self.model: GroundEffectModel | None = None
        self.refresh()

    def refresh(self) -> bool:
        store = self.config.params
        if store.version == self.version:
            return False
        self.version = store.version
        self.controller = store.controller()
        self.commander = store.commander()
        self.land_detector = store.land_detector()
        gains = self.controller
        # the speed limits' lead: steady speed = error * a0 / a1 (commander.limited_setpoint)
        self.lead_s = gains.position_d / gains.position_p if gains.position_p > 0 else 2.0
        self.vertical_lead_s = gains.vertical_d / gains.vertical_p if gains.vertical_p > 0 else 2.0
        key = store.model()
        if key != self.model_key:
            self.model_key = key
            self.model = make_model(key[0], self.config.vehicle, key[1], self.config.network)
        return True


def landing_target_xy(cmd: CommanderState) -> tuple[float, float] | None:
    """Where the mission meant to land: its landing item's position, else the last waypoint
    flown before it, else home (a return)."""
    last = None
    for step in cmd.plan:
        if step.kind == "land":
            return step.position_m[:2] if step.position_m is not None else last
        if step.kind == "return":
            return cmd.home_m[:2] if cmd.home_m is not None else last
        if step.position_m is not None:
            last = step.position_m[:2]
    return None


def fly_mission(config: AutopilotConfig) -> Flight:
    """Run the autopilot against the simulator at `config.sim_url` until the flight ends."""
    vehicle = config.vehicle
    resting_height = vehicle.body_size_m[2] / 2.0  # the range sensor sits at the centre of mass
    channels = vehicle.actuator_channels
    n_max = vehicle.max_rotor_speed_rad_s
    tuning = Tuning(config)
    rows: list[tuple[float, ...]] = []
    timings: list[float] = []  # controller and ground-effect model, per step
    step_timings: list[float] = []  # the same with the estimator's prediction before it
    correction_timings: list[float] = []  # the estimator's fusions, after the reply
    ge_pairs: list[tuple[float, float, float]] = []  # (height, predicted, true) vertical GE
    speeds = (0.0, 0.0, 0.0, 0.0)
    ge = (0.0, 0.0, 0.0)
    nav = Navigation(config.params.estimator(), config.origin, resting_height)
    nav_errors: list[tuple[float, ...]] = []
    integral = (0.0, 0.0, 0.0)  # the position loop's integral term, m/s^2
    detector = LandDetector()
    last_t = 0.0
    last_setpoint_z = 0.0
    output = None
    cmd_state = CommanderState()
    ended = "landed"
    samples: list[tuple[float, ...]] = []
    next_sample_s = 0.0
    # The recorder first: the simulator's clock starts when the link connects.
    record = config.record
    if record is not None:  # which rows are airborne, for readers of the recording
        airborne = {
            "airborne_modes": [p.value for p in RECORDED_PHASES],
            "airborne_margin_m": AIRBORNE_MARGIN_M,
        }
        record = dataclasses.replace(record, info={**(record.info or {}), **airborne})
    recorder = open_recorder(record, vehicle, MODES)
    online_options = dataclasses.replace(config.online, on_report=recorder.learner)
    online = OnlineControl(online_options, config.params, config.network)
    online.refresh(tuning.model, 0.0)
    online.wait_ready()
    user_on_event = config.on_event or (lambda t, text: None)

    failsafes: list[str] = []  # for the summary

    def on_event(t: float, text: str) -> None:
        user_on_event(t, text)
        if text.startswith("failsafe"):
            failsafes.append(f"{text} at {t:.2f} s")
        recorder.event(text, "WARN" if text.startswith("failsafe") else "INFO", t)

    gcs = GcsLink(list(config.gcs_urls), config.signing)
    station = GroundStation(
        gcs, config.params, identity_named(config.identity), config.origin, on_event
    )
    # before the link: the simulator's clock runs from the connection to the first reply
    gc.collect()
    gc.freeze()  # what exists now (modules, models, the world) is never scanned again
    try:
        link = SimLink(config.sim_url, timeout_s=config.link_timeout_s)
    except LinkLost as lost:
        recorder.close(str(lost))
        gcs.close()
        online.close()
        raise
    recorder.watch_counters("sim", link.counters)
    recorder.watch_counters("gcs", gcs.counters.recorded)
    drawn_plan: tuple | None = None
    wall0 = time.perf_counter()
    try:
        while True:
            step = link.receive_step()
            t_us = step.sensor["time_usec"]
            t = t_us * 1e-6
            t_nav = time.perf_counter()
            if not nav.ready:  # aligning: on the tick's pose or fix, which follow its IMU
                link.rest_of_tick(step)
            nav.predict(step)
            nav_s = time.perf_counter() - t_nav
            if not nav.ready:  # aligning: the first pose or fix has not come yet
                link.send(t_us, (0.0, 0.0, 0.0, 0.0), channels, False)
                continue
            if cmd_state.phase in (Phase.DISARMED, Phase.ARMED, Phase.LANDED):
                nav.resting()
            state = nav.state()
            height = nav.height_m()
            if not rows and config.mission:
                cmd_state = station.load_mission(cmd_state, config.mission)
            if (
                config.auto_start
                and cmd_state.phase == Phase.DISARMED
                and t >= AUTO_ARM_AFTER_S
                and cmd_state.touchdown_s is None
                and not link.behind()  # caught up with a backlog of stand-time ticks
            ):
                cmd_state, _ = requests.arm(cmd_state, t, state.position_m, None, False)
                cmd_state, _ = requests.set_mode(
                    cmd_state, FlightMode.MISSION, t, state.position_m, tuning.commander
                )
            if tuning.refresh():
                online.refresh(tuning.model, t)
                nav.params = config.params.estimator()
            below = (
                state.position_m[2] - last_setpoint_z if cmd_state.phase == Phase.LANDING else 0.0
            )
            # the lift the controller demands of rotors and ground effect together, over the
            # weight: below 1 it pushes down (a vehicle that does not follow is held up)
            thrust_fraction = (
                1.0 + output.commanded_acceleration_m_s2[2] / GRAVITY_M_S2
                if output is not None
                else 0.0
            )
            contact = ground_contact(
                height,
                resting_height,
                state.velocity_m_s[2],
                below,
                thrust_fraction,
                tuning.land_detector,
            )
            detector = detector.step(t, contact)
            cmd = command(
                cmd_state,
                tuning.commander,
                t,
                state.position_m,
                height,
                resting_height,
                tuning.lead_s,
                detector.landed(t, tuning.land_detector),
                tuning.vertical_lead_s,
            )
            cmd_state = cmd.state
            airborne = height > resting_height + AIRBORNE_MARGIN_M
            applied = speeds  # the rotor speeds of the interval that ended at t
            if cmd.setpoint is not None:
                t0 = time.perf_counter()
                replaced = online.apply(tuning.model)
                inputs = GroundEffectInputs(height, state.velocity_m_s, state.quaternion, speeds)
                target = tuning.model.predict(inputs)
                if replaced is not None and tuning.controller.position_i > 0.0:
                    # bumpless: the new model takes over what the integral held of it
                    old = NeuralGroundEffect(replaced).predict(inputs)
                    m = vehicle.mass_kg
                    change = ((target[0] - old[0]) / m, (target[1] - old[1]) / m,
                              (target[2] - old[2]) / m)  # fmt: skip
                    integral = handover(integral, change)
                rotor_thrust = vehicle.thrust_coefficient_n_s2 * sum(n * n for n in speeds)
                ge = fixed_point_step(ge, target, rotor_thrust)
                term = output.position_term_m_s2 if output is not None else None
                output = control(
                    state, cmd.setpoint, ge, vehicle, tuning.controller, integral, term, t - last_t
                )
                speeds = output.rotor_speeds_rad_s
                last_setpoint_z = cmd.setpoint.position_m[2]
                timings.append(time.perf_counter() - t0)
                step_timings.append(timings[-1] + nav_s)
            else:
                speeds, ge, output = (0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), None
                integral = (0.0, 0.0, 0.0)  # rotors off: the next flight starts afresh
            link.send(t_us, tuple(n / n_max for n in speeds), channels, cmd.armed)
            # off the control path from here: the simulator steps meanwhile
            if output is not None:
                # the integral for the next step. Anti-windup: not on the ground (but while
                # taking off: a vehicle heavier than its file must wind the integral up to
                # leave it), in contact or saturated. While landing it runs: a vehicle held
                # up by a force its model lacks must wind it down to come down (PX4's
                # integrators run until ground contact)
                frozen = (
                    cmd_state.phase not in RECORDED_PHASES
                    or (
                        cmd_state.phase != Phase.TAKING_OFF
                        and height < resting_height + INTEGRATE_ABOVE_M
                    )
                    or contact
                    or output.saturated
                )
                integral = integrate(
                    integral,
                    output.pd_acceleration_m_s2,
                    t - last_t,
                    tuning.controller,
                    frozen,
                )
            last_t = t
            inp = StepInput(
                t, time.monotonic(), state, height, resting_height, nav.position_lost(t)
            )
            # the rest of the tick (its other sensors, then its truth) for the fusions
            link.receive_truth(step)
            t_nav = time.perf_counter()
            nav.correct(step)
            correction_timings.append(time.perf_counter() - t_nav)
            truth = step.latest.get("DEBUG_VECT")
            if cmd.setpoint is not None and airborne and truth is not None:
                ge_pairs.append((height, target[2], truth["z"]))
            sample_hz = config.record_hz or online.sample_hz
            if (
                sample_hz > 0.0
                and t >= next_sample_s
                and airborne
                and cmd_state.phase in RECORDED_PHASES
            ):
                row = learning_sample(
                    t, step, state, height, applied, vehicle, nav.accel_bias_m_s2()
                )
                online.submit(row, vertical_tracking_error(state, cmd.setpoint))
                if config.record_hz > 0.0:
                    samples.append(row)
                period = 1.0 / sample_hz  # on a 100 Hz schedule, 250 Hz steps
                next_sample_s = next_sample_s + period if t - next_sample_s < period else t + period
                if config.on_sample is not None:
                    config.on_sample(len(samples))
                if (
                    config.record_hz > 0.0
                    and config.stop_after_samples is not None
                    and len(samples) >= config.stop_after_samples
                ):
                    ended = "enough samples"
                    break
            actual = true_state(step, config.origin) or state
            true_height = true_height_m(step, actual, nav.terrain_m)
            # the flight log's rows: in the air by the truth, as the recording's reader judges
            truly_airborne = true_height > resting_height + AIRBORNE_MARGIN_M
            if config.on_step is not None and truly_airborne and cmd_state.phase in RECORDED_PHASES:
                config.on_step(t, step, actual, applied)
            station.after_step(cmd_state, inp, cmd.reached, cmd.events)
            if cmd_state.plan is not drawn_plan:
                drawn_plan = cmd_state.plan
                recorder.mission(cmd_state.plan, state.position_m, cmd_state.home_m, t)
            nav_error = estimation_error(state, actual)
            if airborne and cmd_state.phase in RECORDED_PHASES:
                nav_errors.append(nav_error)
            recorder.estimator(t, nav_error, nav.quality.this_step)
            recorder.step(
                t,
                step,
                actual,
                true_height,
                cmd_state.phase,
                cmd.armed,
                cmd.setpoint,
                ge,
                speeds,
                output,
                flight_mode=cmd_state.mode.value,
            )
            for text in nav.events:  # after the step: the recording opens with the mode
                on_event(t, text)
            nav.events.clear()
            zd = cmd.setpoint.position_m[2] if cmd.setpoint is not None else math.nan
            p, v = actual.position_m, actual.velocity_m_s
            rows.append(
                (
                    t,
                    p[0],
                    p[1],
                    p[2],
                    v[0],
                    v[1],
                    v[2],
                    zd,
                    true_height,
                    MODES.index(cmd_state.phase),
                )
            )
            # what the ground stations asked since, and the failsafes: for the next step (a
            # real autopilot's commander runs beside its control loop, not in it)
            cmd_state = station.before_step(cmd_state, inp)
            if (
                config.exit_after_landing
                and cmd_state.phase == Phase.LANDED
                and t - (cmd_state.touchdown_s or t) >= config.settle_after_landing_s
            ):
                break
            if t >= config.max_flight_s:
                ended = "mission time limit"
                break
            if config.should_stop():
                ended = "stopped"
                break
    except LinkLost as lost:
        ended = str(lost)
    finally:
        # the loop's time: stopping the learner and closing links and files is not flying
        wall = time.perf_counter() - wall0
        link.close()
        online_summary = online.close()
        station.save_signing(time.monotonic())
        gcs.close()
        if sys.exc_info()[0] is not None:  # an exception on its way out ended the flight
            recorder.close("interrupted")
    summary: dict[str, Any] = {"ended": ended, "landed": ended == "landed"}
    try:
        log = np.asarray(rows, dtype=float).reshape(-1, len(COLUMNS))
        if len(log):
            summary.update(flight_metrics(log, MODES, landing_target_xy(cmd_state), resting_height))
            sim_s = float(log[-1, 0] - log[0, 0])
            summary.update(
                sim_s=sim_s,
                wall_s=wall,
                rtf=sim_s / wall if wall > 0 else 0.0,
                steps=len(log),
                trajectory_sha256=trajectory_sha256(log),
            )
        summary.update(estimator_metrics(np.asarray(nav_errors).reshape(-1, 7), nav))
        summary.update(ge_error_metrics(np.asarray(ge_pairs, dtype=float).reshape(-1, 3)))
        if timings:
            us = np.asarray(timings) * 1e6
            summary.update(
                controller_us_p50=float(np.percentile(us, 50)),
                controller_us_p99=float(np.percentile(us, 99)),
            )
            us = np.asarray(step_timings) * 1e6
            summary.update(
                estimator_controller_us_p50=float(np.percentile(us, 50)),
                estimator_controller_us_p99=float(np.percentile(us, 99)),
            )
        if correction_timings:
            us = np.asarray(correction_timings) * 1e6
            summary.update(
                estimator_correction_us_p50=float(np.percentile(us, 50)),
                estimator_correction_us_p99=float(np.percentile(us, 99)),
            )
        summary.update(
            model=tuning.model.name,
            malformed=link.malformed,
            unknown=link.unknown,
            gcs=gcs.counters.as_dict(),
            mission_items=len(station.items),
            touchdown_declared_s=cmd_state.touchdown_s,
            failsafes=failsafes,
            **online_summary,
        )
    finally:
        recorder.close(ended, summary)  # the summary in the file too (a no-op if closed)
    summary.update(recorder.stats())
    data = np.asarray(samples, dtype=float) if samples else None
    return Flight(log=log, summary=summary, ended=ended, samples=data)
