"""The effects as pure functions, against their equations."""

from __future__ import annotations

import math

import pytest

from simbridge.effects import parse_effects
from simbridge.effects.actuators import motor_lag_step
from simbridge.effects.drag import (
    BodyDragParams,
    RotorDragParams,
    WindParams,
    body_drag_n,
    rotor_drag_n,
    wind_velocity_m_s,
)
from simbridge.effects.ground import (
    MAX_CUTOFF_GAIN,
    GroundEffectParams,
    cutoff_height_m,
    ground_effect_force_n,
    hover_rotor_speed_in_ground_effect_rad_s,
    singular_height_m,
)
from simbridge.effects.proximity import WallEffectParams, wall_force_n
from simbridge.effects.sensor_errors import delay_steps
from simbridge.rotors import (
    prioritised_rotor_forces,
    rotor_forces_for,
    rotor_forces_n,
    rotor_speeds_for,
    thrust_and_moments,
)
from simbridge.vehicle import load_vehicle

R = 0.047
C_T = 2.39e-5


def equation_3_4(n: float, z: float, rho: float) -> float:
    return C_T * n**2 * (1.0 / (1.0 - rho * (R / (4.0 * z)) ** 2) - 1.0)


@pytest.mark.parametrize(("rho", "cutoff"), [(1.0, 0.02), (2.0, 0.02), (0.5, 0.01), (4.0, 0.03)])
def test_cutoff_is_the_smallest_two_decimal_height_above_the_singularity(rho, cutoff):
    assert cutoff_height_m(rho, R) == pytest.approx(cutoff)
    assert cutoff_height_m(rho, R) > singular_height_m(rho, R) > cutoff_height_m(rho, R) - 0.01


@pytest.mark.parametrize("rho", [2.5, 2.7, 2.8, 2.88, 5.9, 6.0, 12.0])
@pytest.mark.parametrize("radius", [R, 0.1524])  # the nano's, a 12-inch propeller's
@pytest.mark.parametrize("rho_scale", [1.0, 4.0])
def test_cutoff_never_multiplies_a_rotors_thrust_more_than_tenfold(rho, radius, rho_scale):
    """Just above the singularity the thesis's rule would (29 times at rho 2.8): such rho
    take the next centimetre, where the gain is modest."""
    rho = min(rho * rho_scale, 50.0)
    cut = cutoff_height_m(rho, radius)
    r = radius / (4.0 * cut)
    gain = 1.0 / (1.0 - rho * r * r) - 1.0
    assert 0.0 < gain <= MAX_CUTOFF_GAIN
    assert cut > singular_height_m(rho, radius)
    assert round(cut * 100) == pytest.approx(cut * 100)  # whole centimetres still


@pytest.mark.parametrize("rho", [1.0, 2.0])
@pytest.mark.parametrize("z", [0.02, 0.03, 0.05, 0.1, 0.25, 0.5])
def test_ground_effect_is_equation_3_4(rho, z):
    n = 76.0
    assert ground_effect_force_n(C_T * n * n, z, rho, R, 0.02) == pytest.approx(
        equation_3_4(n, z, rho), rel=1e-12
    )


def test_ground_effect_is_constant_below_the_cutoff_and_zero_with_nothing_below():
    at_cutoff = ground_effect_force_n(0.137, 0.02, 2.0, R, 0.02)
    for z in (0.0, 0.005, 0.0166, 0.0199):
        assert ground_effect_force_n(0.137, z, 2.0, R, 0.02) == at_cutoff
    assert ground_effect_force_n(0.137, math.inf, 2.0, R, 0.02) == 0.0
    # rho = 2 at the cut-off: the rotor gains 2.23x its thrust
    assert at_cutoff / 0.137 == pytest.approx(1 / (1 - 2 * (0.047 / 0.08) ** 2) - 1)


def test_a_cutoff_below_the_singularity_is_refused():
    with pytest.raises(ValueError, match="singular height"):
        GroundEffectParams(rho=2.0, cutoff_m=0.015).cutoff_for(R)


def test_hover_speed_in_ground_effect_carries_the_weight():
    weight = 0.056 * 9.81
    for z in (0.03, 0.1, 1.0):
        n = hover_rotor_speed_in_ground_effect_rad_s(weight, C_T, z, 1.0, R, 0.02)
        assert 4 * (C_T * n * n + equation_3_4(n, z, 1.0)) == pytest.approx(weight)


def test_equations_3_5_and_3_6_and_their_inverse():
    forces = rotor_forces_n(C_T, (70.0, 80.0, 75.0, 72.0))
    assert forces[1] == pytest.approx(C_T * 80.0**2)
    k, kz = 0.03164, 0.005964
    t, mx, my, mz = thrust_and_moments(forces, k, kz)
    f0, f1, f2, f3 = forces
    assert t == pytest.approx(f0 + f1 + f2 + f3)
    assert mx == pytest.approx(k * (f0 + f1 - f2 - f3))
    assert my == pytest.approx(k * (-f0 + f1 + f2 - f3))
    assert mz == pytest.approx(kz * (-f0 + f1 - f2 + f3))
    assert rotor_forces_for(t, (mx, my, mz), k, kz) == pytest.approx(forces)
    assert rotor_speeds_for(C_T, forces, 140.0) == pytest.approx((70.0, 80.0, 75.0, 72.0))
    assert rotor_speeds_for(C_T, (-0.1, 0.0, 1.0, 0.1), 140.0) == pytest.approx(
        (0.0, 0.0, 140.0, math.sqrt(0.1 / C_T))
    )


def test_the_mixer_gives_up_yaw_then_thrust_then_tilt_never_the_tilt_direction():
    """Within the rotors' range the plain inverse, bit for bit. Beyond it: the yaw moment
    shrinks first, then the collective thrust is lowered (never raised), and only a tilt
    moment that does not fit is scaled down, in its direction. Clipping each rotor alone
    turned a yaw demand at full tilt into roll and pitch: the 2.7 kg quadrotor with a 60 ms
    motor lag tumbled on its first 3 m/s leg (it now flies the leg and lands)."""
    k, kz, f_max = 0.03164, 0.005964, C_T * 140.0**2
    fit = (0.6, (1e-3, -2e-3, 1e-4))
    assert prioritised_rotor_forces(*fit, k, kz, f_max) == rotor_forces_for(*fit, k, kz)
    # a yaw demand beyond the range: roll, pitch and thrust exact, the yaw what is left
    t, m = 0.6, (2e-3, 1e-3, 5e-3)
    f = prioritised_rotor_forces(t, m, k, kz, f_max)
    assert all(0.0 <= x <= f_max for x in f)
    t2, mx, my, mz = thrust_and_moments(f, k, kz)
    assert (t2, mx, my) == pytest.approx((t, m[0], m[1]))
    assert 0.0 < mz < m[2]
    # low thrust and a tilt demand: the thrust kept, never raised (PX4's airmode off: a
    # vehicle caught on the ground by a corner must be able to settle), the moment scaled
    f = prioritised_rotor_forces(0.05, (4e-3, 0.0, 0.0), k, kz, f_max)
    t2, mx, my, mz = thrust_and_moments(f, k, kz)
    assert min(f) == pytest.approx(0.0, abs=1e-15) and 0.0 < mx < 4e-3
    assert t2 == pytest.approx(0.05) and my == pytest.approx(0.0, abs=1e-15)
    # a high thrust and a tilt demand: the thrust lowered just enough, the moments exact
    f = prioritised_rotor_forces(4 * f_max - 0.01, (4e-3, 0.0, 0.0), k, kz, f_max)
    t2, mx, my, mz = thrust_and_moments(f, k, kz)
    assert max(f) == pytest.approx(f_max) and mx == pytest.approx(4e-3)
    assert t2 < 4 * f_max - 0.01
    # a tilt moment no thrust can give: scaled, its direction kept, yaw given up
    m = (0.04, -0.02, 1e-3)
    f = prioritised_rotor_forces(0.6, m, k, kz, f_max)
    assert all(0.0 <= x <= f_max for x in f)
    _, mx, my, mz = thrust_and_moments(f, k, kz)
    assert mx / my == pytest.approx(m[0] / m[1]) and abs(mx) < m[0]
    assert mz == pytest.approx(0.0, abs=1e-12)


def test_motor_lag_is_the_exact_first_order_response():
    n = 0.0
    for _ in range(20):  # 20 ms with tau = 20 ms: 1 - 1/e of the step
        n = motor_lag_step(n, 100.0, 0.001, 0.02)
    assert n == pytest.approx(100.0 * (1 - math.exp(-1.0)), rel=1e-9)


def test_rotor_drag_opposes_air_relative_velocity_linearly():
    params = RotorDragParams(coefficient_n_s_m=(2e-5, 3e-5, 1e-5))
    f = rotor_drag_n(params, 300.0, (1.0, -2.0, 0.5))
    assert f == pytest.approx((-2e-5 * 300, 3e-5 * 300 * 2, -1e-5 * 300 * 0.5))


def test_body_drag_is_quadratic():
    params = BodyDragParams(
        drag_coefficient=1.2, area_m2=(0.002, 0.003, 0.006), air_density_kg_m3=1.2
    )
    v = (3.0, 4.0, 0.0)
    f = body_drag_n(params, v)
    assert f == pytest.approx(
        (-0.5 * 1.2 * 1.2 * 0.002 * 5 * 3, -0.5 * 1.2 * 1.2 * 0.003 * 5 * 4, 0.0)
    )


def test_wind_constant_and_gusts_with_the_stated_spread():
    calm = WindParams(mean_m_s=(1.0, 0.0, 0.0))
    assert wind_velocity_m_s(calm, 12.3) == (1.0, 0.0, 0.0)
    gusty = WindParams(mean_m_s=(1.0, 0.0, 0.0), gust_std_m_s=0.5, gust_seed=3)
    samples = [wind_velocity_m_s(gusty, 0.01 * k) for k in range(200_000)]  # 2000 s
    for axis, mean in enumerate((1.0, 0.0, 0.0)):
        values = [s[axis] for s in samples]
        mu = sum(values) / len(values)
        sd = math.sqrt(sum((v - mu) ** 2 for v in values) / len(values))
        assert mu == pytest.approx(mean, abs=0.05)
        assert sd == pytest.approx(0.5, rel=0.05)
    assert wind_velocity_m_s(gusty, 7.0) == wind_velocity_m_s(gusty, 7.0)  # pure in time
    other = WindParams(mean_m_s=(1.0, 0.0, 0.0), gust_std_m_s=0.5, gust_seed=4)
    assert wind_velocity_m_s(other, 7.0) != wind_velocity_m_s(gusty, 7.0)


def test_wall_force_points_to_the_wall_and_decays_with_the_inverse_square():
    params = WallEffectParams(gain=0.5, range_m=0.5, min_distance_m=0.02)
    inf = math.inf
    near = wall_force_n(params, 0.55, R, (0.1, inf, inf, inf))  # wall 0.1 m in +x
    far = wall_force_n(params, 0.55, R, (0.2, inf, inf, inf))
    assert near[0] == pytest.approx(0.5 * 0.55 * (R / 0.4) ** 2) and near[1] == 0.0
    assert near[0] / far[0] == pytest.approx(4.0)
    assert wall_force_n(params, 0.55, R, (inf, inf, inf, 0.1))[1] < 0  # wall in -y
    assert wall_force_n(params, 0.55, R, (0.6, inf, inf, inf)) == (0.0, 0.0, 0.0)  # out of range


def test_sensor_delay_in_control_periods():
    assert delay_steps(0.008, 0.004) == 2
    assert delay_steps(0.0, 0.004) == 0


def test_drag_a_world_leaves_out_follows_its_vehicle() -> None:
    """`{name: rotor_drag}` and `{name: body_drag}` without values: the nano's rotor drag at
    the same share of the weight per m/s at hover, and the vehicle's own box. Before, every
    vehicle got the nano's numbers: on a Crazyflie (rotor speeds near 1700 rad/s, not 76) a
    rotor drag of 45% of its weight per m/s, and the nano's 8 cm body on a 60 cm frame."""
    effects = parse_effects([{"name": "rotor_drag"}, {"name": "body_drag"}], "effects")
    shares = {}
    for name in ("nano", "crazyflie2", "quad_2_7kg"):
        vehicle = load_vehicle(name)
        fx = effects.for_vehicle(vehicle)
        n_sum = 4.0 * vehicle.hover_rotor_speed_rad_s
        fx_n, _, _ = rotor_drag_n(fx.rotor_drag, n_sum, (1.0, 0.0, 0.0))
        shares[name] = -fx_n / vehicle.weight_n
        x, y, z = vehicle.body_size_m
        assert fx.body_drag.area_m2 == pytest.approx((y * z, x * z, x * y))
    assert shares["crazyflie2"] == pytest.approx(shares["nano"], rel=1e-9)
    assert shares["quad_2_7kg"] == pytest.approx(shares["nano"], rel=1e-9)
    nano = effects.for_vehicle(load_vehicle("nano"))
    assert nano.rotor_drag.coefficient_n_s_m == (2.2e-5, 2.2e-5, 1.0e-5)  # the file's
    assert nano.body_drag.area_m2 == (0.002016, 0.002016, 0.0064)
    # the Crazyflie's within a factor of two of what Foerster 2015 identified on one
    k_cf = effects.for_vehicle(load_vehicle("crazyflie2")).rotor_drag.coefficient_n_s_m[0]
    assert 0.5 * 9.2e-7 < k_cf < 2.0 * 10.3e-7
    # values a world gives are kept, whatever the vehicle
    given = parse_effects(
        [{"name": "rotor_drag", "coefficient_n_s_m": [1e-6, 2e-6, 3e-6]},
         {"name": "body_drag", "area_m2": [0.1, 0.2, 0.3]}], "effects",
    ).for_vehicle(load_vehicle("quad_2_7kg"))  # fmt: skip
    assert given.rotor_drag.coefficient_n_s_m == (1e-6, 2e-6, 3e-6)
    assert given.body_drag.area_m2 == (0.1, 0.2, 0.3)
