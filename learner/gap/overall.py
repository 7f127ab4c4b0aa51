"""Whole-flight summaries of the force residual that no regime bin names: a constant
horizontal force fixed in the world frame (wind, a tunnel's mean flow), and a trend of the
vertical residual with time since take-off (battery sag, warming motors). Each comes with
per-flight figures, a bootstrap interval over flights or blocks of flight, the noise floor
of learner/gap/floor.py, and a rule sentence when it clears it. JSON-able dicts throughout.

Directions are in the log's world frame, ENU as the flight logs are read: 0 deg along +x
(east), counterclockwise (90 deg = +y, north).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from learner.gap.flightdata import FlightData
from learner.gap.floor import (
    K_SE,
    RESAMPLES,
    bootstrap_units,
    ci95,
    noise_level,
    noise_se,
    se_of,
    unit_sums,
)
from learner.gap.stats import bootstrap_mean, bootstrap_p, wald_p
from simbridge.vehicle import Vehicle

ALPHA = 0.05
MIN_FORCE_SHARE = 0.001  # absolute floor of a constant force (share of the weight)
MIN_SLOPE_SHARE_PER_MIN = 0.001  # absolute floor of a trend (share of the weight per minute)
# Flights agree on a constant force when each one's own mean points within this of the
# pooled direction and is significant along it.
CONSISTENT_DEG = 45.0
# Below this heading spread a force fixed in the world and one fixed in the body (an
# accelerometer bias, a centre-of-mass offset) look the same.
MIN_YAW_SPREAD_DEG = 20.0


def _direction_deg(x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
    return np.degrees(np.arctan2(y, x)) % 360.0


def _wrap_deg(a: np.ndarray | float) -> np.ndarray:
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


def _yaw_spread_deg(flights: list[FlightData]) -> float:
    """Circular sd of the heading (body x projected on the ground) over every row."""
    rot = np.concatenate([d.rotation for d in flights])
    yaw = np.arctan2(rot[:, 1, 0], rot[:, 0, 0])
    r = float(np.hypot(np.mean(np.cos(yaw)), np.mean(np.sin(yaw))))
    return float(np.degrees(np.sqrt(-2.0 * np.log(max(r, 1e-12)))))


def _horizontal_draws(
    flights: list[FlightData], series: list[np.ndarray], rng: np.random.Generator
) -> np.ndarray:
    """(RESAMPLES, 2) bootstrap draws of the mean of the (N, 2) `series`."""
    units = bootstrap_units(flights)
    sums, counts = unit_sums(series, units)
    return np.column_stack(
        [bootstrap_mean(sums[:, :, j], counts, RESAMPLES, rng)[:, 0] for j in range(2)]
    )


def world_frame_summary(
    flights: list[FlightData], residuals: list[np.ndarray], vehicle: Vehicle, seed: int = 0
) -> dict[str, Any]:
    """The mean horizontal residual in the world frame: pooled and per flight (N, share of
    the weight, direction), with intervals, a test, the flights' agreement and a rule."""
    rng = np.random.default_rng(seed)
    weight = vehicle.weight_n
    xy = [r[:, :2] for r in residuals]
    rows = sum(len(a) for a in xy)
    mean = np.concatenate(xy).mean(axis=0)
    draws = _horizontal_draws(flights, xy, rng)
    size = float(np.hypot(*mean))
    direction = float(_direction_deg(*mean))
    size_draws = np.hypot(draws[:, 0], draws[:, 1])
    dir_draws = direction + _wrap_deg(_direction_deg(draws[:, 0], draws[:, 1]) - direction)
    sd, ess = noise_level(xy, flights)
    floor_n = max(
        K_SE * se_of(size_draws),
        K_SE * float(np.max(noise_se(sd, rows, ess))),
        MIN_FORCE_SHARE * weight,
    )
    p = wald_p(mean, np.cov(draws.T))
    unit = mean / size if size > 0 else np.zeros(2)
    per_flight = []
    for d, a in zip(flights, xy, strict=True):
        m = a.mean(axis=0)
        off_deg = abs(float(_wrap_deg(_direction_deg(*m) - direction)))
        along = _horizontal_draws([d], [a], rng) @ unit  # this flight's blocks
        lo, hi = ci95(along)
        per_flight.append({
            "flight": d.name,
            "mean_n": [float(m[0]), float(m[1])],
            "size_n": float(np.hypot(*m)),
            "share": float(np.hypot(*m) / weight),
            "direction_deg": float(_direction_deg(*m)),
            "along_pooled_n": float(m @ unit),
            "along_pooled_ci95_n": [lo, hi],
            "agrees": bool(lo > 0.0 and off_deg <= CONSISTENT_DEG),
        })  # fmt: skip
    pairs = zip(flights, residuals, strict=True)
    body = np.concatenate([np.einsum("nji,nj->ni", d.rotation, r)[:, :2] for d, r in pairs])
    out: dict[str, Any] = {
        "mean_n": [float(mean[0]), float(mean[1])],
        "size_n": size,
        "share": size / weight,
        "direction_deg": direction,
        "size_ci95_n": list(ci95(size_draws)),
        "direction_ci95_deg": [float(x) % 360.0 for x in ci95(dir_draws)],
        "p": p,
        "floor_n": floor_n,
        "significant": bool(p < ALPHA and size >= floor_n),
        "consistent": bool(len(flights) > 1 and all(f["agrees"] for f in per_flight)),
        "flights": per_flight,
        "body_frame_mean_n": [float(x) for x in body.mean(axis=0)],
        "yaw_spread_deg": _yaw_spread_deg(flights),
    }
    out["rule"] = world_rule(out)
    return out


def world_rule(s: dict[str, Any]) -> str | None:
    """'everywhere: a constant horizontal force of 1.2 N (4.6% of the weight) towards 166 deg
    in the world frame (...)', or None below the floor."""
    if not s["significant"]:
        return None
    lo, hi = s["size_ci95_n"]
    dlo, dhi = s["direction_ci95_deg"]
    n = len(s["flights"])
    agree = sum(f["agrees"] for f in s["flights"])
    text = (
        f"everywhere: a constant horizontal force of {s['size_n']:.3g} N ({s['share'] * 100:.1f}% "
        f"of the weight) towards {s['direction_deg']:.0f} deg in the world frame (0 = +x, "
        f"counterclockwise; 95% CI {lo:.3g} to {hi:.3g} N, {dlo:.0f} to {dhi:.0f} deg; "
        f"{agree} of {n} flights agree)"
    )
    if s["yaw_spread_deg"] < MIN_YAW_SPREAD_DEG:
        text += (
            f"; the heading hardly changed (sd {s['yaw_spread_deg']:.0f} deg): a force fixed in "
            "the body (an accelerometer bias, a centre-of-mass offset) would look the same"
        )
    return text


def trend_summary(
    flights: list[FlightData], residuals: list[np.ndarray], vehicle: Vehicle, seed: int = 0
) -> dict[str, Any]:
    """The slope of the vertical residual (share of the weight) against time since take-off
    (per minute): per flight, and pooled within flights (each its own intercept), with a
    bootstrap interval, the noise floor and a rule."""
    rng = np.random.default_rng(seed)
    weight = vehicle.weight_n
    xy_terms, xx_terms, per_flight, centred = [], [], [], []
    for d, r in zip(flights, residuals, strict=True):
        t = (d.time_s - d.time_s[0]) / 60.0
        y = r[:, 2] / weight
        tc, yc = t - t.mean(), y - y.mean()
        xy_terms.append(tc * yc)
        xx_terms.append(tc * tc)
        centred.append(yc)
        sxx = float(np.sum(tc * tc))
        per_flight.append({
            "flight": d.name,
            "minutes": float(t[-1]),
            "slope_share_per_min": float(np.sum(tc * yc) / sxx) if sxx > 0 else 0.0,
        })  # fmt: skip
    units = bootstrap_units(flights)
    sxy, _ = unit_sums(xy_terms, units)
    sxx, _ = unit_sums(xx_terms, units)
    total_xx = float(sxx.sum())
    slope = float(sxy.sum() / total_xx) if total_xx > 0 else 0.0
    draws = bootstrap_mean(sxy[:, :, 0], sxx[:, :, 0], RESAMPLES, rng)[:, 0]
    p = float(bootstrap_p(draws[:, None])[0])
    sd, ess = noise_level(centred, flights)
    se_noise = float(sd[0] / np.sqrt(max(total_xx * ess, 1e-12)))
    floor = max(K_SE * se_of(draws), K_SE * se_noise, MIN_SLOPE_SHARE_PER_MIN)
    out: dict[str, Any] = {
        "slope_share_per_min": slope,
        "slope_n_per_min": slope * weight,
        "ci95_share_per_min": list(ci95(draws)),
        "p": p,
        "floor_share_per_min": floor,
        "significant": bool(p < ALPHA and abs(slope) >= floor and total_xx > 0),
        "flights": per_flight,
    }
    out["rule"] = trend_rule(out)
    return out


def trend_rule(s: dict[str, Any]) -> str | None:
    """'the vertical residual falls by 0.8% of the weight per minute since take-off (...)'."""
    if not s["significant"]:
        return None
    slope = s["slope_share_per_min"]
    lo, hi = s["ci95_share_per_min"]
    minutes = [f["minutes"] for f in s["flights"]]
    span = (
        f"{min(minutes):.1f} to {max(minutes):.1f} min"
        if len(minutes) > 1
        else f"{minutes[0]:.1f} min"
    )
    return (
        f"the vertical residual {'rises' if slope > 0 else 'falls'} by {abs(slope) * 100:.2f}% "
        f"of the weight per minute since take-off (95% CI {lo * 100:+.2f} to {hi * 100:+.2f}%; "
        f"{len(minutes)} flights of {span})"
    )
