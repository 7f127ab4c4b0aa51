"""The PX4 simulator protocol's messages: the vehicle state in, MAVLink bytes out.

Simulator -> autopilot, per control step: HIL_STATE_QUATERNION and HIL_SENSOR; ODOMETRY (a
motion-capture pose, float precision), DISTANCE_SENSOR (downward range, whole cm) with
HIL_OPTICAL_FLOW (a flow deck: flow and the same range in float metres) and
ESC_TELEMETRY_1_TO_4 (actual rotor speeds, so motor lag is observable) at their world-file
rates; HIL_GPS at 10 Hz; HIL_SENSOR, the tick, first and alone in its send. Autopilot ->
simulator, HIL_ACTUATOR_CONTROLS, is decoded in `actuator_controls`. With the true ground
effect (DEBUG_VECT GE_TRUE) go the true position in floats (LOCAL_POSITION_NED) and the true
height above the surface below (ALTITUDE's bottom_clearance), all for evaluation only.
Units and frames (NED, FRD, degE7, mm, cm/s, mG, gauss, hPa) exist only here and in
`frames`.
"""

from __future__ import annotations

import math
import os
from collections import deque
from collections.abc import Sequence

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink

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
from simbridge.sim_state import VehicleState
from simbridge.vehicle import GRAVITY_M_S2, Vehicle
from simbridge.wire import PacketSequence, WirePacker
from simbridge.world import World

SIM_SYSTEM_ID = 1
SIM_COMPONENT_ID = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
# HIL_SENSOR.fields_updated: accelerometer, gyro, magnetometer, barometer (MAVLINK.md).
FIELDS_UPDATED = 0x7 | 0x38 | 0x1C0 | 0x1A00
Frame = tuple[WirePacker, tuple]  # a message's packer and its fields, packed later
UNKNOWN_COVARIANCE = [math.nan] + [0.0] * 20
RAD_S_TO_RPM = 60.0 / (2.0 * math.pi)
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


def _int16(v: float) -> int:
    r = round(v)  # a comparison instead of min and max: six a step
    return r if -32767 <= r <= 32767 else (32767 if r > 0 else -32767)


class HilEncoder:
    """Encodes each control step's sensors; keeps the sequence counter and the delay lines."""

    def __init__(self, world: World, vehicle: Vehicle) -> None:
        self.world, self.vehicle = world, vehicle
        seq = PacketSequence()

        def packer(cls: object) -> WirePacker:
            return WirePacker(cls, SIM_SYSTEM_ID, SIM_COMPONENT_ID, seq)

        self._pack_hil_state = packer(mavlink.MAVLink_hil_state_quaternion_message)
        self._pack_hil_sensor = packer(mavlink.MAVLink_hil_sensor_message)
        self._pack_odometry = packer(mavlink.MAVLink_odometry_message)
        self._pack_distance = packer(mavlink.MAVLink_distance_sensor_message)
        self._pack_esc = packer(mavlink.MAVLink_esc_telemetry_1_to_4_message)
        self._pack_gps = packer(mavlink.MAVLink_hil_gps_message)
        self._pack_flow = packer(mavlink.MAVLink_hil_optical_flow_message)
        self._pack_debug = packer(mavlink.MAVLink_debug_vect_message)
        self._pack_local = packer(mavlink.MAVLink_local_position_ned_message)
        self._pack_altitude = packer(mavlink.MAVLink_altitude_message)
        fx = world.effects
        period = world.control_period_s
        # the IMU's delay in whole periods and the fraction of one beyond: its sample is then
        # interpolated between the two neighbouring ones (a 10 ms delay at 250 Hz is 10 ms,
        # not the 8 ms that rounding to periods made of it)
        self._imu_delay, self._imu_fraction = (
            delay_periods(fx.sensor_latency.imu_delay_s, period) if fx.sensor_latency else (0, 0.0)
        )
        self._state_delay = (
            delay_steps(fx.sensor_latency.state_delay_s, period) if fx.sensor_latency else 0
        )
        noise = world.sensor_noise
        self._errors = SensorErrors(noise, period)
        # the motion-capture pose comes later than the state (the capture system's latency)
        self._mocap_delay = self._state_delay + delay_steps(noise.mocap_latency_s, period)
        self._history: deque[VehicleState] = deque(
            maxlen=max(self._imu_delay + (self._imu_fraction > 0.0), self._mocap_delay) + 1
        )
        bias = fx.sensor_bias
        zero = (0.0, 0.0, 0.0)
        self._accel_bias = bias.accel_bias_m_s2 if bias else zero
        self._gyro_bias = bias.gyro_bias_rad_s if bias else zero
        self._position_bias = bias.position_bias_m if bias else zero
        self._mag_enu = ned_to_enu(world.origin.magnetic_field_ned_gauss)
        rates = world.sensors
        # samples a step of each sensor with a clock of its own, in the order of `_schedule`:
        # odometry, distance (range and flow), esc, gps, truth
        self._per_step = tuple(
            world.samples_per_step(hz)
            for hz in (
                rates.odometry_hz, rates.distance_sensor_hz, rates.esc_hz, rates.gps_hz,
                rates.truth_hz,
            )
        )  # fmt: skip
        # each one's next sampling step (-1: found at the first step), none for a sensor that
        # samples at every step (at least once a step)
        self._every_step = tuple(rate >= 1.0 for rate in self._per_step)
        self._due_steps = [math.inf if every else -1.0 for every in self._every_step]
        self._soonest_due = -1.0
        self._due_now = (False,) * 5  # `_schedule` at the step being encoded
        # the step of the last range-and-flow sample (the first integrates one nominal period)
        per_step = self._per_step[1]
        self._distance_step = -max(1, round(1.0 / per_step)) if per_step > 0.0 else 0
        self._steps = 0
        self._period_us = world.control_period_us
        self._rest: list[Frame] = []  # the tick's messages after HIL_SENSOR, packed later

    def _schedule(self) -> tuple[bool, bool, bool, bool, bool]:
        """Which sensors sample at this step (odometry, distance, esc, gps, truth): those
        whose own clock began a period at it, so that each samples at its rate on average,
        not at a rate rounded to a whole number of steps. A sensor's next such step is found
        when its last one has passed (`_next_due`); asked once a step."""
        n = self._steps
        due = self._due_steps
        if n > self._soonest_due:
            for i, rate in enumerate(self._per_step):
                if n > due[i]:
                    due[i] = _next_due(rate, n)
            self._soonest_due = min(due)
        every = self._every_step
        return (
            every[0] or n == due[0],
            every[1] or n == due[1],
            every[2] or n == due[2],
            every[3] or n == due[3],
            every[4] or n == due[4],
        )

    def encode(
        self, state: VehicleState, time_us: int, ground_effect_n: Vec3 | None = None
    ) -> bytes:
        """All messages of one control step at `time_us`, in the order the simulator sends
        them (`tick`, then `truth`)."""
        return self.tick(state, time_us) + self.truth(time_us, ground_effect_n)

    def tick(self, state: VehicleState, time_us: int) -> bytes:
        """HIL_SENSOR of one control step: the tick a lockstep autopilot answers (its control
        path needs the IMU alone). The step's other sensors (drawn before it, as always) go
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
        hist = self._history
        n = len(hist)  # each delay line reads its delay back, or the oldest it holds
        d = self._imu_delay
        self._imu_state = hist[-1 - d] if n > d else hist[0]
        d = self._state_delay
        self._nav_state = hist[-1 - d] if n > d else hist[0]
        d = self._mocap_delay
        self._mocap_state = hist[-1 - d] if n > d else hist[0]
        self._due_now = self._schedule()
        self._truth_due = self._due_now[4]

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
        nav = self._nav_state
        rest = self._rest
        until_s = self.world.sensors.odometry_until_s
        odometry, distance, esc, gps, _ = self._due_now
        if odometry and (until_s is None or time_us < until_s * 1e6):
            rest.append(self._odometry(self._mocap_state, time_us))
        if distance:
            range_m = self._errors.range_m(nav.range_m)
            rest.append(self._distance(range_m, time_us))
            rest.append(self._flow(nav, range_m, time_us))
        if esc:
            rest.append(self._esc(self._history[-1]))  # the rotors now: no delay line
        if gps:
            rest.append(self._gps(nav, time_us))
        # computed last, as it always was (the sensor errors are drawn in this order: a seed
        # gives the same flight), packed and sent first; the others are packed with the truth
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
        errors = self._errors
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

    def _position(self, s: VehicleState) -> tuple[float, float, float]:
        p = s.position_m
        b = self._position_bias
        return (p[0] + b[0], p[1] + b[1], p[2] + b[2])

    def _geodetic(self, position_m: tuple[float, float, float]) -> tuple[int, int, int]:
        """degE7, degE7, mm above mean sea level of a local position."""
        x, y, z = position_m
        o = self.world.origin
        lat, lon = local_to_geodetic(o.lat_deg, o.lon_deg, x, y)
        return round(lat * 1e7), round(lon * 1e7), round(self._amsl_m(z) * 1000.0)

    def _hil_state(self, s: VehicleState, time_us: int) -> bytes:
        lat, lon, alt = self._geodetic(self._position(s))
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
            _int16(100 * v[0]),
            _int16(100 * v[1]),
            _int16(100 * v[2]),
            speed_cm_s,
            speed_cm_s,
            _int16(acc[0] * to_mg),
            _int16(acc[1] * to_mg),
            _int16(acc[2] * to_mg),
        )

    def _odometry(self, s: VehicleState, time_us: int) -> Frame:
        """A motion-capture pose, stamped with its capture time (it arrives `mocap_latency_s`
        late). Velocities are NaN (not measured) unless the sensors are ideal."""
        errors = self._errors
        p = enu_to_ned(errors.vector(self._position(s), errors.noise.mocap_position_m))
        q = quat_enu_flu_to_ned_frd(errors.attitude(s.quaternion))
        if errors.ideal:
            v_body = flu_to_frd(rotate_transposed(s.rotation, s.velocity_m_s))
            rates = flu_to_frd(s.angular_velocity_body_rad_s)
        else:
            v_body = rates = (math.nan, math.nan, math.nan)
        captured_us = time_us - (self._mocap_delay - self._state_delay) * self._period_us
        return self._pack_odometry, (
            max(0, captured_us),
            mavlink.MAV_FRAME_LOCAL_NED,
            mavlink.MAV_FRAME_BODY_FRD,
            p[0],
            p[1],
            p[2],
            list(q),
            v_body[0],
            v_body[1],
            v_body[2],
            rates[0],
            rates[1],
            rates[2],
            UNKNOWN_COVARIANCE,
            UNKNOWN_COVARIANCE,
            0,
            mavlink.MAV_ESTIMATOR_TYPE_MOCAP,
            100,
        )

    def _distance(self, range_m: float, time_us: int) -> Frame:
        max_cm = round(self.vehicle.range_sensor_max_m * 100.0)
        # MAVLink: max_distance + 1 means nothing in range.
        current = max_cm + 1 if range_m == math.inf else min(max_cm, round(range_m * 100.0))
        return self._pack_distance, (
            time_us // 1000,
            1,
            max_cm,
            current,
            mavlink.MAV_DISTANCE_SENSOR_LASER,
            0,
            mavlink.MAV_SENSOR_ROTATION_PITCH_270,
            0,
            0.0,
            0.0,
            (0.0, 0.0, 0.0, 0.0),
            0,
        )

    def _flow(self, s: VehicleState, range_m: float, time_us: int) -> Frame:
        """A downward flow-and-range deck (Crazyflie flow deck): the range in float metres.

        Flow is integrated over the message interval from the current rates and velocity
        (sensor frame = body FRD): x = (p - v_y / h) dt, y = (q + v_x / h) dt.
        """
        # integrated since the last sample (at a rate that is no whole number of steps, the
        # interval alternates)
        steps = max(1, self._steps - self._distance_step)
        self._distance_step = self._steps
        dt = steps * self.world.control_period_s
        rates = flu_to_frd(s.angular_velocity_body_rad_s)
        v = flu_to_frd(rotate_transposed(s.rotation, s.velocity_m_s))
        h = s.range_m
        known = math.isfinite(h) and h > 0.0
        flow_sd = self._errors.noise.flow_noise_rad
        flow_x = self._errors.scalar((rates[0] - v[1] / h) * dt, flow_sd) if known else 0.0
        flow_y = self._errors.scalar((rates[1] + v[0] / h) * dt, flow_sd) if known else 0.0
        h = range_m
        return self._pack_flow, (
            time_us,
            0,
            round(dt * 1e6),
            flow_x,
            flow_y,
            rates[0] * dt,
            rates[1] * dt,
            rates[2] * dt,
            2000,
            255 if known else 0,
            0,
            h if known else -1.0,
        )

    def _esc(self, s: VehicleState) -> Frame:
        rpm = [min(65535, round(n * RAD_S_TO_RPM)) for n in s.rotor_speeds_rad_s]
        count = self._steps & 0xFFFF
        return self._pack_esc, ([0] * 4, [0] * 4, [0] * 4, [0] * 4, rpm, [count] * 4)

    def _gps(self, s: VehicleState, time_us: int) -> Frame:
        n, errors = self._errors.noise, self._errors
        x, y, z = self._position(s)
        lat, lon, alt = self._geodetic((
            errors.scalar(x, n.gps_horizontal_m),
            errors.scalar(y, n.gps_horizontal_m),
            errors.scalar(z, n.gps_vertical_m),
        ))  # fmt: skip
        vn, ve, vd = enu_to_ned(errors.vector(s.velocity_m_s, n.gps_velocity_m_s))
        ground = math.hypot(vn, ve)
        cog = (
            round(math.degrees(math.atan2(ve, vn)) % 360.0 * 100.0) % 36000
            if ground > 0.05
            else 65535
        )
        return self._pack_gps, (
            time_us,
            3,
            lat,
            lon,
            alt,
            100,
            100,
            min(65535, round(ground * 100.0)),
            _int16(vn * 100),
            _int16(ve * 100),
            _int16(vd * 100),
            cog,
            12,
            0,
            0,
        )
