"""The gap diagnosis's statistics, geometry and log reading on synthetic data (no flights)."""

from __future__ import annotations

import numpy as np
import pytest

from learner.flightlogs.flightlog import FlightLog, write_log
from learner.flightlogs.readers import read_log
from learner.flightlogs.tables import ColumnMapping
from learner.gap.geometry import height_below_m, wall_distances_m
from learner.gap.stats import (
    benjamini_hochberg,
    bootstrap_mean,
    bootstrap_p,
    effective_sample_size,
    holm,
)
from simbridge.config import ConfigError
from simbridge.effects.ground import thrust_gain, thrust_gain_array
from simbridge.frames import quat_enu_flu_to_ned_frd
from simbridge.world import Box

Q_LEVEL_NED = quat_enu_flu_to_ned_frd((1.0, 0.0, 0.0, 0.0))


def test_effective_sample_size_of_an_ar1_series_matches_theory() -> None:
    rng = np.random.default_rng(1)
    phi, n = 0.9, 20000
    x = np.zeros(n)
    e = rng.normal(size=n)
    for i in range(1, n):
        x[i] = phi * x[i - 1] + e[i]
    expected = n * (1 - phi) / (1 + phi)  # about 1050
    assert effective_sample_size(x) == pytest.approx(expected, rel=0.25)
    assert effective_sample_size(rng.normal(size=n)) == pytest.approx(n, rel=0.1)


def test_flight_bootstrap_interval_covers_the_mean_and_widens_with_flight_spread() -> None:
    rng = np.random.default_rng(2)
    offsets = rng.normal(0.0, 1.0, 8)  # each flight its own offset: samples are correlated
    sums = np.array([[100 * (0.5 + o)] for o in offsets])
    counts = np.full((8, 1), 100.0)
    draws = bootstrap_mean(sums, counts, 4000, rng)
    lo, hi = np.percentile(draws[:, 0], [2.5, 97.5])
    assert lo < sums.sum() / counts.sum() < hi
    assert hi - lo > 0.8  # as wide as the flights' spread, not the samples' count
    assert bootstrap_p(np.full((1000, 1), 3.0))[0] < 0.01
    assert bootstrap_p(rng.normal(0, 1, (1000, 1)))[0] > 0.2


def test_multiple_comparison_corrections() -> None:
    p = np.array([0.01, 0.04, 0.03, 0.2])
    assert holm(p) == pytest.approx([0.04, 0.09, 0.09, 0.2])
    assert benjamini_hochberg(p) == pytest.approx([0.04, 0.16 / 3, 0.16 / 3, 0.2])


def test_array_ground_effect_gain_is_the_simulators_formula() -> None:
    heights = np.array([0.005, 0.02, 0.05, 0.3, np.inf])
    got = thrust_gain_array(heights, 2.0, 0.047, 0.03)
    assert got == pytest.approx([thrust_gain(h, 2.0, 0.047, 0.03) for h in heights])


def test_geometry_heights_and_walls() -> None:
    box = Box(center_m=(1.0, 0.0, 0.05), size_m=(0.3, 0.3, 0.1), yaw_deg=45.0)
    pts = np.array([[1.0, 0.0, 0.3], [0.0, 0.0, 0.3], [1.0, 0.0, 5.0]])
    assert height_below_m(pts, (box,), 3.0) == pytest.approx([0.2, 0.3, np.inf])
    wall = Box(center_m=(0.0, 0.6, 1.0), size_m=(4.0, 0.1, 2.0))
    d = wall_distances_m(np.array([[0.0, 0.3, 0.5], [0.0, -0.3, 0.5]]), (wall,), 0.5)
    assert d[0] == pytest.approx([np.inf, np.inf, 0.25, np.inf])
    assert np.all(np.isinf(d[1]))


def test_csv_with_renamed_columns_units_and_ned_frame(tmp_path) -> None:
    n = 20
    t = np.arange(n) * 0.01
    log = FlightLog(
        "ours", t, np.tile([1.0, 2.0, 3.0], (n, 1)), np.tile([0.1, 0.2, -0.3], (n, 1)),
        np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), np.tile([0.01, 0.02, 0.03], (n, 1)),
        np.full((n, 4), 76.0),
    )  # fmt: skip
    path = write_log(log, tmp_path / "ours.csv")
    text = path.read_text().splitlines()
    # rename, rescale to ms and rpm, write the position in NED
    header = text[1].split(",")
    rows = [list(map(float, r.split(","))) for r in text[2:]]
    i = {h: k for k, h in enumerate(header)}
    out = ["T,N,E,D,vn,ve,vd,qw,qx,qy,qz,p,q,r,m0,m1,m2,m3"]
    for r in rows:
        out.append(",".join(str(v) for v in (
            r[i["time_s"]] * 1000, r[i["y_m"]], r[i["x_m"]], -r[i["z_m"]],
            r[i["vy_m_s"]], r[i["vx_m_s"]], -r[i["vz_m_s"]],
            *Q_LEVEL_NED,
            r[i["p_rad_s"]], -r[i["q_rad_s"]], -r[i["r_rad_s"]],
            *(r[i[f"n{k}_rad_s"]] * 60 / (2 * np.pi) for k in range(4)),
        )))  # fmt: skip
    theirs = tmp_path / "theirs.csv"
    theirs.write_text("\n".join(out) + "\n")
    names = dict(zip(
        ["time_s", "x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s", "p_rad_s", "q_rad_s",
         "r_rad_s", "n0_rad_s", "n1_rad_s", "n2_rad_s", "n3_rad_s"],
        ["T", "N", "E", "D", "vn", "ve", "vd", "p", "q", "r", "m0", "m1", "m2", "m3"], strict=True,
    ))  # fmt: skip
    units = {"time_s": "ms"} | {f"n{k}_rad_s": "rpm" for k in range(4)}
    mapping = ColumnMapping(names=names, units=units, frame="ned_frd")
    got = read_log(theirs, mapping)
    assert got.time_s == pytest.approx(t)
    assert got.position_m[0] == pytest.approx([1.0, 2.0, 3.0])
    assert got.velocity_m_s[0] == pytest.approx([0.1, 0.2, -0.3])
    assert got.body_rates_rad_s[0] == pytest.approx([0.01, 0.02, 0.03])
    assert got.rotor_speeds_rad_s[0] == pytest.approx([76.0] * 4)
    assert abs(got.quaternion[0, 0]) == pytest.approx(1.0)  # level, yaw 0 in ENU
    with pytest.raises(ConfigError, match="missing column 'T'"):
        read_log(path, mapping)
    with pytest.raises(ConfigError, match=r"units\.time_s"):
        ColumnMapping(units={"time_s": "fortnights"})


def test_block_sandwich_interval_matches_the_spread_under_correlated_misfit() -> None:
    """A slope fitted through a slowly varying misfit (AR(1), phi 0.98): the white-noise
    standard error is far too small; the 1 s block sandwich is about the true spread."""
    from scipy.signal import lfilter

    from learner.gap.fit import _block_ids, block_sandwich

    rng = np.random.default_rng(3)
    t = np.arange(0.0, 60.0, 0.01)
    x = np.sin(0.7 * t) + 0.3 * np.sin(3.1 * t)
    slopes, naive, robust = [], [], []
    for _ in range(200):
        e = lfilter([1.0], [1.0, -0.98], rng.normal(0.0, 0.05, len(t)))
        y = 2.0 * x + e
        jac = x[:, None]
        bread = np.linalg.inv(jac.T @ jac)
        b = float((bread @ jac.T @ y)[0])
        r = jac[:, 0] * b - y
        slopes.append(b)
        naive.append(np.sqrt(bread[0, 0] * (r @ r) / (len(t) - 1)))
        robust.append(np.sqrt(block_sandwich(bread, jac, r, _block_ids(t, 0))[0, 0]))
    spread = np.std(slopes)
    assert np.median(naive) < 0.3 * spread
    assert 0.75 * spread < np.median(robust) < 1.25 * spread


def _robust_slope_p(t: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares slope of y on x; Wald p-values with the white and the block covariance."""
    from learner.gap.fit import _block_ids, block_sandwich
    from learner.gap.stats import wald_p

    jac = x[:, None]
    bread = np.linalg.inv(jac.T @ jac)
    b = bread @ jac.T @ y
    r = jac @ b - y
    white = bread * (r @ r) / (len(t) - 1)
    robust = block_sandwich(bread, jac, r, _block_ids(t, 0))
    return wald_p(b, white), wald_p(b, np.maximum(robust, white))


def test_block_robust_wald_test_keeps_its_level_under_correlated_misfit_and_finds_effects() -> None:
    """The selection rule's significance test: on a slowly varying misfit with no effect the
    white-noise test cries wolf most of the time; the block-robust one keeps near its level,
    and still finds a slope of 0.15 in a misfit of standard deviation 0.25."""
    from scipy.signal import lfilter

    from learner.gap.selection import selected

    rng = np.random.default_rng(5)
    t = np.arange(0.0, 60.0, 0.01)
    x = np.sin(0.7 * t) + 0.3 * np.sin(3.1 * t)
    alpha = 0.05
    naive_fp = robust_fp = found = 0
    runs = 200
    for _ in range(runs):
        e = lfilter([1.0], [1.0, -0.98], rng.normal(0.0, 0.05, len(t)))  # sd 0.25
        p_naive, p_robust = _robust_slope_p(t, x, e)
        naive_fp += p_naive < alpha
        robust_fp += p_robust < alpha
        found += selected(1.0, _robust_slope_p(t, x, 0.15 * x + e)[1], 1, 0.01)
    assert naive_fp / runs > 0.5
    assert robust_fp / runs < 0.15  # 0.11 here: 60 blocks make the sandwich a bit small
    assert found / runs > 0.8


def test_selection_rule_needs_criterion_significance_and_held_out_gain() -> None:
    from learner.gap.selection import ALPHA, selected

    assert selected(5.0, 0.2 * ALPHA, tried=3, cv_gain=0.001)
    assert not selected(5.0, 0.5 * ALPHA, tried=3, cv_gain=0.001)  # Bonferroni over 3 tried
    assert not selected(-1.0, 1e-9, tried=1, cv_gain=0.5)  # the criterion rose
    assert not selected(5.0, 1e-9, tried=1, cv_gain=-1e-4)  # worse on the flights left out


def test_selection_rule_ignores_significant_but_tiny_effects() -> None:
    """A 1 ms IMU delay (an eighth of the catalogue's 8 ms) riding on a large effect's misfit is
    not reported however significant; a ground effect raised from the nominal rho 1 to 1.6 is."""
    from learner.gap.selection import MIN_SIZE, effect_size, selected

    tiny = effect_size("sensor_latency", np.array([0.001]), {})
    assert tiny < MIN_SIZE
    assert not selected(50.0, 1e-30, tried=5, cv_gain=0.001, size=tiny)
    ground = effect_size("ground_effect", np.array([1.6]), {"ground_effect": np.array([1.0])})
    assert ground == pytest.approx(0.6)
    assert selected(50.0, 1e-30, tried=5, cv_gain=0.001, size=ground)


def test_selection_rule_rejects_a_fit_on_its_bounds() -> None:
    from learner.gap.selection import at_bound, selected

    assert at_bound("thrust_mass", np.array([-0.5]))
    assert not at_bound("thrust_mass", np.array([0.04]))
    assert not at_bound("rotor_drag", np.array([4e-5, 4e-5, 0.0]))  # no drag along z
    assert not selected(50.0, 1e-30, tried=1, cv_gain=0.01, size=10.0, interior=False)


def test_the_measured_noise_floor_is_the_white_one_for_white_noise_and_more_for_coloured() -> None:
    from learner.gap.residual import gap_over_floor_ms, measured_floor_ms, white_floor_ms

    rng = np.random.default_rng(3)
    n, dt, sd = 60000, 0.01, 0.005  # 100 Hz, a 0.1 s window of 10 rows, 5 mN per component
    segment = np.zeros(n, dtype=int)
    white = rng.normal(0.0, sd, (n, 3))
    white_floor = white_floor_ms(sd**2, dt)
    assert white_floor == pytest.approx(3 * sd**2 / 10)
    assert measured_floor_ms(white, segment, dt) == pytest.approx(white_floor, rel=0.05)
    coloured = np.zeros((n, 3))  # AR(1) with a 0.1 s correlation time, the same variance
    phi = np.exp(-dt / 0.1)
    for k in range(1, n):
        coloured[k] = phi * coloured[k - 1] + np.sqrt(1 - phi**2) * white[k]
    assert measured_floor_ms(coloured, segment, dt) > 3 * white_floor
    # a steady force is no noise: its gap stands out of the measured floor whole
    steady = coloured + np.array([0.0, 0.0, 0.02])
    floor = measured_floor_ms(steady, segment, dt)
    assert floor == pytest.approx(measured_floor_ms(coloured, segment, dt))
    assert np.sqrt(gap_over_floor_ms(steady, segment, dt, floor)) == pytest.approx(0.02, rel=0.05)


def test_the_residual_noise_is_the_noise_with_a_few_rows_of_a_catapulting_force() -> None:
    """A few rows of a force that changes within a row or two (a ground effect near its
    cut-off, an impact) are no noise: they once made 5.6 mN read as 84 mN and every candidate
    'not excited'. Without them the estimate is the plain variance's; for noise alone the
    trimmed variance is the plain one."""
    from learner.gap.stats import trimmed_variance

    rng = np.random.default_rng(5)
    noise = rng.normal(0.0, 0.0056, (12000, 3))
    assert trimmed_variance(noise) == pytest.approx(float(np.var(noise)), rel=1e-12)
    spiked = noise.copy()
    spiked[0, 2], spiked[1, 2], spiked[4000, 2] = 18.7, 2.8, 0.3
    assert np.sqrt(np.var(spiked)) > 0.05  # the plain variance: ten times the noise
    assert np.sqrt(trimmed_variance(spiked)) == pytest.approx(0.0056, rel=0.03)


def test_a_model_force_is_filtered_as_a_differentiated_acceleration_is() -> None:
    """Without an accelerometer the log's acceleration is its velocity's Savitzky-Golay
    derivative; the model's force goes through the same (summed into a velocity, then that
    derivative): a steady or ramping force unchanged, a step smoothed exactly as the log's
    acceleration is. Unfiltered, the smoothing was fitted as a motor lag (8.5 ms) and a
    flatter thrust curve (0.95) in worlds with neither."""
    import dataclasses

    from learner.gap.flightdata import as_differentiated, differentiate

    n, dt = 400, 0.01
    t = np.arange(n) * dt
    segment = np.zeros(n, dtype=int)
    d = dataclasses.make_dataclass("D", ["time_s", "segment", "dt_s"])(t, segment, dt)
    ramp = np.column_stack([0.3 + 0.5 * t, np.zeros(n), np.ones(n)])
    inner = slice(10, n - 10)  # the derivative's edges are one-sided
    # each row's force is its period's mean: the derivative at the row's time reads the force
    # there, half a period on
    expected = ramp[inner] + [0.5 * dt / 2, 0.0, 0.0]
    np.testing.assert_allclose(as_differentiated(ramp, d)[inner], expected, atol=1e-9)
    step = np.zeros((n, 3))
    step[200:, 2] = 1.0
    velocity = np.cumsum(step * dt, axis=0)  # what a log's velocity would hold
    np.testing.assert_allclose(as_differentiated(step, d), differentiate(t, velocity, segment, dt))
    assert 0.0 < as_differentiated(step, d)[199, 2] < 1.0  # smoothed across the step
