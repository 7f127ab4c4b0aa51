"""Regimes, whole-flight summaries and the per-rotor attribution of the gap diagnosis on
synthetic flights built as FlightData arrays: a constant world-frame force, a thrust that
decays with time, a rotor missing 15% of its thrust, and pure noise (no rule)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from scipy.signal import lfilter

from learner.gap.flightdata import FlightData
from learner.gap.overall import trend_summary, world_frame_summary
from learner.gap.regimes import COMPONENTS, REGIMES, regime_table, regime_variables, rules
from learner.gap.residual import residual_n
from learner.gap.rotors import mixer, rotor_attribution
from simbridge.vehicle import GRAVITY_M_S2, Vehicle, load_vehicle

DT_S = 0.01
NOISE_SHARE = 0.05  # per-component sd of the logged m a, share of the weight
RATE_NOISE_RAD_S = 0.02

Force = Callable[[np.ndarray], np.ndarray]


@pytest.fixture(scope="module")
def vehicle() -> Vehicle:
    return load_vehicle("crazyflie2")


def _none(t: np.ndarray) -> np.ndarray:
    return np.zeros((len(t), 3))


def synthetic_flight(
    vehicle: Vehicle,
    seconds: float,
    seed: int,
    external_n: Force = _none,
    rotor_scale: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0),
) -> tuple[FlightData, np.ndarray]:
    """A slow figure flight, turning in yaw, under an external world-frame force, whose
    rotors deliver `rotor_scale` times the thrust their commands give in the model; the
    logged acceleration carries white and slowly correlated noise. Returns the flight and
    its residual against the nominal (effect-free) model."""
    rng = np.random.default_rng(seed)
    m, w = vehicle.mass_kg, vehicle.weight_n
    t = np.arange(0.0, seconds, DT_S)
    ph = rng.uniform(0, 2 * np.pi, 3)
    amp, om = np.array([1.0, 0.8, 0.2]), np.array([0.6, 0.45, 0.3])
    arg = om * t[:, None] + ph
    p = amp * np.sin(arg) + np.array([0.0, 0.0, 1.0])
    v = amp * om * np.cos(arg)
    a = -amp * om * om * np.sin(arg)
    ext = external_n(t)
    # the thrust gives m a + m g e_z - F_ext; body z along it, heading turning slowly
    f = m * a + np.array([0.0, 0.0, m * GRAVITY_M_S2]) - ext
    thrust = np.linalg.norm(f, axis=1)
    zb = f / thrust[:, None]
    yaw = 0.4 * t + ph[0]
    heading = np.column_stack([np.cos(yaw), np.sin(yaw), np.zeros_like(t)])
    xb = heading - np.sum(heading * zb, axis=1)[:, None] * zb
    xb /= np.linalg.norm(xb, axis=1, keepdims=True)
    rot = np.stack([xb, np.cross(zb, xb), zb], axis=2)
    # rates are noise about zero: no moment on average, so the real rotor forces are equal
    # but for a little white jitter (logs command each rotor on its own)
    real = thrust[:, None] / 4.0 * (1.0 + rng.normal(0.0, 0.005, (len(t), 4)))
    commands = np.sqrt(real / (vehicle.thrust_coefficient_n_s2 * np.asarray(rotor_scale)))
    white = rng.normal(0.0, NOISE_SHARE * w, (len(t), 3))
    slow = lfilter(
        [0.05], [1.0, -0.95], rng.normal(0.0, 0.3 * NOISE_SHARE * w, (len(t), 3)), axis=0
    )
    n = len(t)
    d = FlightData(
        name=f"synthetic_{seed}", time_s=t, dt_s=DT_S, segment=np.zeros(n, dtype=int),
        position_m=p, velocity_m_s=v, velocity_at_m_s=v, rotation=rot,
        rates_rad_s=rng.normal(0.0, RATE_NOISE_RAD_S, (n, 3)), commands_rad_s=commands,
        acceleration_m_s2=a + (white + slow) / m, measured_acceleration=True,
        rotor_heights_m=np.full((n, 4), 1.0), rotor_ceilings_m=np.full((n, 4), np.inf),
        wall_distances_m=np.full((n, 4), np.inf), height_m=p[:, 2], substeps=1, meta={},
    )  # fmt: skip
    return d, residual_n(d, {}, vehicle)


def flights(vehicle: Vehicle, count: int, seconds: float, seed: int, **kw) -> tuple[list, list]:
    pairs = [synthetic_flight(vehicle, seconds, seed * 10 + i, **kw) for i in range(count)]
    return [p[0] for p in pairs], [p[1] for p in pairs]


def test_regime_table_covers_every_component_and_time_since_take_off(vehicle: Vehicle) -> None:
    fl, res = flights(vehicle, 2, 30.0, 7)
    table = regime_table(fl, res, vehicle)
    assert {b.component for b in table} == set(COMPONENTS)
    assert "time_since_takeoff_s" in {b.variable for b in table}
    assert set(regime_variables(fl[0], vehicle)) == set(REGIMES)


def test_a_constant_world_force_gives_the_world_frame_rule_with_its_direction(
    vehicle: Vehicle,
) -> None:
    share, towards = 0.03, np.radians(150.0)
    force = share * vehicle.weight_n * np.array([np.cos(towards), np.sin(towards), 0.0])
    fl, res = flights(vehicle, 3, 30.0, 1, external_n=lambda t: np.tile(force, (len(t), 1)))
    s = world_frame_summary(fl, res, vehicle)
    assert s["significant"] and s["consistent"]
    assert abs((s["direction_deg"] - 150.0 + 180) % 360 - 180) < 8.0
    assert s["share"] == pytest.approx(share, rel=0.2)
    assert s["rule"].startswith("everywhere: a constant horizontal force")
    assert "towards 1" in s["rule"]  # 14x-15x deg
    # the bins repeat the whole flights' force: no regime rule in the world frame for it
    assert not [r for r in rules(regime_table(fl, res, vehicle)) if "world" in r]


def test_a_thrust_decaying_with_time_gives_the_falling_trend_rule(vehicle: Vehicle) -> None:
    rate = -0.02  # share of the weight per minute
    w = vehicle.weight_n

    def sag(t: np.ndarray) -> np.ndarray:
        out = np.zeros((len(t), 3))
        out[:, 2] = rate * w * t / 60.0
        return out

    fl, res = flights(vehicle, 2, 90.0, 2, external_n=sag)
    s = trend_summary(fl, res, vehicle)
    assert s["significant"]
    lo, hi = s["ci95_share_per_min"]
    assert (hi < 0 and lo < rate < hi) or s["slope_share_per_min"] == pytest.approx(rate, rel=0.2)
    assert "falls by" in s["rule"]
    assert any("time since take-off" in r for r in rules(regime_table(fl, res, vehicle)))


def test_the_mixer_is_equation_3_6(vehicle: Vehicle) -> None:
    a, k = vehicle.arm_m, vehicle.yaw_moment_coefficient_m
    np.testing.assert_allclose(mixer(vehicle) @ np.array([0.0, 0.0, 1.0, 0.0]), [1, -a, a, -k])


def test_a_rotor_missing_15_percent_of_its_thrust_is_named(vehicle: Vehicle) -> None:
    fl, res = flights(vehicle, 2, 30.0, 3, rotor_scale=(1.0, 1.0, 0.85, 1.0))
    s = rotor_attribution(fl, {}, vehicle, res)
    by = {r["rotor"]: r for r in s["rotors"]}
    assert by[2]["significant"] and by[2]["thrust_error"] == pytest.approx(-0.15, abs=0.02)
    assert by[2]["ci95"][0] < -0.15 < by[2]["ci95"][1] or abs(by[2]["thrust_error"] + 0.15) < 0.01
    assert not any(by[i]["significant"] for i in (0, 1, 3))
    assert s["rule"].startswith("rotor 2 (back-right) delivers 15% less thrust than modelled")
    assert "the others within" in s["rule"]
    x, y = (a for a in s["axes"] if a["axis"] in "xy")
    assert x["significant"] and y["significant"]  # the missing rotor's moment


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_pure_noise_gives_no_rule(vehicle: Vehicle, seed: int) -> None:
    fl, res = flights(vehicle, 2, 40.0, seed)
    assert rules(regime_table(fl, res, vehicle, seed=seed)) == []
    assert world_frame_summary(fl, res, vehicle, seed=seed)["rule"] is None
    assert trend_summary(fl, res, vehicle, seed=seed)["rule"] is None
    assert rotor_attribution(fl, {}, vehicle, res, seed=seed)["rule"] is None


def test_all_rotors_alike_is_named_as_a_pattern_not_a_rotor(vehicle: Vehicle) -> None:
    fl, res = flights(vehicle, 2, 30.0, 4, rotor_scale=(0.9, 0.9, 0.9, 0.9))
    s = rotor_attribution(fl, {}, vehicle, res)
    assert s["patterns"]["collective"]["share"] == pytest.approx(-0.1, abs=0.015)
    assert "follow one pattern, all four rotors alike" in s["rule"]


def test_summaries_are_json_and_render_their_rules(vehicle: Vehicle) -> None:
    import json

    from learner.gap.summaries import extra_rules, markdown_section, summaries

    fl, res = flights(vehicle, 2, 30.0, 5, rotor_scale=(1.0, 0.85, 1.0, 1.0))
    s = json.loads(json.dumps(summaries(fl, res, {}, vehicle)))
    found = extra_rules(s)
    assert len(found) == 1 and found[0].startswith("rotor 1 (back-left)")
    text = "\n".join(markdown_section(s, with_rules=True))
    assert found[0] in text and "| 1 (back-left) | -15." in text


def test_logs_with_one_collective_command_name_no_rotor(vehicle: Vehicle) -> None:
    import dataclasses

    fl, res = flights(vehicle, 2, 30.0, 6, rotor_scale=(0.9, 0.9, 0.9, 0.9))
    same = [
        dataclasses.replace(d, commands_rad_s=np.repeat(d.commands_rad_s.mean(1)[:, None], 4, 1))
        for d in fl
    ]
    s = rotor_attribution(same, {}, vehicle, res)
    assert not s["per_rotor_logged"] and not any(r["significant"] for r in s["rotors"])
    assert s["rule"].startswith("all four rotors alike: -10") and "no single rotor" in s["rule"]
