"""The controller of thesis section 3.4 as a pure function."""

from __future__ import annotations

import math

import pytest

from autopilot.control.controller import (
    ControllerParams,
    control,
    handover,
    integral_frozen,
    integrate,
    jerk_limited,
    model_handover,
)
from autopilot.control.ground_models import (
    AnalyticGroundEffect,
    GroundEffectInputs,
    fixed_point_step,
    make_model,
)
from autopilot.types import FlightState, Setpoint
from simbridge.config import ConfigError
from simbridge.effects.ground import ground_effect_force_n
from simbridge.frames import quat_from_euler
from simbridge.rotors import rotor_forces_n, thrust_and_moments
from simbridge.vehicle import GRAVITY_M_S2, load_vehicle

V = load_vehicle()
# the thesis's gains, the same on every axis
P = ControllerParams(
    position_p=1.0,
    position_d=2.0,
    vertical_p=1.0,
    vertical_d=2.0,
    vertical_accel_limit_m_s2=100.0,
    position_i=0.0,
)
LEVEL = FlightState((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


def applied(out):
    return thrust_and_moments(
        rotor_forces_n(V.thrust_coefficient_n_s2, out.rotor_speeds_rad_s),
        V.arm_m,
        V.yaw_moment_coefficient_m,
    )


def test_at_the_setpoint_it_commands_the_hover_speed():
    out = control(LEVEL, Setpoint((0.0, 0.0, 1.0)), (0.0, 0.0, 0.0), V, P)
    assert out.rotor_speeds_rad_s == pytest.approx((V.hover_rotor_speed_rad_s,) * 4)
    assert out.moments_n_m == pytest.approx((0.0, 0.0, 0.0))


def test_equation_3_7_and_3_11_thrust():
    state = FlightState((0.0, 0.0, 1.0), (0.0, 0.0, 0.5), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    out = control(state, Setpoint((0.0, 0.0, 1.2)), (0.0, 0.0, 0.0), V, P)
    az = 1.0 * 0.2 + 2.0 * (0.0 - 0.5)  # a0 (z_d - z) + a1 (v_d - v)
    assert out.commanded_acceleration_m_s2[2] == pytest.approx(az)
    assert out.thrust_n == pytest.approx(V.mass_kg * (az + GRAVITY_M_S2))
    assert applied(out)[0] == pytest.approx(out.thrust_n)


def test_a_ground_effect_estimate_is_subtracted_from_the_thrust():
    without = control(LEVEL, Setpoint((0.0, 0.0, 1.0)), (0.0, 0.0, 0.0), V, P)
    with_ge = control(LEVEL, Setpoint((0.0, 0.0, 1.0)), (0.0, 0.0, 0.2), V, P)
    assert without.thrust_n - with_ge.thrust_n == pytest.approx(0.2)


def test_tilt_commands_point_the_thrust_toward_the_setpoint():
    forward = control(LEVEL, Setpoint((1.0, 0.0, 1.0)), (0.0, 0.0, 0.0), V, P)
    assert forward.desired_pitch_rad == pytest.approx(math.atan(1.0 / GRAVITY_M_S2))  # (3.12)
    assert forward.moments_n_m[1] > 0  # pitch toward +theta: thrust tilts forward
    left = control(LEVEL, Setpoint((0.0, 1.0, 1.0)), (0.0, 0.0, 0.0), V, P)
    assert left.desired_roll_rad == pytest.approx(math.atan(1.0 / -GRAVITY_M_S2))  # (3.13)
    assert left.moments_n_m[0] < 0
    # facing north (yaw 90 deg), "forward" is +y: an eastward setpoint is to its right
    north = FlightState(
        (0.0, 0.0, 1.0), (0.0, 0.0, 0.0), quat_from_euler(0.0, 0.0, math.pi / 2), (0.0, 0.0, 0.0)
    )
    east = control(north, Setpoint((1.0, 0.0, 1.0), yaw_rad=math.pi / 2), (0.0, 0.0, 0.0), V, P)
    assert east.desired_roll_rad > 0 and abs(east.desired_pitch_rad) < 1e-12


def test_lateral_ground_effect_estimate_is_compensated_by_tilt():
    pushed = control(LEVEL, Setpoint((0.0, 0.0, 1.0)), (0.056, 0.0, 0.0), V, P)  # 1 m/s^2 east
    assert pushed.desired_pitch_rad == pytest.approx(math.atan(-1.0 / GRAVITY_M_S2))


def test_attitude_feedback_linearisation_gives_the_commanded_angular_acceleration():
    tilted = FlightState(
        (0.0, 0.0, 1.0), (0.0, 0.0, 0.0), quat_from_euler(0.1, 0.0, 0.0), (0.0, 0.0, 0.0)
    )
    out = control(tilted, Setpoint((0.0, 0.0, 1.0)), (0.0, 0.0, 0.0), V, P)
    # at rest, (3.14): phi'' = k_p (phi_dc - phi); (3.15): M_x = I_xx phi''
    assert out.moments_n_m[0] == pytest.approx(
        V.inertia_kg_m2[0] * P.attitude_p * (out.desired_roll_rad - 0.1)
    )


def test_saturation_keeps_rotor_speeds_in_range():
    far = control(LEVEL, Setpoint((0.0, 0.0, 100.0)), (0.0, 0.0, 0.0), V, P)
    assert all(0.0 <= n <= V.max_rotor_speed_rad_s for n in far.rotor_speeds_rad_s)
    falling = control(LEVEL, Setpoint((0.0, 0.0, -100.0)), (0.0, 0.0, 0.0), V, P)
    assert all(0.0 <= n <= V.max_rotor_speed_rad_s for n in falling.rotor_speeds_rad_s)


def test_analytic_model_is_equation_3_4_per_rotor():
    model = AnalyticGroundEffect(V, 2.0)
    n = 70.0
    f = model.predict(GroundEffectInputs(0.05, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (n,) * 4))
    assert f == pytest.approx(
        (
            0.0,
            0.0,
            4 * ground_effect_force_n(V.thrust_coefficient_n_s2 * n * n, 0.05, 2.0, 0.047, 0.02),
        )
    )
    # rolled right: the left rotors (0, 1) sit higher, and feel less
    rolled = quat_from_euler(0.2, 0.0, 0.0)
    f_rolled = model.predict(GroundEffectInputs(0.05, (0.0, 0.0, 0.0), rolled, (n,) * 4))
    assert f_rolled[2] > f[2]  # the lower rotors gain more than the higher ones lose
    assert make_model("none", V).predict(
        GroundEffectInputs(0.03, (0, 0, 0), (1, 0, 0, 0), (n,) * 4)
    ) == (0.0, 0.0, 0.0)


def test_model_choice_errors_name_the_option():
    with pytest.raises(ConfigError, match="network 'rho9': no such file or packaged network"):
        make_model("neural", V, network="rho9")
    assert make_model("neural", V, rho=2.0).net.header["training"]["rho"] == [2.0]
    with pytest.raises(ConfigError, match=r"--rho: -1 is outside the allowed range \(0, 50\]"):
        make_model("analytic", V, -1.0)


def test_the_ground_effect_fixed_point_converges_where_straight_feedback_diverges():
    """With rho = 2 at the cut-off the effect is 2.2 times the thrust causing it."""
    gain, need = 2.23, 0.5  # f_ge = gain * T; the controller needs T + f_ge = need
    straight = estimate = 0.0
    for _ in range(20):
        straight = gain * (need - straight)  # next estimate from the thrust just chosen
        thrust = need - estimate
        estimate = fixed_point_step((0.0, 0.0, estimate), (0.0, 0.0, gain * thrust), thrust)[2]
    assert estimate == pytest.approx(need * gain / (1 + gain), rel=1e-9)
    assert abs(straight) > 100  # the thesis's plain feedback oscillates ever wider


def test_the_integral_sums_the_pd_term_and_stops_when_frozen_or_at_its_limit():
    gains = ControllerParams()
    pd = (0.0, 0.0, 0.5)  # a steady shortfall: the vehicle sags below its setpoint
    i = (0.0, 0.0, 0.0)
    for _ in range(250):  # one second at 250 Hz
        i = integrate(i, pd, 0.004, gains, frozen=False)
    assert i[2] == pytest.approx(gains.position_i * 0.5, rel=1e-9)
    assert integrate(i, pd, 0.004, gains, frozen=True) == i
    for _ in range(10000):
        i = integrate(i, pd, 0.004, gains, frozen=False)
    assert i[2] == pytest.approx(gains.integral_limit_m_s2)


def test_a_saturated_command_is_flagged_so_that_the_integral_does_not_wind_up():
    far_below = Setpoint((0.0, 0.0, -50.0))  # asks for a fall faster than 0.8 g
    unlimited = ControllerParams(vertical_accel_limit_m_s2=100.0)
    out = control(LEVEL, far_below, (0.0, 0.0, 0.0), V, unlimited)
    assert out.saturated
    near = Setpoint((0.0, 0.0, 1.01))
    out = control(LEVEL, near, (0.0, 0.0, 0.0), V, ControllerParams())
    assert not out.saturated and out.pd_acceleration_m_s2[2] == pytest.approx(0.36)


def test_the_vertical_loop_is_stiffer_than_the_horizontal_one_by_default():
    """a0 = 36, a1 = 12 along z (the spring that holds the vehicle in the ground effect),
    6 and 6 across; `GFX_POS_Z_*` and `GFX_POS_*` set each; the vertical term is limited."""
    moving = FlightState((0.0, 0.0, 1.0), (0.1, 0.0, 0.1), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    out = control(moving, Setpoint((0.01, 0.0, 1.01)), (0.0, 0.0, 0.0), V, ControllerParams())
    assert out.pd_acceleration_m_s2 == pytest.approx(
        (6 * 0.01 - 6 * 0.1, 0.0, 36 * 0.01 - 12 * 0.1)
    )
    # a large error asks for no more than the vertical limit (4 m/s^2), either way
    far = control(LEVEL, Setpoint((0.0, 0.0, 2.0)), (0.0, 0.0, 0.0), V, ControllerParams())
    assert far.pd_acceleration_m_s2[2] == 4.0 and not far.saturated
    far = control(LEVEL, Setpoint((0.0, 0.0, 0.5)), (0.0, 0.0, 0.0), V, ControllerParams())
    assert far.pd_acceleration_m_s2[2] == -4.0
    soft = ControllerParams(vertical_p=6.0, vertical_d=6.0)
    out = control(moving, Setpoint((0.01, 0.0, 1.01)), (0.0, 0.0, 0.0), V, soft)
    assert out.pd_acceleration_m_s2[2] == pytest.approx(6 * 0.01 - 6 * 0.1)


def test_a_new_model_takes_over_what_the_integral_held_and_no_more():
    """Bumpless transfer: the integral held -0.03 m/s^2 of a ground effect the old model
    missed; a model that now predicts 0.02 of it leaves -0.01, one that predicts more than
    the integral held leaves 0 (never past it), a change the other way leaves it alone."""
    assert handover((0.0, 0.0, -0.03), (0.0, 0.0, 0.02)) == pytest.approx((0.0, 0.0, -0.01))
    assert handover((0.0, 0.0, -0.03), (0.0, 0.0, 0.05)) == (0.0, 0.0, 0.0)
    assert handover((0.01, 0.0, -0.03), (0.02, 0.0, -0.01)) == (0.01, 0.0, -0.03)


def test_a_replaced_model_hands_over_its_new_prediction_per_mass():
    """A model that now predicts 1 mN more lift than the old one at the same state takes
    1 mN / m of what the integral held."""
    m = V.mass_kg
    after = model_handover((0.0, 0.0, -0.03), (0.0, 0.0, 0.002), (0.0, 0.0, 0.001), m)
    assert after == pytest.approx((0.0, 0.0, -0.03 + 0.001 / m))


def test_the_integral_holds_on_the_ground_in_contact_or_saturated_and_runs_in_the_air():
    rest = 0.0126

    def frozen(air=True, takeoff=False, height=0.5, contact=False, saturated=False):
        return integral_frozen(air, takeoff, height, rest, contact, saturated)

    assert not frozen()  # flying: it runs
    assert frozen(air=False)  # disarmed, landed: it holds
    assert frozen(height=rest + 0.001)  # on the ground while flying or landing
    assert not frozen(takeoff=True, height=rest)  # a heavy vehicle winds it up to leave
    assert frozen(contact=True) and frozen(saturated=True)


def test_the_jerk_limit_moves_a_vector_towards_the_wanted_one_at_most_jerk_times_dt():
    gains = ControllerParams(max_jerk_m_s3=20.0)
    assert jerk_limited((0.0, 0.0), (0.01, 0.0), 0.004, gains) == (0.01, 0.0)  # within reach
    step = jerk_limited((1.0, 0.0), (4.0, 4.0), 0.004, gains)
    assert math.hypot(step[0] - 1.0, step[1]) == pytest.approx(0.08)
    assert step[1] / (step[0] - 1.0) == pytest.approx(4.0 / 3.0)  # the change keeps its direction
    assert jerk_limited((1.0, 0.0), (4.0, 4.0), 0.004, ControllerParams(max_jerk_m_s3=0.0)) == (
        4.0,
        4.0,
    )


def test_a_jumping_setpoint_tilts_the_vehicle_at_the_jerk_limit_and_not_at_once():
    """A waypoint 1 m east appears: without a previous step the position term is a0 * 1 m at
    once; after a step with none, it grows by the jerk limit times dt, and the velocity term
    passes unlimited (it moves with the vehicle, not with the setpoint)."""
    gains = ControllerParams()
    east = Setpoint((1.0, 0.0, 1.0))
    at_once = control(LEVEL, east, (0.0, 0.0, 0.0), V, gains)
    assert at_once.position_term_m_s2 == pytest.approx((gains.position_p, 0.0))
    shaped = control(LEVEL, east, (0.0, 0.0, 0.0), V, gains, (0.0, 0.0, 0.0), (0.0, 0.0), 0.004)
    assert shaped.position_term_m_s2 == pytest.approx((gains.max_jerk_m_s3 * 0.004, 0.0))
    assert 0.0 < shaped.desired_pitch_rad < at_once.desired_pitch_rad
    assert not shaped.saturated  # a delay, not a saturation: the integral runs on
    moving = FlightState((0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    out = control(
        moving, Setpoint((0.0, 0.0, 1.0)), (0.0, 0.0, 0.0), V, gains, (0, 0, 0), (0, 0), 0.004
    )
    assert out.pd_acceleration_m_s2[0] == pytest.approx(-gains.position_d)  # velocity term whole
    assert out.pd_acceleration_m_s2[2] == pytest.approx(0.0)


def test_landing_contact_needs_a_landing_setpoint_below_and_a_low_thrust_demand():
    from autopilot.control.land_detector import LandDetectorParams, landing_contact

    params, rest = LandDetectorParams(), 0.0126
    # landing, 3 cm up, still, the setpoint 2 cm below and the controller pushing down
    assert landing_contact(rest + 0.03, rest, 0.0, 0.05, 0.03, -0.5, params)
    assert not landing_contact(rest + 0.03, rest, 0.0, 0.05, None, -0.5, params)  # not landing
    assert not landing_contact(rest + 0.03, rest, 0.0, 0.05, 0.03, 0.0, params)  # full lift
    assert not landing_contact(rest + 0.03, rest, 0.2, 0.05, 0.03, -0.5, params)  # descending
    # rotors off (no command): no lift demanded at all
    assert landing_contact(rest, rest, 0.0, 0.05, 0.03, None, params)
