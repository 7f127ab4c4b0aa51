"""What the HIL messages say about a known state, decoded by pymavlink: units, frames, errors."""

from __future__ import annotations

import dataclasses
import math

import pytest

from simbridge.actuator_controls import ARMED_MODE, LOCKSTEP_FLAG, decode_actuators
from simbridge.effects.sensor_errors import SensorBiasParams, SensorLatencyParams
from simbridge.hil import HilEncoder, mavlink
from simbridge.physics import with_effects
from simbridge.sim_state import VehicleState
from simbridge.vehicle import load_vehicle
from simbridge.world import SensorRates, load_world, with_ideal_sensors

VEHICLE = load_vehicle()


def state(x=0.0, y=0.0, z=1.0, *, t=0.0, v=(0.0, 0.0, 0.0), range_m=1.0, rotors=(0.0,) * 4):
    return VehicleState(
        time_s=t,
        position_m=(x, y, z),
        quaternion=(1.0, 0.0, 0.0, 0.0),
        velocity_m_s=v,
        angular_velocity_body_rad_s=(0.01, 0.02, 0.03),
        acceleration_m_s2=(0.0, 0.0, 0.0),
        rotor_speeds_rad_s=rotors,
        range_m=range_m,
    )


def decode(data: bytes) -> dict[str, list]:
    out: dict[str, list] = {}
    for msg in mavlink.MAVLink(None).parse_buffer(data) or ():
        out.setdefault(msg.get_type(), []).append(msg)
    return out


def every_step(world):
    """Every message every step, from ideal sensors (units and frames are checked here;
    the errors are in test_sensor_noise.py)."""
    rates = SensorRates(gps_hz=250, odometry_hz=250, distance_sensor_hz=250, esc_hz=250)
    return dataclasses.replace(with_ideal_sensors(world), sensors=rates)


def test_actuator_values_out_of_range_or_nan_are_clamped_and_counted():
    """The simulator flies what it can (NaN: off; beyond [0, 1]: the nearer end) and
    counts each such value, on the channels the vehicle's rotors are wired to."""
    n_max = VEHICLE.max_rotor_speed_rad_s
    controls = [9.0] * 16  # channels no rotor is on are not read
    for ch, value in zip(VEHICLE.actuator_channels, (0.5, math.nan, -0.2, 1.7), strict=True):
        controls[ch] = value
    command = decode_actuators(123, controls, ARMED_MODE, LOCKSTEP_FLAG, VEHICLE)
    assert command.rotor_speeds_rad_s == (0.5 * n_max, 0.0, 0.0, n_max)
    assert command.clamped == 3
    assert (command.time_us, command.armed, command.lockstep) == (123, True, True)
    ok = decode_actuators(7, [0.25] * 16, 0, 0, VEHICLE)
    assert (ok.clamped, ok.armed, ok.lockstep) == (0, False, False)
    assert ok.rotor_speeds_rad_s == (0.25 * n_max,) * 4


def test_sequence_numbers_count_up_in_the_order_frames_go_on_the_wire():
    """HIL_SENSOR is computed after the other sensors (the errors are drawn in that order)
    but goes first: its sequence number is taken first, so a receiver counting sequence
    gaps (MAVProxy's link statistics) sees none."""
    world = every_step(load_world())
    encoder = HilEncoder(world, VEHICLE)
    seqs = []
    for k in range(3):
        data = encoder.encode(state(1.0, 2.0, 1.5), 4000 * (k + 1))
        seqs += [m.get_seq() for m in mavlink.MAVLink(None).parse_buffer(data) or ()]
    assert len(seqs) > 10
    assert seqs == [(seqs[0] + i) % 256 for i in range(len(seqs))]


def test_a_level_hovering_state_in_mavlink_units_and_frames():
    world = every_step(load_world())
    msgs = decode(
        HilEncoder(world, VEHICLE).encode(
            state(
                1.0, 2.0, 1.5, v=(0.3, -0.2, 0.1), range_m=0.0345, rotors=(70.0, 71.0, 72.0, 73.0)
            ),
            8000,
        )
    )
    # the tick (HIL_SENSOR) first, the step's other sensors behind it, then its truth (here
    # the state alone: no effect forces given)
    order = list(msgs)
    assert order[0] == "HIL_SENSOR" and order[-1] == "HIL_STATE_QUATERNION"
    assert {"ODOMETRY", "DISTANCE_SENSOR", "HIL_OPTICAL_FLOW", "HIL_GPS"} <= set(msgs)
    sensor = msgs["HIL_SENSOR"][0]
    assert (sensor.xacc, sensor.yacc, sensor.zacc) == pytest.approx((0.0, 0.0, -9.81))
    assert (sensor.xgyro, sensor.ygyro, sensor.zgyro) == pytest.approx((0.01, -0.02, -0.03))
    assert (
        sensor.time_usec == 8000 and sensor.fields_updated == 0x1BFF
    )  # no airspeed: diff_pressure unset
    assert sensor.abs_pressure == pytest.approx(
        1013.25 * (1 - 2.25577e-5 * 29.5) ** 5.25588, rel=1e-6
    )
    hsq = msgs["HIL_STATE_QUATERNION"][0]
    assert (hsq.vx, hsq.vy, hsq.vz) == (-20, 30, -10)  # NED cm/s
    assert hsq.alt == 29500
    odo = msgs["ODOMETRY"][0]
    assert (odo.x, odo.y, odo.z) == pytest.approx((2.0, 1.0, -1.5))  # NED metres
    assert (
        odo.frame_id == mavlink.MAV_FRAME_LOCAL_NED
        and odo.child_frame_id == mavlink.MAV_FRAME_BODY_FRD
    )
    assert msgs["DISTANCE_SENSOR"][0].current_distance == 3  # MAVLink's whole centimetres
    assert msgs["DISTANCE_SENSOR"][0].orientation == mavlink.MAV_SENSOR_ROTATION_PITCH_270
    assert list(msgs["ESC_TELEMETRY_1_TO_4"][0].rpm) == [
        round(n * 60 / (2 * math.pi)) for n in (70, 71, 72, 73)
    ]
    gps = msgs["HIL_GPS"][0]
    assert gps.fix_type == 3 and (gps.vn, gps.ve, gps.vd) == (-20, 30, -10)


def test_nothing_in_range_reads_max_plus_one():
    msgs = decode(HilEncoder(every_step(load_world()), VEHICLE).encode(state(range_m=math.inf), 0))
    reading = msgs["DISTANCE_SENSOR"][0]
    assert reading.current_distance == reading.max_distance + 1 == 401


def test_sensor_bias_offsets_accelerometer_gyro_and_position():
    bias = SensorBiasParams(
        accel_bias_m_s2=(0.1, 0.2, 0.3),
        gyro_bias_rad_s=(0.01, 0.0, -0.01),
        position_bias_m=(0.0, 0.0, 0.05),
    )
    world = every_step(with_effects(load_world(), sensor_bias=bias))
    msgs = decode(HilEncoder(world, VEHICLE).encode(state(z=1.0), 0))
    sensor = msgs["HIL_SENSOR"][0]
    assert (sensor.xacc, sensor.yacc, sensor.zacc) == pytest.approx((0.1, -0.2, -(9.81 + 0.3)))
    assert (sensor.xgyro, sensor.ygyro, sensor.zgyro) == pytest.approx((0.02, -0.02, -0.02))
    assert msgs["HIL_STATE_QUATERNION"][0].alt == 29050
    assert msgs["ODOMETRY"][0].z == pytest.approx(-1.05)


def test_sensor_latency_reports_older_states():
    latency = SensorLatencyParams(imu_delay_s=0.004, state_delay_s=0.008)
    encoder = HilEncoder(every_step(with_effects(load_world(), sensor_latency=latency)), VEHICLE)
    reported = []
    for k in range(5):
        s = dataclasses.replace(state(z=1.0 + k), angular_velocity_body_rad_s=(0.1 * k, 0.0, 0.0))
        msgs = decode(encoder.encode(s, 4000 * k))
        reported.append(
            (
                msgs["HIL_STATE_QUATERNION"][0].alt,
                msgs["HIL_SENSOR"][0].xgyro,
                msgs["HIL_SENSOR"][0].time_usec,
            )
        )
    assert [alt for alt, _, _ in reported] == [29000, 29000, 29000, 30000, 31000]  # 2 steps late
    assert [g for _, g, _ in reported] == pytest.approx([0.0, 0.0, 0.1, 0.2, 0.3])  # 1 step late
    assert [t for _, _, t in reported] == [0, 4000, 8000, 12000, 16000]  # stamps stay current


def test_an_imu_delay_between_control_periods_is_interpolated_not_rounded():
    """10 ms at 250 Hz is two and a half periods: the gyro reads the rate of 10 ms ago (a
    ramp, so exactly its value there), where rounding to periods made it 8 ms (a blind case's
    latency then read 7.7 ms, 23% short of the world file's)."""
    latency = SensorLatencyParams(imu_delay_s=0.010)
    encoder = HilEncoder(every_step(with_effects(load_world(), sensor_latency=latency)), VEHICLE)
    rates = []
    for k in range(8):
        s = dataclasses.replace(state(), angular_velocity_body_rad_s=(0.1 * k, 0.0, 0.0))
        rates.append(decode(encoder.encode(s, 4000 * k))["HIL_SENSOR"][0].xgyro)
    # the rate at t is 0.1 per 4 ms; at t - 10 ms it is 0.1 (k - 2.5), once the history holds it
    assert rates[3:] == pytest.approx([0.1 * (k - 2.5) for k in range(3, 8)])


@pytest.mark.parametrize("rate", [0.04, 0.2, 0.4, 0.5, 1.0, 2.0, 1 / 3, 0.37, 0.123456, 0.999, 0.0])
def test_a_sensor_samples_on_the_steps_its_own_clock_begins_a_period(rate):
    """The encoder finds each sensor's next sampling step once the last has passed; the steps
    are those at which floor(n * rate) grows, as when it asked at every step (rates that are
    no whole fraction of the control rate alternate their intervals)."""
    from simbridge.hil import _next_due

    def asked_every_step(n):  # the rule as the encoder asked it at every step before
        if rate <= 0.0:
            return False
        return n == 0 or math.floor(n * rate + 1e-9) > math.floor((n - 1) * rate + 1e-9)

    expected = [n for n in range(3100) if asked_every_step(n)]  # past the steps asked
    if rate > 0.0:
        counts = [math.floor(n * rate + 1e-9) for n in expected]
        assert counts == sorted(set(counts))  # one sample per period begun
    due, found = -1.0, []
    for n in range(3000):
        if n > due:
            due = _next_due(rate, n)
        if n == due:
            found.append(n)
    assert found == [n for n in expected if n < 3000]
    # asked at scattered steps, it answers as at every step
    for n in range(0, 3000, 7):
        first = next((m for m in expected if m >= n), math.inf)
        assert _next_due(rate, n) == first
