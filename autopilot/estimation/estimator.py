"""The state estimator: an error-state extended Kalman filter, as pure functions.

In the manner of PX4's EKF2 and the Crazyflie's: the IMU predicts (specific force and body
rates integrated, biases subtracted), measurements correct. The nominal state is position,
velocity (world x east, y north, z up), attitude (quaternion w, x, y, z, body FLU to world),
accelerometer and gyro biases (body). The filter's covariance is over the 15 errors
[dp, dv, dtheta, dba, dbg], dtheta a small rotation in the body frame (Sola, "Quaternion
kinematics for the error-state Kalman filter", 2017, sections 5 and 7).

Each correction returns the new state and its innovation test ratio, PX4's figure:
the largest of innovation^2 / (gate^2 * innovation variance) over the measurement's axes;
above 1 the measurement is rejected and the state is unchanged.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np

from autopilot.estimation.attitude import rotation, rotation_vector_floats, skew
from simbridge.frames import Vec3, quat_multiply, quat_normalize
from simbridge.vehicle import GRAVITY_M_S2

N_ERRORS = 15
P_, V_, TH_, BA_, BG_ = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15)


@dataclass(frozen=True)
class ProcessNoise:
    """IMU noise as the filter assumes it (a little above the sensors', for model error)."""

    accel_noise_density: float = 1.8e-3  # m/s^2/sqrt(Hz)
    gyro_noise_density: float = 5e-4  # rad/s/sqrt(Hz)
    accel_bias_walk: float = 1e-4  # m/s^2/sqrt(s)
    gyro_bias_walk: float = 1e-4  # rad/s/sqrt(s)


@dataclass(frozen=True)
class Estimate:
    time_us: int
    position_m: np.ndarray  # world
    velocity_m_s: np.ndarray  # world
    quaternion: np.ndarray  # (w, x, y, z) body to world
    accel_bias_m_s2: np.ndarray  # body
    gyro_bias_rad_s: np.ndarray  # body
    covariance: np.ndarray  # 15 x 15
    angular_velocity_body_rad_s: np.ndarray  # the last gyro sample, bias removed


@dataclass(frozen=True)
class Fused:
    estimate: Estimate
    test_ratio: float
    accepted: bool


def initial(
    time_us: int,
    position_m: np.ndarray,
    quaternion: np.ndarray,
    position_sd_m: float,
    attitude_sd_rad: float,
    accel_bias_sd: float = 0.1,
    gyro_bias_sd: float = 0.01,
) -> Estimate:
    """At rest: velocity zero (0.1 m/s), the biases unknown within the given spreads."""
    sd = np.concatenate(
        [
            np.full(3, position_sd_m),
            np.full(3, 0.1),
            np.full(3, attitude_sd_rad),
            np.full(3, accel_bias_sd),
            np.full(3, gyro_bias_sd),
        ]
    )
    return Estimate(
        time_us=time_us,
        position_m=np.asarray(position_m, dtype=float),
        velocity_m_s=np.zeros(3),
        quaternion=np.asarray(quaternion, dtype=float),
        accel_bias_m_s2=np.zeros(3),
        gyro_bias_rad_s=np.zeros(3),
        covariance=np.diag(sd * sd),
        angular_velocity_body_rad_s=np.zeros(3),
    )


def predict_state(
    est: Estimate,
    time_us: int,
    specific_force_body: Vec3 | np.ndarray,
    rates_body: Vec3 | np.ndarray,
) -> Estimate:
    """Propagate the state (not its covariance) over the IMU sample that ended at `time_us`
    (its mean over the period): every control step, as PX4's output predictor does. Written
    out in floats: a dozen 3-vector operations in numpy cost more than the whole of it."""
    dt = (time_us - est.time_us) * 1e-6
    if dt <= 0.0:
        return est
    dt = min(dt, 0.1)  # a gap in the IMU stream is not integrated as one long step
    w0, x0, y0, z0 = est.quaternion.tolist()
    bax, bay, baz = est.accel_bias_m_s2.tolist()
    bgx, bgy, bgz = est.gyro_bias_rad_s.tolist()
    fx, fy, fz = specific_force_body
    fx, fy, fz = fx - bax, fy - bay, fz - baz
    wx, wy, wz = rates_body
    wx, wy, wz = wx - bgx, wy - bgy, wz - bgz
    # world acceleration: R(q) f + g
    ax = (
        (1 - 2 * (y0 * y0 + z0 * z0)) * fx
        + 2 * (x0 * y0 - w0 * z0) * fy
        + 2 * (x0 * z0 + w0 * y0) * fz
    )
    ay = (
        2 * (x0 * y0 + w0 * z0) * fx
        + (1 - 2 * (x0 * x0 + z0 * z0)) * fy
        + 2 * (y0 * z0 - w0 * x0) * fz
    )
    az = (
        2 * (x0 * z0 - w0 * y0) * fx + 2 * (y0 * z0 + w0 * x0) * fy
        + (1 - 2 * (x0 * x0 + y0 * y0)) * fz - GRAVITY_M_S2
    )  # fmt: skip
    px, py, pz = est.position_m.tolist()
    vx, vy, vz = est.velocity_m_s.tolist()
    h = 0.5 * dt * dt
    # q * exp(w dt / 2), exactly
    angle = math.sqrt(wx * wx + wy * wy + wz * wz) * dt
    if angle < 1e-12:
        cw, k = 1.0, 0.5 * dt
    else:
        cw, k = math.cos(0.5 * angle), math.sin(0.5 * angle) / angle * dt
    dx, dy, dz = k * wx, k * wy, k * wz
    qw = w0 * cw - x0 * dx - y0 * dy - z0 * dz
    qx = w0 * dx + x0 * cw + y0 * dz - z0 * dy
    qy = w0 * dy - x0 * dz + y0 * cw + z0 * dx
    qz = w0 * dz + x0 * dy - y0 * dx + z0 * cw
    n = 1.0 / math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    return Estimate(
        time_us=time_us,
        position_m=np.array((px + vx * dt + h * ax, py + vy * dt + h * ay, pz + vz * dt + h * az)),
        velocity_m_s=np.array((vx + ax * dt, vy + ay * dt, vz + az * dt)),
        quaternion=np.array((qw * n, qx * n, qy * n, qz * n)),
        accel_bias_m_s2=est.accel_bias_m_s2,
        gyro_bias_rad_s=est.gyro_bias_rad_s,
        covariance=est.covariance,
        angular_velocity_body_rad_s=np.array((wx, wy, wz)),
    )


_IDENTITY = np.eye(N_ERRORS)


def predict_covariance(
    est: Estimate,
    dt: float,
    specific_force_body: Vec3 | np.ndarray,
    rates_body: Vec3 | np.ndarray,
    noise: ProcessNoise,
) -> Estimate:
    """Propagate the covariance over `dt` with the mean IMU sample of that interval (PX4's
    EKF2 predicts its covariance at 100 Hz from the accumulated IMU deltas). The Jacobian's
    blocks are written out in floats: a dozen 3 x 3 array operations cost more than the
    15 x 15 products."""
    if dt <= 0.0:
        return est
    w, x, y, z = est.quaternion.tolist()
    r00, r01, r02 = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    r10, r11, r12 = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    r20, r21, r22 = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    bax, bay, baz = est.accel_bias_m_s2.tolist()
    bgx, bgy, bgz = est.gyro_bias_rad_s.tolist()
    fx_, fy_, fz_ = specific_force_body
    fx_, fy_, fz_ = fx_ - bax, fy_ - bay, fz_ - baz
    wx, wy, wz = rates_body
    wx, wy, wz = (wx - bgx) * dt, (wy - bgy) * dt, (wz - bgz) * dt
    fx = _IDENTITY.copy()
    # diagonals by flat strides (row stride 15, so 16 steps along a diagonal): fancy indexing
    # costs several times more on these small arrays
    fx.flat[3:48:16] = dt  # dp/dv
    # dv/dtheta = -R [f]x dt and dv/dba = -R dt, side by side
    fx[V_, 6:12] = (
        (-(r01 * fz_ - r02 * fy_) * dt, -(r02 * fx_ - r00 * fz_) * dt,
         -(r00 * fy_ - r01 * fx_) * dt, -r00 * dt, -r01 * dt, -r02 * dt),
        (-(r11 * fz_ - r12 * fy_) * dt, -(r12 * fx_ - r10 * fz_) * dt,
         -(r10 * fy_ - r11 * fx_) * dt, -r10 * dt, -r11 * dt, -r12 * dt),
        (-(r21 * fz_ - r22 * fy_) * dt, -(r22 * fx_ - r20 * fz_) * dt,
         -(r20 * fy_ - r21 * fx_) * dt, -r20 * dt, -r21 * dt, -r22 * dt),
    )  # fmt: skip
    # exp(-[w dt]x) to first order: w dt is milliradians
    fx[TH_, TH_] = ((1.0, wz, -wy), (-wz, 1.0, wx), (wy, -wx, 1.0))
    fx.flat[102:135:16] = -dt  # dtheta/dbg
    p = fx @ est.covariance @ fx.T
    p.flat[48::16] += _process_variances(noise) * dt  # the diagonal from state 3 on
    # built directly: dataclasses.replace costs more than the products above
    return Estimate(
        est.time_us,
        est.position_m,
        est.velocity_m_s,
        est.quaternion,
        est.accel_bias_m_s2,
        est.gyro_bias_rad_s,
        p,
        est.angular_velocity_body_rad_s,
    )


@functools.lru_cache(maxsize=8)
def _process_variances(noise: ProcessNoise) -> np.ndarray:
    """Per unit time, on the velocity, angle, accelerometer- and gyro-bias errors."""
    return np.repeat(
        [
            noise.accel_noise_density**2,
            noise.gyro_noise_density**2,
            noise.accel_bias_walk**2,
            noise.gyro_bias_walk**2,
        ],
        3,
    )


def predict(
    est: Estimate,
    time_us: int,
    specific_force_body: np.ndarray,
    rates_body: np.ndarray,
    noise: ProcessNoise,
) -> Estimate:
    """State and covariance over one IMU sample."""
    dt = min((time_us - est.time_us) * 1e-6, 0.1)
    if dt <= 0.0:
        return est
    covariance = predict_covariance(est, dt, specific_force_body, rates_body, noise)
    return predict_state(covariance, time_us, specific_force_body, rates_body)


def _updated(est: Estimate, dx: np.ndarray, p_new: np.ndarray) -> Estimate:
    q = quat_normalize(
        quat_multiply(tuple(est.quaternion.tolist()), rotation_vector_floats(dx[6], dx[7], dx[8]))
    )
    return Estimate(
        time_us=est.time_us,
        position_m=est.position_m + dx[P_],
        velocity_m_s=est.velocity_m_s + dx[V_],
        quaternion=np.array(q),
        accel_bias_m_s2=est.accel_bias_m_s2 + dx[BA_],
        gyro_bias_rad_s=est.gyro_bias_rad_s + dx[BG_],
        covariance=0.5 * (p_new + p_new.T),
        angular_velocity_body_rad_s=est.angular_velocity_body_rad_s,
    )


def _gain(ph: np.ndarray, s: np.ndarray) -> np.ndarray | None:
    """The Kalman gain P h^T S^-1, or None where S cannot be inverted: a covariance gone
    singular or infinite (a vehicle tumbling on the ground) refuses the measurement, as the
    gate refuses an outlier, instead of ending the flight's loop with an exception."""
    try:
        k = ph @ np.linalg.inv(s)
    except np.linalg.LinAlgError:
        return None
    return k if np.isfinite(k).all() else None


def correct(
    est: Estimate, innovation: np.ndarray, h: np.ndarray, variance: np.ndarray, gate_sd: float
) -> Fused:
    """The Kalman correction for `innovation` = measured - predicted with Jacobian `h` (m x 15)
    and measurement variances `variance` (m); rejected beyond `gate_sd` standard deviations."""
    p = est.covariance
    ph = p @ h.T
    s = h @ ph + np.diag(variance)
    ratio = float(np.max(innovation * innovation / (gate_sd * gate_sd * np.diag(s))))
    k = _gain(ph, s) if ratio <= 1.0 else None  # NaN is rejected too
    if k is None:
        return Fused(est, ratio, False)
    return Fused(_updated(est, k @ innovation, p - k @ ph.T), ratio, True)


def correct_states(
    est: Estimate, innovation: np.ndarray, states: list[int], variance: np.ndarray, gate_sd: float
) -> Fused:
    """`correct` for a measurement of error states themselves (h selects `states`): the same
    update without the products by h."""
    p = est.covariance
    if len(states) == 1:  # a scalar: the same arithmetic without indexing and inverting arrays
        ph1 = p[:, states[0]]
        s1 = float(ph1[states[0]]) + float(variance[0])
        nu = float(innovation[0])
        ratio = nu * nu / (gate_sd * gate_sd * s1)
        if not ratio <= 1.0:  # NaN is rejected too
            return Fused(est, ratio, False)
        k1 = ph1 * (1.0 / s1)
        return Fused(_updated(est, k1 * nu, p - np.outer(k1, ph1)), ratio, True)
    ph = p[:, states]
    s = ph[states, :]
    m = len(states)
    s.flat[:: m + 1] += variance
    ratio = float(np.max(innovation * innovation / (gate_sd * gate_sd * s.flat[:: m + 1])))
    k = _gain(ph, s) if ratio <= 1.0 else None  # NaN is rejected too
    if k is None:
        return Fused(est, ratio, False)
    return Fused(_updated(est, k @ innovation, p - k @ ph.T), ratio, True)


def fuse_position(
    est: Estimate,
    measured_m: np.ndarray,
    predicted_m: np.ndarray,
    sd_m: np.ndarray,
    gate_sd: float,
    axes: list[int] | None = None,
) -> Fused:
    """A position (world) on the given axes; `predicted_m` is the filter's position at the
    measurement's capture time (a delayed measurement corrects the present state)."""
    axes = [0, 1, 2] if axes is None else axes
    innovation = (measured_m - predicted_m)[axes]
    return correct_states(est, innovation, axes, sd_m[axes] ** 2, gate_sd)


def fuse_velocity(est: Estimate, measured_m_s: np.ndarray, sd_m_s: float, gate_sd: float) -> Fused:
    """A world-frame velocity (GPS)."""
    innovation = measured_m_s - est.velocity_m_s
    return correct_states(est, innovation, [3, 4, 5], np.full(3, sd_m_s**2), gate_sd)


def fuse_pose(
    est: Estimate,
    position_innovation_m: np.ndarray,
    axes: list[int],
    position_sd_m: float,
    yaw_innovation_rad: float | None,
    yaw_sd_rad: float,
    gate_sd: float,
) -> Fused:
    """A motion-capture pose in one update, as PX4's EKF2 fuses external vision: the position
    on `axes` (innovations given, each against the filter's position at capture time) and
    the yaw (roll and pitch come from the accelerometer: a capture system's attitude noise
    would only add to them)."""
    if yaw_innovation_rad is None:
        variance = np.full(len(axes), position_sd_m * position_sd_m)
        return correct_states(est, position_innovation_m, axes, variance, gate_sd)
    # h: the position axes' rows select states; the yaw row is R's last row on the angle
    # error (a body rotation turns the heading by (R dtheta)_z). This runs at the capture
    # system's rate, so in as few array operations as the update allows.
    m = len(axes) + 1
    w, x, y, z = est.quaternion.tolist()
    h = _pose_rows(tuple(axes)).copy()
    h[-1, TH_] = (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y))  # R[2]
    p = est.covariance
    ph = p @ h.T
    s = h @ ph
    position_var = position_sd_m * position_sd_m
    s.flat[:: m + 1] += [position_var] * (m - 1) + [yaw_sd_rad * yaw_sd_rad]
    innovation = np.asarray(position_innovation_m, dtype=float).tolist()
    innovation.append((yaw_innovation_rad + math.pi) % (2.0 * math.pi) - math.pi)
    gate2 = gate_sd * gate_sd
    variances = s.flat[:: m + 1].tolist()
    ratios = [nu * nu / (gate2 * var) for nu, var in zip(innovation, variances, strict=True)]
    ratio = math.nan if any(r != r for r in ratios) else max(ratios)  # NaN is rejected too
    gain = _gain(ph, s) if ratio <= 1.0 else None
    if gain is None:
        return Fused(est, ratio, False)
    return Fused(_updated(est, gain @ innovation, p - gain @ ph.T), ratio, True)


@functools.lru_cache(maxsize=8)
def _pose_rows(axes: tuple[int, ...]) -> np.ndarray:
    """A pose's measurement rows with the position axes' ones set, the yaw row to fill."""
    h = np.zeros((len(axes) + 1, N_ERRORS))
    h[range(len(axes)), axes] = 1.0
    return h


def reset_position(
    est: Estimate, innovation_m: np.ndarray, axes: list[int], sd_m: float
) -> Estimate:
    """PX4's EKF2 reset to a position source whose fusion keeps failing: the position on
    `axes` moved by the innovation, its covariance rows and columns cleared, its variance the
    source's."""
    position = est.position_m.copy()
    position[axes] += innovation_m
    p = est.covariance.copy()
    p[axes, :] = 0.0
    p[:, axes] = 0.0
    p[axes, axes] = sd_m * sd_m
    return dataclasses.replace(est, position_m=position, covariance=p)


def fuse_heading(
    est: Estimate, field_body: np.ndarray, field_world: np.ndarray, sd_rad: float, gate_sd: float
) -> Fused:
    """The magnetometer's heading: its field turned into the world by the estimated attitude,
    compared horizontally with the known field; corrects yaw only."""
    r = rotation(est.quaternion)
    f = r @ field_body
    innovation = math.atan2(field_world[1], field_world[0]) - math.atan2(f[1], f[0])
    innovation = (innovation + math.pi) % (2.0 * math.pi) - math.pi
    h = np.zeros((1, N_ERRORS))
    h[0, TH_] = r[2, :]  # a body rotation dtheta turns the heading by (R dtheta)_z
    return correct(est, np.array([innovation]), h, np.array([sd_rad**2]), gate_sd)


def fuse_height(
    est: Estimate, height_m: float, terrain_m: float, sd_m: float, gate_sd: float
) -> Fused:
    """A height above the terrain at `terrain_m` (range finder, barometer against its
    reference)."""
    innovation = np.array([height_m - (est.position_m[2] - terrain_m)])
    return correct_states(est, innovation, [2], np.array([sd_m**2]), gate_sd)


def fuse_body_velocity(
    est: Estimate, measured_xy_m_s: np.ndarray, sd_m_s: float, gate_sd: float
) -> Fused:
    """The horizontal body-frame velocity of an optical-flow sensor (flow times height)."""
    r = rotation(est.quaternion)
    v_body = r.T @ est.velocity_m_s
    innovation = measured_xy_m_s - v_body[:2]
    h = np.zeros((2, N_ERRORS))
    h[:, V_] = r.T[:2, :]
    h[:, TH_] = skew(v_body)[:2, :]
    return correct(est, innovation, h, np.full(2, sd_m_s**2), gate_sd)
