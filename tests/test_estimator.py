"""The estimator's pure parts: the error-state Kalman filter, the land detector, the landing
floor, and the simulated sensors' errors."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from autopilot.commander.commander import CommanderParams, CommanderState, Phase, command
from autopilot.control.land_detector import LandDetector, LandDetectorParams, ground_contact
from autopilot.estimation import estimator as ekf
from autopilot.estimation.attitude import (
    attitude_from_gravity_and_field,
    rotation,
    rotation_vector_quat,
)
from autopilot.types import FlightMode
from simbridge.sensor_noise import SensorErrors, SensorNoise
from simbridge.vehicle import GRAVITY_M_S2

LEVEL = np.array([1.0, 0.0, 0.0, 0.0])
NOISE = ekf.ProcessNoise()
DT_US = 4000  # 250 Hz


def at_rest(position=(0.0, 0.0, 1.0)) -> ekf.Estimate:
    return ekf.initial(0, np.array(position), LEVEL, position_sd_m=0.01, attitude_sd_rad=0.01)


def test_prediction_integrates_a_constant_acceleration_exactly():
    est = at_rest()
    up = np.array([0.0, 0.0, GRAVITY_M_S2 + 1.0])  # specific force: 1 m/s^2 upwards
    for k in range(1, 251):
        est = ekf.predict(est, k * DT_US, up, np.zeros(3), NOISE)
    assert est.velocity_m_s[2] == pytest.approx(1.0, rel=1e-9)
    assert est.position_m[2] == pytest.approx(1.5, rel=1e-9)  # 1 + a t^2 / 2
    assert np.allclose(est.quaternion, LEVEL)


def test_a_turn_rate_turns_the_attitude():
    est = at_rest()
    for k in range(1, 251):
        est = ekf.predict(
            est, k * DT_US, np.array([0, 0, GRAVITY_M_S2]), np.array([0, 0, 0.5]), NOISE
        )
    yaw = 2.0 * math.atan2(est.quaternion[3], est.quaternion[0])
    assert yaw == pytest.approx(0.5, rel=1e-6)


def test_motion_capture_corrections_find_the_accelerometer_bias_and_hold_the_position():
    """A hovering vehicle whose accelerometer reads 0.2 m/s^2 too much upwards and 0.1 m/s^2
    sideways: with the motion-capture pose fused at 100 Hz the filter learns the vertical bias
    and its position stays within a millimetre of the truth (sideways, a bias and a tilt read
    alike: roll and pitch come from the accelerometer, as in EKF2)."""
    rng = np.random.default_rng(0)
    bias = np.array([0.1, 0.0, 0.2])
    truth = np.array([0.0, 0.0, 1.0])
    est = at_rest(truth)
    worst = 0.0
    for k in range(1, 250 * 30 + 1):
        f = np.array([0.0, 0.0, GRAVITY_M_S2]) + bias + rng.normal(0, 0.003, 3)
        est = ekf.predict(est, k * DT_US, f, rng.normal(0, 5e-4, 3), NOISE)
        if k % 10 == 0:  # mocap: 1 mm, 0.1 deg
            measured = truth + rng.normal(0, 0.001, 3)
            yaw = 2.0 * math.atan2(est.quaternion[3], est.quaternion[0])
            innovation = measured - est.position_m
            est = ekf.fuse_pose(
                est, innovation, [0, 1, 2], 0.002, rng.normal(0, 0.0017) - yaw, 0.005, 5.0
            ).estimate
        if k > 250 * 20:
            worst = max(worst, float(np.linalg.norm(est.position_m - truth)))
    assert est.accel_bias_m_s2[2] == pytest.approx(bias[2], abs=0.02), est.accel_bias_m_s2
    assert worst < 0.002
    assert np.all(np.linalg.eigvalsh(est.covariance) > 0.0)  # still a covariance


def test_an_outlier_is_rejected_by_the_innovation_gate_and_changes_nothing():
    est = at_rest()
    fused = ekf.fuse_position(
        est, np.array([0.0, 0.0, 5.0]), est.position_m, np.full(3, 0.002), 5.0
    )
    assert not fused.accepted and fused.test_ratio > 1.0
    assert fused.estimate is est
    near = ekf.fuse_position(
        est, np.array([0.0, 0.0, 1.001]), est.position_m, np.full(3, 0.002), 5.0
    )
    assert near.accepted and near.test_ratio < 1.0
    assert near.estimate.position_m[2] > 1.0
    nan = ekf.fuse_height(est, math.nan, 0.0, 0.01, 5.0)
    assert not nan.accepted


def test_a_covariance_gone_singular_refuses_a_measurement_instead_of_raising():
    """A tumbling vehicle's filter can reach a covariance whose innovation covariance has no
    inverse; the pose and position fusions then refuse the measurement (counted as such),
    and the flight's loop goes on to its failsafes."""
    est = at_rest()
    flat = dataclasses.replace(est, covariance=np.ones_like(est.covariance))  # rank one
    pose = ekf.fuse_pose(flat, np.zeros(3), [0, 1, 2], 0.0, 0.0, 0.0, 5.0)
    assert not pose.accepted and pose.estimate is flat
    position = ekf.fuse_position(flat, est.position_m, est.position_m, np.zeros(3), 5.0)
    assert not position.accepted and position.estimate is flat


def test_a_position_reset_moves_the_position_and_forgets_its_correlations():
    est = at_rest()
    for k in range(1, 26):
        est = ekf.predict(est, k * DT_US, np.array([0.5, 0.0, GRAVITY_M_S2]), np.zeros(3), NOISE)
    reset = ekf.reset_position(est, np.array([0.3, -0.2]), [0, 1], 0.002)
    assert reset.position_m[:2] == pytest.approx(est.position_m[:2] + np.array([0.3, -0.2]))
    assert reset.position_m[2] == est.position_m[2]
    assert np.array_equal(reset.velocity_m_s, est.velocity_m_s)
    p = reset.covariance
    assert p[0, 0] == p[1, 1] == pytest.approx(4e-6)
    assert not p[0, 1:].any() and not p[3:, 1].any()  # no correlations left
    assert np.array_equal(p[2:, 2:], est.covariance[2:, 2:])


def test_the_heading_of_a_magnetometer_corrects_the_yaw():
    yawed = rotation_vector_quat(np.array([0.0, 0.0, 0.2]))
    est = ekf.initial(0, np.zeros(3), yawed, 0.01, attitude_sd_rad=0.3)
    field_world = np.array([0.0, 1.0, 0.0])  # north
    field_body = field_world  # a level vehicle facing east: the truth has no yaw
    for _ in range(50):
        est = ekf.fuse_heading(est, field_body, field_world, 0.05, 5.0).estimate
    assert abs(2.0 * math.atan2(est.quaternion[3], est.quaternion[0])) < 0.01


def test_the_attitude_at_rest_comes_from_gravity_and_the_field():
    q_true = rotation_vector_quat(np.array([0.1, -0.05, 0.7]))
    r = rotation(q_true)
    field_world = np.array([0.1, 0.9, -0.4])
    q = attitude_from_gravity_and_field(
        r.T @ np.array([0, 0, GRAVITY_M_S2]), r.T @ field_world, field_world
    )
    assert abs(float(np.dot(q, q_true))) == pytest.approx(1.0, abs=1e-9)


def test_ground_contact_needs_every_sign_of_it_for_the_trigger_time():
    p = LandDetectorParams()
    resting = 0.0126
    sitting = dict(height_m=resting, resting_height_m=resting, vertical_speed_m_s=0.0,
                   setpoint_below_m=0.03, thrust_fraction=0.8)  # fmt: skip
    assert ground_contact(**sitting, params=p)
    assert not ground_contact(**{**sitting, "vertical_speed_m_s": -0.1}, params=p)  # descending
    assert not ground_contact(**{**sitting, "setpoint_below_m": 0.0}, params=p)  # holding
    assert not ground_contact(**{**sitting, "thrust_fraction": 1.0}, params=p)  # lifting
    assert not ground_contact(**{**sitting, "height_m": resting + 0.5}, params=p)
    d = LandDetector()
    for t in (0.0, 0.1, 0.2):
        d = d.step(t, True)
    assert not d.landed(0.2, p)
    d = d.step(0.31, True)
    assert d.landed(0.31, p)
    assert not d.step(0.32, False).landed(0.32, p)  # a break starts it over


def test_the_landing_setpoint_stops_below_the_resting_height_and_contact_lands():
    params = CommanderParams()
    resting = 0.0126
    state = CommanderState(
        phase=Phase.LANDING, mode=FlightMode.LAND, since_s=0.0,
        landing_from_m=(0.0, 0.0, 0.03),
    )  # fmt: skip
    floating = (0.0, 0.0, 0.04)  # held up by a cushion of air the model lacks
    for t in (1.0, 10.0, 100.0):
        cmd = command(state, params, t, floating, 0.04, resting)
        z = cmd.setpoint.position_m[2]
        assert z == pytest.approx(resting - params.landing_floor_m)
        assert cmd.setpoint.velocity_m_s[2] == 0.0
        assert cmd.state.phase == Phase.LANDING
    landed = command(state, params, 100.0, floating, 0.04, resting, ground_contact=True)
    assert landed.state.phase == Phase.LANDED and not landed.armed


def test_simulated_imu_noise_has_the_datasheet_density_and_a_seeded_bias():
    noise = SensorNoise()
    period = 0.004
    a = SensorErrors(noise, period)
    samples = np.array([a.imu((0.0, 0.0, 9.81), (0.0, 0.0, 0.0))[0] for _ in range(20000)])
    sd = np.std(samples - samples.mean(axis=0), axis=0)
    assert np.allclose(sd, noise.accel_noise_density / math.sqrt(period), rtol=0.05)
    same, other = SensorErrors(noise, period), SensorErrors(SensorNoise(seed=2), period)
    assert np.array_equal(same.accel_bias, SensorErrors(noise, period).accel_bias)
    assert not np.array_equal(same.accel_bias, other.accel_bias)
    assert np.all(np.abs(same.accel_bias) < 5 * noise.accel_bias_sd_m_s2)
    ideal = SensorErrors(SensorNoise.ideal(), period)
    assert ideal.imu((0.1, 0.2, 9.81), (0.01, 0.0, 0.0)) == ((0.1, 0.2, 9.81), (0.01, 0.0, 0.0))
    assert ideal.range_m(0.5) == 0.5
