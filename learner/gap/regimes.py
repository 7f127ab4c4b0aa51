"""Where the residual is: by regime (height above the surface in rotor radii, distance to
ceiling and walls, speed, vertical speed, thrust over weight, tilt, rate of thrust change,
saturation), with flight-level bootstrap intervals, Benjamini-Hochberg-corrected tests and a
few readable rules."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from learner.gap.flightdata import FlightData
from learner.gap.stats import benjamini_hochberg, bootstrap_mean, bootstrap_p
from simbridge.vehicle import Vehicle

RESAMPLES = 2000
ALPHA = 0.05
MIN_RULE_SHARE = 0.01  # a rule names a bin whose mean residual is at least 1% of the weight
MIN_ROWS = 50

# variable -> (label, unit, bin edges)
REGIMES: dict[str, tuple[str, str, tuple[float, ...]]] = {
    "height_r": ("height above the surface", "rotor radii", (0, 1, 2, 3, 5, 10, 40, np.inf)),
    "ceiling_m": ("distance to the ceiling", "m", (0, 0.1, 0.2, 0.5, 1.0, np.inf)),
    "wall_m": ("distance to a wall", "m", (0, 0.1, 0.2, 0.3, 0.5, np.inf)),
    "speed_m_s": ("speed", "m/s", (0, 0.1, 0.3, 0.6, 1.0, 2.0, np.inf)),
    "vz_m_s": ("vertical speed", "m/s", (-np.inf, -0.3, -0.1, 0.1, 0.3, np.inf)),
    "thrust_weight": ("thrust over weight", "1", (0, 0.8, 0.95, 1.05, 1.2, np.inf)),
    "tilt_deg": ("tilt", "deg", (0, 2, 5, 10, 20, 90)),
    "thrust_rate": ("rate of thrust change", "weights/s", (0, 0.5, 2, 5, np.inf)),
    "saturated": ("rotor saturation", "1", (-0.5, 0.5, 1.5)),
}
COMPONENTS = ("vertical", "horizontal_along_velocity")


def regime_variables(d: FlightData, vehicle: Vehicle) -> dict[str, np.ndarray]:
    """Each row's regime coordinates."""
    thrust = vehicle.thrust_coefficient_n_s2 * np.sum(d.commands_rad_s**2, axis=1)
    tw = thrust / vehicle.weight_n
    rate = np.abs(np.gradient(tw, d.time_s)) if len(tw) > 1 else np.zeros_like(tw)
    n = d.commands_rad_s
    n_max = vehicle.max_rotor_speed_rad_s
    return {
        "height_r": d.height_m / vehicle.rotor_radius_m,
        "ceiling_m": np.min(d.rotor_ceilings_m, axis=1),
        "wall_m": np.min(d.wall_distances_m, axis=1),
        "speed_m_s": np.linalg.norm(d.velocity_m_s, axis=1),
        "vz_m_s": d.velocity_m_s[:, 2],
        "thrust_weight": tw,
        "tilt_deg": np.degrees(np.arccos(np.clip(d.rotation[:, 2, 2], -1.0, 1.0))),
        "thrust_rate": rate,
        "saturated": ((n >= 0.98 * n_max) | (n <= 0.02 * n_max)).any(axis=1).astype(float),
    }


def residual_components(d: FlightData, residual: np.ndarray, vehicle: Vehicle) -> np.ndarray:
    """(N, 2) residual over the weight: vertical, and horizontal along the velocity (a drag
    shows as negative)."""
    vh = d.velocity_m_s[:, :2]
    speed = np.linalg.norm(vh, axis=1)
    unit = np.where(speed[:, None] > 0.05, vh / np.maximum(speed, 1e-9)[:, None], 0.0)
    along = np.sum(residual[:, :2] * unit, axis=1)
    return np.column_stack([residual[:, 2], along]) / vehicle.weight_n


@dataclass(frozen=True)
class RegimeBin:
    variable: str
    low: float
    high: float
    component: str
    rows: int
    flights: int
    mean: float  # residual over weight
    ci_low: float
    ci_high: float
    p: float
    p_adjusted: float = 1.0

    @property
    def significant(self) -> bool:
        return self.p_adjusted < ALPHA and not (self.ci_low <= 0.0 <= self.ci_high)


def regime_table(
    flights: list[FlightData], residuals: list[np.ndarray], vehicle: Vehicle, seed: int = 0
) -> list[RegimeBin]:
    """Per regime bin and component: mean residual over weight with a flight-level bootstrap
    95% interval and a BH-adjusted p-value over every bin tested."""
    rng = np.random.default_rng(seed)
    variables = [regime_variables(d, vehicle) for d in flights]
    comps = [residual_components(d, r, vehicle) for d, r in zip(flights, residuals, strict=True)]
    out: list[RegimeBin] = []
    for name, (_, _, edges) in REGIMES.items():
        bins = [np.digitize(v[name], edges) - 1 for v in variables]
        nb = len(edges) - 1
        counts = np.array([[np.sum(b == k) for k in range(nb)] for b in bins], dtype=float)
        for ci, comp in enumerate(COMPONENTS):
            sums = np.array(
                [
                    [np.sum(c[b == k, ci]) for k in range(nb)]
                    for b, c in zip(bins, comps, strict=True)
                ]
            )
            draws = bootstrap_mean(sums, counts, RESAMPLES, rng)
            p = bootstrap_p(draws)
            for k in range(nb):
                rows = int(counts[:, k].sum())
                if rows < MIN_ROWS:
                    continue
                lo, hi = np.nanpercentile(draws[:, k], [2.5, 97.5])
                out.append(
                    RegimeBin(
                        name,
                        float(edges[k]),
                        float(edges[k + 1]),
                        comp,
                        rows,
                        int(np.sum(counts[:, k] > 0)),
                        float(sums[:, k].sum() / rows),
                        float(lo),
                        float(hi),
                        float(p[k]),
                    )
                )
    if out:
        adjusted = benjamini_hochberg(np.array([b.p for b in out]))
        out = [_with_p(b, a) for b, a in zip(out, adjusted, strict=True)]
    return out


def _with_p(b: RegimeBin, p_adjusted: float) -> RegimeBin:
    from dataclasses import replace

    return replace(b, p_adjusted=float(p_adjusted))


def describe_range(variable: str, low: float, high: float) -> str:
    label, unit, _ = REGIMES[variable]
    if variable == "saturated":
        return "with a rotor saturated" if low > 0 else "with no rotor saturated"
    if np.isinf(high):
        return f"{label} above {low:g} {unit}"
    if np.isinf(low) or (low == 0 and variable != "vz_m_s"):
        return f"{label} below {high:g} {unit}"
    return f"{label} {low:g} to {high:g} {unit}"


def rules(table: list[RegimeBin], limit: int = 6) -> list[str]:
    """The largest significant bins as sentences."""
    sig = [b for b in table if b.significant and abs(b.mean) >= MIN_RULE_SHARE]
    sig.sort(key=lambda b: -abs(b.mean))
    out = []
    for b in sig[:limit]:
        what = "vertical" if b.component == "vertical" else "horizontal (along the velocity)"
        out.append(
            f"{describe_range(b.variable, b.low, b.high)}: the {what} residual is "
            f"{b.mean * 100:+.1f}% of the weight (95% CI {b.ci_low * 100:+.1f} to "
            f"{b.ci_high * 100:+.1f}%, {b.flights} flights, {b.rows} samples)"
        )
    return out
