"""The PX4 simulator protocol's messages: the vehicle state in, MAVLink bytes out.

Simulator -> autopilot, per control step: HIL_SENSOR (IMU, magnetometer, barometer), the tick,
first and alone in its send; then the declared sensors (`simbridge.sensors`: motion capture,
the flow deck's range and flow, ESC telemetry, GPS) at their world-file rates, and
HIL_STATE_QUATERNION. Autopilot -> simulator, HIL_ACTUATOR_CONTROLS, is decoded in
`actuator_controls`. With the true ground effect (DEBUG_VECT GE_TRUE) go the true position in
floats (LOCAL_POSITION_NED) and the true height above the surface below (ALTITUDE's
bottom_clearance), all for evaluation only. Units and frames (NED, FRD, degE7, mm, cm/s, mG,
gauss, hPa) exist only here, in the sensors' modules and in `frames`.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from typing import Any

from simbridge.effects.sensor_errors import add, delay_periods, delay_steps
from simbridge.frames import (
    Vec3,
    enu_to_ned,
    flu_to_frd,
    local_to_geodetic,
    ned_to_enu,
    quat_enu_flu_to_ned_frd,
    rotate_transposed,
)
from simbridge.sensor_noise import SensorErrors
from simbridge.sensors import SENSORS, Frame, int16, mavlink
from simbridge.sim_state import VehicleState
from simbridge.vehicle import GRAVITY_M_S2, Vehicle
from simbridge.wire import PacketSequence, WirePacker
from simbridge.world import World

SIM_SYSTEM_ID = 1
SIM_COMPONENT_ID = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
# HIL_SENSOR.fields_updated: accelerometer, gyro, magnetometer, barometer (MAVLINK.md).
FIELDS_UPDATED = 0x7 | 0x38 | 0x1C0 | 0x1A00
TRUTH_NAME = b"GE_TRUE"  # DEBUG_VECT carrying the true ground-effect force


def _imu_sample(s: VehicleState, m: Sequence[float]) -> tuple[Vec3, Vec3]:
    """The specific force (body FLU, m/s^2) and body rates an ideal IMU reads in state `s`
    (`m` its rotation matrix, row-major)."""
    a = s.acceleration_m_s2
    return rotate_transposed(m, (a[0], a[1], a[2] + GRAVITY_M_S2)), s.angular_velocity_body_rad_s


def _blend(new: Vec3, old: Vec3, fraction: float) -> Vec3:
    """`fraction` of the way from `new` to `old`."""
    k = 1.0 - fraction
    return (k * new[0] + fraction * old[0], k * new[1] + fraction * old[1],
            k * new[2] + fraction * old[2])  # fmt: skip


def pressure_hpa(altitude_amsl_m: float) -> float:
    """International standard atmosphere, troposphere."""
    return 1013.25 * (1.0 - 2.25577e-5 * altitude_amsl_m) ** 5.25588


def _next_due(rate: float, step: int) -> float:
    """The first step from `step` on at which a clock of `rate` periods a step begins one
    (inf: never): step 0, then each step at which floor(n * rate) grows (the tolerance keeps
    whole-step periods, 50 Hz at 250 Hz every 5th, exact in floats). That count only grows
    with the step: searched from the guess the rate gives, not asked at every step."""
    if rate <= 0.0:
        return math.inf
    if step == 0:
        return 0
    begun = math.floor((step - 1) * rate + 1e-9)  # periods begun before `step`
    guess = max(step, math.ceil((begun + 1) / rate))
    while guess > step and math.floor((guess - 1) * rate + 1e-9) > begun:
        guess -= 1
    while math.floor(guess * rate + 1e-9) <= begun:
        guess += 1
    return guess


class HilEncoder:
    """Encodes each control step's sensors; keeps the sequence counter and the delay lines.
    The declared sensors (`simbridge.sensors`) sample through it (`SensorContext`)."""

    def __init__(self, world: World, vehicle: Vehicle) -> None:
        self.world, self.vehicle = world, vehicle
        self._seq = PacketSequence()
        self._pack_hil_state = self.packer(mavlink.MAVLink_hil_state_quaternion_message)
        self._pack_hil_sensor = self.packer(mavlink.MAVLink_hil_sensor_message)
        self._pack_debug = self.packer(mavlink.MAVLink_debug_vect_message)
        self._pack_local = self.packer(mavlink.MAVLink_local_position_ned_message)
        self._pack_altitude = self.packer(mavlink.MAVLink_altitude_message)
        fx = world.effects
        period = world.control_period_s
        # the IMU's delay in whole periods and the fraction of one beyond: its sample is then
        # interpolated between the two neighbouring ones (a 10 ms delay at 250 Hz is 10 ms,
        # not the 8 ms that rounding to periods made of it)
        self._imu_delay, self._imu_fraction = (
            delay_periods(fx.sensor_latency.imu_delay_s, period) if fx.sensor_latency else (0, 0.0)
        )
        self.state_delay = (
            delay_steps(fx.sensor_latency.state_delay_s, period) if fx.sensor_latency else 0
        )
        self.errors = SensorErrors(world.sensor_noise, period)
        bias = fx.sensor_bias
        zero = (0.0, 0.0, 0.0)
        self._accel_bias = bias.accel_bias_m_s2 if bias else zero
        self._gyro_bias = bias.gyro_bias_rad_s if bias else zero
        self._position_bias = bias.position_bias_m if bias else zero
        self._mag_enu = ned_to_enu(world.origin.magnetic_field_ned_gauss)
        self._steps = 0
        self.period_us = world.control_period_us
        # each declared sensor's sampler, in the order their errors are drawn
        self._samplers = [sensor.sampler(self) for sensor in SENSORS.values()]
        self._history: deque[VehicleState] = deque(
            maxlen=max(
                self._imu_delay + (self._imu_fraction > 0.0),
                self.state_delay,
                *(sampler.history_steps for sampler in self._samplers),
            )
            + 1
        )
        rates = world.sensors
        # samples a step of each sensor with a clock of its own: the samplers', then the truth
        self._per_step = tuple(
            world.samples_per_step(hz)
            for hz in [rates.rate_hz(name) for name in SENSORS] + [rates.truth_hz]
        )
        # each one's next sampling step (-1: found at the first step), none for a sensor that
        # samples at every step (at least once a step)
        self._every_step = tuple(rate >= 1.0 for rate in self._per_step)
        self._due_steps = [math.inf if every else -1.0 for every in self._every_step]
        self._soonest_due = -1.0
        self._due_now = [False] * len(self._per_step)  # `_schedule` at the step being encoded
        self._rest: list[Frame] = []  # the tick's messages after HIL_SENSOR, packed later

    # -- what a sensor's sampler reads (`simbridge.sensors.SensorContext`) -------------------

    def packer(self, message_class: Any) -> WirePacker:
        return WirePacker(message_class, SIM_SYSTEM_ID, SIM_COMPONENT_ID, self._seq)

    @property
    def steps(self) -> int:
        return self._steps

    def delayed(self, steps: int) -> VehicleState:
        """The state `steps` control steps ago, or the oldest the delay line holds."""
        hist = self._history
        return hist[-1 - steps] if len(hist) > steps else hist[0]

    def position(self, s: VehicleState) -> tuple[float, float, float]:
        p = s.position_m
        b = self._position_bias
        return (p[0] + b[0], p[1] + b[1], p[2] + b[2])

    def geodetic(self, position_m: tuple[float, float, float]) -> tuple[int, int, int]:
        """degE7, degE7, mm above mean sea level of a local position."""
        x, y, z = position_m
        o = self.world.origin
        lat, lon = local_to_geodetic(o.lat_deg, o.lon_deg, x, y)
        return round(lat * 1e7), round(lon * 1e7), round(self._amsl_m(z) * 1000.0)

    # -- one control step -------------------------------------------------------------------

    def _schedule(self) -> list[bool]:
        """Which sensors sample at this step (the samplers', then the truth): those whose own
        clock began a period at it, so that each samples at its rate on average, not at a
        rate rounded to a whole number of steps. A sensor's next such step is found when its
        last one has passed (`_next_due`); asked once a step."""
        n = self._steps
        due = self._due_steps
        if n > self._soonest_due:
            for i, rate in enumerate(self._per_step):
                if n > due[i]:
                    due[i] = _next_due(rate, n)
            self._soonest_due = min(due)
        return [every or n == d for every, d in zip(self._every_step, due, strict=True)]

    def encode(
        self, state: VehicleState, time_us: int, ground_effect_n: Vec3 | None = None
    ) -> bytes:
        """All messages of one control step at `time_us`, in the order the simulator sends
        them (`tick`, then `truth`)."""
        return self.tick(state, time_us) + self.truth(time_us, ground_effect_n)

    def tick(self, state: VehicleState, time_us: int) -> bytes:
        """HIL_SENSOR of one control step: the tick a lockstep autopilot answers (its control
        path needs the IMU alone). The step's other sensors (drawn before it) go
        with the truth in a second send (`truth`), packed while the autopilot computes its
        reply, off the lockstep's path; it reads them after its reply, for its fusions."""
        self._advance(state)
        return self._tick_bytes(time_us)

    def truth(self, time_us: int, ground_effect_n: Vec3 | None = None) -> bytes:
        """The rest of the step `tick` encoded: its other sensors, then its truth,
        HIL_STATE_QUATERNION last (the end of it).

        `ground_effect_n`, the simulator's true world-frame ground-effect force (N), travels
        as DEBUG_VECT "GE_TRUE" with the true position and clearance: for evaluation and
        recordings, never control; without it the truth is the state alone.
        """
        return self._truth_bytes(time_us, ground_effect_n)

    def _advance(self, state: VehicleState) -> None:
        self._history.append(state)
        self._imu_state = self.delayed(self._imu_delay)
        self._nav_state = self.delayed(self.state_delay)
        self._due_now = self._schedule()
        self._truth_due = self._due_now[-1]

    def _truth_bytes(self, time_us: int, ge: Vec3 | None) -> bytes:
        nav = self._nav_state
        parts = [packer.pack(*fields) for packer, fields in self._rest]  # the tick's others
        self._rest.clear()
        if ge is not None and self._truth_due:
            parts.append(self._pack_debug.pack(TRUTH_NAME, time_us, ge[0], ge[1], ge[2]))
            # the true position and velocity in floats (HIL_STATE_QUATERNION's degE7 resolve
            # 11 mm): for evaluating the autopilot's estimator, never for control
            x, y, z = enu_to_ned(nav.position_m)
            vx, vy, vz = enu_to_ned(nav.velocity_m_s)
            parts.append(self._pack_local.pack(time_us // 1000, x, y, z, vx, vy, vz))
            # ... and the true height of the centre of mass above the surface below it
            # (bottom_clearance), by which landings and holds are judged
            up = nav.rotation[8]
            clearance = nav.range_m * up if math.isfinite(nav.range_m) else nav.position_m[2]
            parts.append(self._pack_altitude.pack(
                time_us, nav.position_m[2], nav.position_m[2] + self.world.origin.alt_m,
                nav.position_m[2], nav.position_m[2], -1000.0, clearance,
            ))  # fmt: skip
        parts.append(self._hil_state(nav, time_us))
        return b"".join(parts)

    def _tick_bytes(self, time_us: int) -> bytes:
        rest = self._rest
        for sampler, due in zip(self._samplers, self._due_now, strict=False):
            if due:
                rest.extend(sampler(time_us))
        # computed last (the sensor errors are drawn in this order: a seed gives one flight),
        # packed and sent first; the others are packed with the truth
        self._steps += 1
        return self._hil_sensor(self._imu_state, time_us)

    # -- one message each ---------------------------------------------------------------

    def _amsl_m(self, z_m: float) -> float:
        return self.world.origin.alt_m + z_m

    def _hil_sensor(self, s: VehicleState, time_us: int) -> bytes:
        m = s.rotation
        specific_force, rates = _imu_sample(s, m)
        f = self._imu_fraction
        if f > 0.0:  # a fraction of a period further back: towards the older sample
            hist = self._history
            old = hist[max(0, len(hist) - 2 - self._imu_delay)]
            old_force, old_rates = _imu_sample(old, old.rotation)
            specific_force = _blend(specific_force, old_force, f)
            rates = _blend(rates, old_rates, f)
        errors = self.errors
        specific_force, rates = errors.imu(
            add(specific_force, self._accel_bias), add(rates, self._gyro_bias)
        )
        acc = flu_to_frd(specific_force)
        gyro = flu_to_frd(rates)
        mag = flu_to_frd(
            errors.vector(rotate_transposed(m, self._mag_enu), errors.noise.mag_noise_gauss)
        )
        alt = self._amsl_m(s.position_m[2] + self._position_bias[2])
        pressure = errors.scalar(pressure_hpa(alt), errors.noise.baro_noise_hpa)
        return self._pack_hil_sensor.pack(
            time_us,
            acc[0],
            acc[1],
            acc[2],
            gyro[0],
            gyro[1],
            gyro[2],
            mag[0],
            mag[1],
            mag[2],
            pressure,
            0.0,
            alt,
            15.0 - 0.0065 * alt,
            FIELDS_UPDATED,
            0,
        )

    def _hil_state(self, s: VehicleState, time_us: int) -> bytes:
        lat, lon, alt = self.geodetic(self.position(s))
        v = enu_to_ned(s.velocity_m_s)
        rates = flu_to_frd(s.angular_velocity_body_rad_s)
        # xacc..zacc: the true kinematic acceleration in body FRD (as Gazebo reports it), mG.
        acc = flu_to_frd(rotate_transposed(s.rotation, s.acceleration_m_s2))
        to_mg = 1000.0 / GRAVITY_M_S2
        speed_cm_s = min(65535, round(100.0 * math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)))
        return self._pack_hil_state.pack(
            time_us,
            list(quat_enu_flu_to_ned_frd(s.quaternion)),
            rates[0],
            rates[1],
            rates[2],
            lat,
            lon,
            alt,
            int16(100 * v[0]),
            int16(100 * v[1]),
            int16(100 * v[2]),
            speed_cm_s,
            speed_cm_s,
            int16(acc[0] * to_mg),
            int16(acc[1] * to_mg),
            int16(acc[2] * to_mg),
        )
