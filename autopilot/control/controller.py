"""The feedback-linearising controller of thesis section 3.4, a pure function.

(state, setpoint, ground-effect estimate, vehicle, gains) -> rotor speeds:

    (3.7)  a = a0 (p_d - p) + a1 (v_d - v) + a_d  (+ a_i = k_i * integral of the PD term)
    (3.11) T = (m a_w + m g - f_w) / (cos phi cos theta)
    (3.12) theta_dc = arctan((a_u - f_u / m) / (a_w + g - f_w / m))
    (3.13) phi_dc   = arctan((a_v - f_v / m) / (-a_w - g + f_w / m))
    (3.14) eta'' = k_p (eta_d - eta) + k_d (eta_d' - eta'),  eta = (phi, theta, psi)
    (3.15) eta'' = W w' + W' w  ->  w' = W^-1 (eta'' - W' w);  M = I w' + w x I w
    (3.5, 3.6) inverted by the mixer within [0, n_max], yaw given up first, then thrust,
               then roll and pitch (their direction kept)

u, v, w is the world frame turned by the yaw; f is the ground-effect estimate (world frame,
N). Angles are Z-Y-X Euler angles of the body (x forward, y left, z up): a positive theta
tilts the thrust forward, a positive phi to the right. The desired angle rates are taken as
zero (the thesis stops at each waypoint), and the gyroscopic term w x I w is added to the
thesis's M = I w' (exact feedback linearisation; it is below 1e-8 N m in hover).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from autopilot.types import FlightState, Setpoint
from simbridge.config import param
from simbridge.frames import Vec3, euler_from_quat
from simbridge.rotors import Quad, prioritised_rotor_forces, rotor_speeds_for
from simbridge.vehicle import GRAVITY_M_S2, Vehicle

# Below this the vertical term of 3.12 and 3.13 would flip the desired tilt: commanding a
# fall faster than 0.2 g is refused by holding it here.
MIN_VERTICAL_ACCEL_M_S2 = 0.2 * GRAVITY_M_S2
# The horizontal jerk limit (PX4's MPC_JERK_MAX, 8 m/s^3 on a vehicle of 0.2-0.25 m arms),
# scaled to this vehicle's size: with thrust per mass alike, a vehicle's angular
# acceleration for a given moment share goes as 1/arm, its attitude time scales as
# sqrt(arm), so an acceleration it can follow changes sqrt(0.225 / 0.045) = 2.2 times
# faster. A tilt command that changes faster rings the attitude loop, which a slow motor
# (tau 0.08 s leaves the 400/40 loop a damping ratio of 0.05) or a late IMU turns into a
# flip: PX4 shapes its setpoints with this limit for the same reason.
JERK_DEFAULT_M_S3 = 18.0


@dataclass(frozen=True)
class ControllerParams:
    """Gains. Horizontal position: a0 = 6, a1 = 6; vertical: a0 = 36, a1 = 12 (a double pole
    at s = -6 rad/s); an integral of the PD term with gain k_i = 4/s on every axis, as PX4's
    velocity-loop integrator (the PD term is zero in steady motion towards a setpoint that
    leads the vehicle, so nothing winds up on the way). The integral flies out a mass or
    thrust error. Why the vertical loop is the stiffer: with the ground effect compensated
    the vertical position loop is the only spring holding the vehicle near the ground, and
    the compensation turns an error e of the estimated height into a force: at 3 cm over
    rho 2 the ground effect changes by G = 0.2 m/s^2 per mm on the nano, which the loop
    balances G e / a0 away. The estimated height's slow error, within the loop's bandwidth,
    is about 0.3 mm on a range sensor of 2.5 mm noise at 50 Hz (the flow deck), so a hold
    within 2 mm asks a0 >= 0.2 * 0.3 / 0.002 = 30/s^2; critically damped, 36 and 12. The
    Crazyflie's Mellinger controller flies its 27 g vehicle at kp_z = 1.25 N/m and kd_z =
    0.4 N s/m, 46/s^2 and 15/s per mass, and 15/s^2 and 7.4/s horizontally: vertical loops
    of nano quadrotors are stiffer than horizontal ones. Horizontally the loop shapes the
    path (the setpoint's lead, the jerk limit) and meets no such gradient. The vertical PD
    term asks for at most 4 m/s^2 up or down (the value of PX4's MPC_ACC_UP_MAX): a stiff
    loop answers a large error with a large thrust step, and rotors that spin down slowly
    (a propeller coasting 0.8 s) turn those steps into a growing vertical oscillation; in a
    hold the term is a hundredth of that. With the integral the poles are at -0.95 and -2.5 +- 4.3j
    horizontally, -2.3 and -4.8 +- 6.2j vertically.
    The thesis's pure PD (a0 = 1, a1 = 2 on every axis, no integral) is `THESIS_GAINS`.
    Attitude: the thesis used 1 and 2, which makes the inner loop no faster than the outer
    one; here a double pole at s = -20 rad/s (k_p = 400, k_d = 40), inside the 250 Hz
    control rate."""

    position_p: float = param(
        6.0, unit="1/s^2", lo=0.0, hi=100.0, doc="a0 of equation 3.7, horizontal"
    )
    position_d: float = param(
        6.0, unit="1/s", lo=0.0, hi=100.0, doc="a1 of equation 3.7, horizontal"
    )
    vertical_p: float = param(
        36.0, unit="1/s^2", lo=0.0, hi=400.0, doc="a0 of equation 3.7, vertical"
    )
    vertical_d: float = param(
        12.0, unit="1/s", lo=0.0, hi=100.0, doc="a1 of equation 3.7, vertical"
    )
    vertical_accel_limit_m_s2: float = param(
        4.0, unit="m/s^2", lo=0.1, hi=100.0,
        doc="largest vertical acceleration the PD term of 3.7 may ask for, up or down",
    )  # fmt: skip
    position_i: float = param(
        4.0, unit="1/s", lo=0.0, hi=100.0, doc="integral gain on the PD term (0: the thesis's PD)"
    )
    integral_limit_m_s2: float = param(
        3.0, unit="m/s^2", lo=0.0, hi=20.0, doc="largest acceleration the integral may add"
    )
    attitude_p: float = param(400.0, unit="1/s^2", lo=0.0, hi=10000.0, doc="roll/pitch k_p")
    attitude_d: float = param(40.0, unit="1/s", lo=0.0, hi=1000.0, doc="roll/pitch k_d")
    yaw_p: float = param(100.0, unit="1/s^2", lo=0.0, hi=10000.0, doc="yaw k_p")
    yaw_d: float = param(20.0, unit="1/s", lo=0.0, hi=1000.0, doc="yaw k_d")
    max_tilt_deg: float = param(30.0, unit="deg", lo=1.0, hi=60.0, doc="desired tilt limit")
    max_jerk_m_s3: float = param(
        JERK_DEFAULT_M_S3, unit="m/s^3", lo=0.0, hi=1000.0,
        doc="how fast a setpoint's jump may change the horizontal acceleration (0: at once)",
    )  # fmt: skip


@dataclass(frozen=True)
class ControlOutput:
    rotor_speeds_rad_s: Quad
    thrust_n: float
    moments_n_m: Vec3  # body frame
    commanded_acceleration_m_s2: Vec3  # equation 3.7, world frame
    desired_roll_rad: float
    desired_pitch_rad: float
    saturated: bool = False  # thrust or tilt limited: the integral must not wind up
    pd_acceleration_m_s2: Vec3 = (0.0, 0.0, 0.0)  # the PD term of 3.7, what the integral sums
    # the horizontal position term a0 (p_d - p) of 3.7 (world x, y) as commanded, jerk-limited:
    # what the next step's limit starts from
    position_term_m_s2: tuple[float, float] = (0.0, 0.0)


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


# thesis section 3.4: the same PD on every axis, unlimited, no integral
THESIS_GAINS = {
    "GFX_POS_P": 1.0, "GFX_POS_D": 2.0, "GFX_POS_Z_P": 1.0, "GFX_POS_Z_D": 2.0,
    "GFX_POS_Z_AMAX": 100.0, "GFX_POS_I": 0.0,
}  # fmt: skip


def integrate(
    integral_m_s2: Vec3,
    pd_m_s2: Vec3,
    dt_s: float,
    params: ControllerParams,
    frozen: bool,
) -> Vec3:
    """The integral term after one step: k_i times the PD term added unless `frozen` (on the
    ground, in ground contact, or the last command saturated: anti-windup), clamped to the
    limit."""
    if frozen or params.position_i == 0.0 or dt_s <= 0.0:
        return integral_m_s2
    k, lim = params.position_i * dt_s, params.integral_limit_m_s2
    i = integral_m_s2
    return (
        min(max(i[0] + k * pd_m_s2[0], -lim), lim),
        min(max(i[1] + k * pd_m_s2[1], -lim), lim),
        min(max(i[2] + k * pd_m_s2[2], -lim), lim),
    )


# The integral runs only this far above the resting height: on the ground the contact force
# would wind it up.
INTEGRATE_ABOVE_M = 0.005


def integral_frozen(
    in_the_air: bool,
    taking_off: bool,
    height_m: float,
    resting_height_m: float,
    contact: bool,
    saturated: bool,
) -> bool:
    """Anti-windup: whether the integral holds still this step. `in_the_air`: the commander
    flies (taking off, flying, holding, landing). It holds on the ground (but while taking
    off: a vehicle heavier than its file must wind the integral up to leave it), in ground
    contact, or when the last command saturated. While landing it runs: a vehicle held up by
    a force its model lacks must wind it down to come down (PX4's integrators run until
    ground contact)."""
    return (
        not in_the_air
        or (not taking_off and height_m < resting_height_m + INTEGRATE_ABOVE_M)
        or contact
        or saturated
    )


def handover(integral_m_s2: Vec3, change_m_s2: Vec3) -> Vec3:
    """The integral after the ground-effect model changed by `change_m_s2` (its new minus its
    old prediction at the current state, over the mass): the model takes over the part of
    the integral it now explains, and no more (per axis: towards zero, never past it), so
    that a model learnt in flight does not step the command while the integral unwinds
    what the model now does (bumpless transfer)."""

    def axis(i: float, d: float) -> float:
        if i * d >= 0.0:  # the change is not what the integral held
            return i
        n = i + d
        return n if n * i > 0.0 else 0.0

    return (
        axis(integral_m_s2[0], change_m_s2[0]),
        axis(integral_m_s2[1], change_m_s2[1]),
        axis(integral_m_s2[2], change_m_s2[2]),
    )


def model_handover(
    integral_m_s2: Vec3, new_prediction_n: Vec3, old_prediction_n: Vec3, mass_kg: float
) -> Vec3:
    """The integral after the ground-effect model was replaced, from the new and the old
    model's predictions at the current state (bumpless transfer, see `handover`)."""
    new, old, m = new_prediction_n, old_prediction_n, mass_kg
    change = ((new[0] - old[0]) / m, (new[1] - old[1]) / m, (new[2] - old[2]) / m)
    return handover(integral_m_s2, change)


def jerk_limited(
    previous_m_s2: tuple[float, float],
    wanted_m_s2: tuple[float, float],
    dt_s: float,
    params: ControllerParams,
) -> tuple[float, float]:
    """`wanted_m_s2`, moved from `previous_m_s2` by at most `max_jerk_m_s3` times `dt_s` (as a
    vector: the direction of the change is kept)."""
    if params.max_jerk_m_s3 <= 0.0 or dt_s <= 0.0:
        return wanted_m_s2
    du, dv = wanted_m_s2[0] - previous_m_s2[0], wanted_m_s2[1] - previous_m_s2[1]
    step, most = math.hypot(du, dv), params.max_jerk_m_s3 * dt_s
    if step <= most:
        return wanted_m_s2
    return (previous_m_s2[0] + du * most / step, previous_m_s2[1] + dv * most / step)


def _commanded_acceleration(
    state: FlightState,
    setpoint: Setpoint,
    params: ControllerParams,
    integral_m_s2: Vec3,
    previous_position_term_m_s2: tuple[float, float] | None,
    dt_s: float,
) -> tuple[tuple[float, float], Vec3, Vec3]:
    """Equation 3.7 in the world frame: (the jerk-limited horizontal position term, the PD
    term, the commanded acceleration with the feed-forward and the integral term)."""
    p, v, sp, i = state.position_m, state.velocity_m_s, setpoint, integral_m_s2
    a0, a1 = params.position_p, params.position_d
    e_xy = (a0 * (sp.position_m[0] - p[0]), a0 * (sp.position_m[1] - p[1]))
    if previous_position_term_m_s2 is not None:
        e_xy = jerk_limited(previous_position_term_m_s2, e_xy, dt_s, params)
    pd_z = params.vertical_p * (sp.position_m[2] - p[2]) + params.vertical_d * (
        sp.velocity_m_s[2] - v[2]
    )
    z_limit = params.vertical_accel_limit_m_s2
    pd = (
        e_xy[0] + a1 * (sp.velocity_m_s[0] - v[0]),
        e_xy[1] + a1 * (sp.velocity_m_s[1] - v[1]),
        min(max(pd_z, -z_limit), z_limit),
    )
    ff = sp.acceleration_m_s2
    commanded = (pd[0] + ff[0] + i[0], pd[1] + ff[1] + i[1], pd[2] + ff[2] + i[2])
    return e_xy, pd, commanded


@dataclass(frozen=True)
class _Attitude:
    """Thrust and the desired roll and pitch (3.11-3.13), and whether a limit cut them."""

    thrust_n: float
    roll_rad: float
    pitch_rad: float
    saturated: bool


def _thrust_and_tilt(
    commanded_m_s2: Vec3,
    ground_effect_n: Vec3,
    euler_rad: Vec3,
    vehicle: Vehicle,
    params: ControllerParams,
) -> _Attitude:
    """(3.11) with the current tilt; (3.12, 3.13) the tilt that gives the commanded
    acceleration, in the frame turned by the yaw."""
    m, g = vehicle.mass_kg, GRAVITY_M_S2
    ax, ay, az = commanded_m_s2
    phi, theta, psi = euler_rad
    c, s = math.cos(psi), math.sin(psi)
    a_u, a_v = c * ax + s * ay, -s * ax + c * ay
    fx, fy, fz = ground_effect_n
    f_u, f_v = c * fx + s * fy, -s * fx + c * fy
    vertical = max(az + g - fz / m, MIN_VERTICAL_ACCEL_M_S2)
    tilt_cos = max(math.cos(phi) * math.cos(theta), 0.5)
    thrust_max = 4.0 * vehicle.thrust_coefficient_n_s2 * vehicle.max_rotor_speed_rad_s**2
    wanted_thrust = m * vertical / tilt_cos
    thrust = min(max(wanted_thrust, 0.0), thrust_max)
    limit = math.radians(params.max_tilt_deg)
    theta_want = math.atan((a_u - f_u / m) / vertical)
    phi_want = math.atan((a_v - f_v / m) / -vertical)
    theta_dc = min(max(theta_want, -limit), limit)
    phi_dc = min(max(phi_want, -limit), limit)
    saturated = (
        wanted_thrust != thrust
        or theta_dc != theta_want
        or phi_dc != phi_want
        or az + g - fz / m < MIN_VERTICAL_ACCEL_M_S2
    )
    return _Attitude(thrust, phi_dc, theta_dc, saturated)


def _moments(
    state: FlightState,
    euler_rad: Vec3,
    desired_rad: Vec3,
    vehicle: Vehicle,
    params: ControllerParams,
) -> Vec3:
    """(3.14) the Euler-angle accelerations towards `desired_rad` (roll, pitch, yaw), (3.15)
    the body's angular acceleration that gives them, and the moment: M = I w' + w x I w."""
    phi, theta, psi = euler_rad
    phi_dc, theta_dc, yaw_rad = desired_rad
    # Euler rates from body rates: eta' = W w
    wx, wy, wz = state.angular_velocity_body_rad_s
    sphi, cphi = math.sin(phi), math.cos(phi)
    cth = math.cos(theta)
    cth = math.copysign(max(abs(cth), 1e-3), cth)
    tth = math.sin(theta) / cth
    phi_dot = wx + sphi * tth * wy + cphi * tth * wz
    theta_dot = cphi * wy - sphi * wz
    psi_dot = (sphi * wy + cphi * wz) / cth
    kp, kd = params.attitude_p, params.attitude_d
    phi_dd = kp * (phi_dc - phi) - kd * phi_dot
    theta_dd = kp * (theta_dc - theta) - kd * theta_dot
    psi_dd = params.yaw_p * _wrap(yaw_rad - psi) - params.yaw_d * psi_dot

    # (3.15) w' = W^-1 (eta'' - W' w)
    sec2 = 1.0 / (cth * cth)
    r_phi = phi_dd - (
        cphi * tth * phi_dot * wy
        + sphi * sec2 * theta_dot * wy
        - sphi * tth * phi_dot * wz
        + cphi * sec2 * theta_dot * wz
    )
    r_theta = theta_dd - (-sphi * phi_dot * wy - cphi * phi_dot * wz)
    r_psi = psi_dd - (
        (cphi * phi_dot * wy - sphi * phi_dot * wz) / cth
        + (sphi * wy + cphi * wz) * math.sin(theta) * theta_dot * sec2
    )
    dwx = r_phi - math.sin(theta) * r_psi
    dwy = cphi * r_theta + sphi * cth * r_psi
    dwz = -sphi * r_theta + cphi * cth * r_psi
    ixx, iyy, izz = vehicle.inertia_kg_m2
    return (
        ixx * dwx + (izz - iyy) * wy * wz,
        iyy * dwy + (ixx - izz) * wz * wx,
        izz * dwz + (iyy - ixx) * wx * wy,
    )


def control(
    state: FlightState,
    setpoint: Setpoint,
    ground_effect_n: Vec3,
    vehicle: Vehicle,
    params: ControllerParams,
    integral_m_s2: Vec3 = (0.0, 0.0, 0.0),
    previous_position_term_m_s2: tuple[float, float] | None = None,
    dt_s: float = 0.0,
) -> ControlOutput:
    """One step. `previous_position_term_m_s2`: the last step's `position_term_m_s2` (None:
    none, as on the ground), `dt_s` before this one. The horizontal position term then
    changes by at most `max_jerk_m_s3` times `dt_s`: a setpoint that jumps (a new waypoint,
    the carrot turning a corner) tilts the vehicle over a few tenths of a second instead of
    in one step, as PX4's jerk-limited setpoints do. The velocity term is not limited: it
    moves with the vehicle, and state noise passes through it unfiltered."""
    e_xy, pd, commanded = _commanded_acceleration(
        state, setpoint, params, integral_m_s2, previous_position_term_m_s2, dt_s
    )
    euler = euler_from_quat(state.quaternion)
    attitude = _thrust_and_tilt(commanded, ground_effect_n, euler, vehicle, params)
    desired = (attitude.roll_rad, attitude.pitch_rad, setpoint.yaw_rad)
    moments = _moments(state, euler, desired, vehicle, params)
    n_max = vehicle.max_rotor_speed_rad_s
    forces = prioritised_rotor_forces(
        attitude.thrust_n,
        moments,
        vehicle.arm_m,
        vehicle.yaw_moment_coefficient_m,
        vehicle.thrust_coefficient_n_s2 * n_max * n_max,
    )
    speeds = rotor_speeds_for(
        vehicle.thrust_coefficient_n_s2, forces, vehicle.max_rotor_speed_rad_s
    )
    return ControlOutput(
        rotor_speeds_rad_s=speeds,
        thrust_n=attitude.thrust_n,
        moments_n_m=moments,
        commanded_acceleration_m_s2=commanded,
        desired_roll_rad=attitude.roll_rad,
        desired_pitch_rad=attitude.pitch_rad,
        saturated=attitude.saturated,
        pd_acceleration_m_s2=pd,
        position_term_m_s2=e_xy,
    )
