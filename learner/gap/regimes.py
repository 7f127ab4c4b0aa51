"""Where the residual is: by regime (height above the surface in rotor radii, distance to
ceiling and walls, speed, vertical speed, thrust over weight, tilt, rate of thrust change,
saturation, time since take-off), in every frame physics uses (vertical; horizontal along
and across the velocity; the world's x and y), with bootstrap intervals over flights or
blocks of flight (learner/gap/floor.py), Benjamini-Hochberg-corrected tests and a few
readable rules. A rule needs its bin to clear the noise floor, not a fixed share of the
weight: three standard errors of the bootstrap and of the residual's own noise."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from learner.gap.flightdata import FlightData
from learner.gap.floor import (
    K_SE,
    bootstrap_units,
    noise_level,
    noise_se,
    normal_p,
    se_of,
    unit_sums,
)
from learner.gap.stats import benjamini_hochberg, bootstrap_mean, bootstrap_p
from simbridge.vehicle import Vehicle

RESAMPLES = 2000
ALPHA = 0.05
# The absolute floor under the noise floor (share of the weight): below it an effect is too
# small to name even when a long log pins it down
MIN_RULE_SHARE = 0.001
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
    # doubling edges: a 20 s hop gets two bins, a 5 min flight six (battery sag and warming
    # motors drift over minutes)
    "time_since_takeoff_s": ("time since take-off", "s", (0, 10, 20, 40, 80, 160, np.inf)),
}
COMPONENTS = ("vertical", "horizontal_along_velocity", "lateral", "world_x", "world_y")
# how each component reads in a sentence
COMPONENT_WORDS = {
    "vertical": "vertical",
    "horizontal_along_velocity": "horizontal (along the velocity, beyond the constant force)",
    "lateral": "horizontal (across the velocity to its left, beyond the constant force)",
    "world_x": "world x",
    "world_y": "world y",
}
# components fixed in the world: a constant force (wind) shows in every bin, so a bin is
# named only where it departs from the whole flights' mean (world_frame_summary names that)
WORLD_COMPONENTS = ("world_x", "world_y")


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
        # prepare() leaves contact out: the first row is the first airborne one
        "time_since_takeoff_s": d.time_s - d.time_s[0],
    }


def residual_components(d: FlightData, residual: np.ndarray, vehicle: Vehicle) -> np.ndarray:
    """(N, 5) residual over the weight, as COMPONENTS: vertical; horizontal along the
    velocity (a drag shows as negative) and across it (positive to its left), both once the
    flight's mean horizontal force is taken out; world x, y. A constant world force (a
    tunnel's wind) would otherwise show along and across a figure-8's velocity in every bin
    of speed or tilt; world_frame_summary names it instead. Rows slower than 5 cm/s have no
    direction of travel: 0 along and across."""
    vh = d.velocity_m_s[:, :2]
    speed = np.linalg.norm(vh, axis=1)
    unit = np.where(speed[:, None] > 0.05, vh / np.maximum(speed, 1e-9)[:, None], 0.0)
    h = residual[:, :2] - residual[:, :2].mean(axis=0)
    along = np.sum(h * unit, axis=1)
    across = h[:, 1] * unit[:, 0] - h[:, 0] * unit[:, 1]
    return (
        np.column_stack([residual[:, 2], along, across, residual[:, 0], residual[:, 1]])
        / vehicle.weight_n
    )


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
    se: float = 0.0  # the bootstrap's standard error of the mean (over weight)
    noise_se: float = 0.0  # the residual noise's standard error of the mean (over weight)
    overall: float = 0.0  # the component's mean over every row (over weight)

    @property
    def significant(self) -> bool:
        return self.p_adjusted < ALPHA and not (self.ci_low <= 0.0 <= self.ci_high)

    @property
    def baseline(self) -> float:
        """What the bin is compared with: 0, or the whole flights' mean for a world component."""
        return self.overall if self.component in WORLD_COMPONENTS else 0.0

    def floor(self, k_se: float = K_SE) -> float:
        """The smallest departure a rule names: `k_se` standard errors of the bootstrap and of
        the noise, and never below MIN_RULE_SHARE."""
        return max(k_se * self.se, k_se * self.noise_se, MIN_RULE_SHARE)

    def rule_worthy(self, k_se: float = K_SE) -> bool:
        if not self.significant or abs(self.mean - self.baseline) < self.floor(k_se):
            return False
        return not (self.ci_low <= self.baseline <= self.ci_high)


def regime_table(
    flights: list[FlightData], residuals: list[np.ndarray], vehicle: Vehicle, seed: int = 0
) -> list[RegimeBin]:
    """Per regime bin and component: mean residual over weight with a bootstrap 95% interval
    (units: learner/gap/floor.py) and a BH-adjusted p-value over every bin tested."""
    rng = np.random.default_rng(seed)
    variables = [regime_variables(d, vehicle) for d in flights]
    comps = [residual_components(d, r, vehicle) for d, r in zip(flights, residuals, strict=True)]
    units = bootstrap_units(flights)
    sd, ess = noise_level(comps, flights)
    all_comps = np.concatenate(comps)
    overall = all_comps.mean(axis=0)
    out: list[RegimeBin] = []
    for name, (_, _, edges) in REGIMES.items():
        bins = [np.digitize(v[name], edges) - 1 for v in variables]
        nb = len(edges) - 1
        sums, counts = unit_sums(comps, units, bins, nb)  # (units, nb, 5), (units, nb)
        per_flight = np.array([[np.sum(b == k) for k in range(nb)] for b in bins])
        for ci, comp in enumerate(COMPONENTS):
            draws = bootstrap_mean(sums[:, :, ci], counts, RESAMPLES, rng)
            p = bootstrap_p(draws)
            for k in range(nb):
                rows = int(counts[:, k].sum())
                if rows < MIN_ROWS:
                    continue
                lo, hi = np.nanpercentile(draws[:, k], [2.5, 97.5])
                mean = float(sums[:, k, ci].sum() / rows)
                se, se_noise = se_of(draws[:, k]), float(noise_se(sd[ci], rows, ess))
                # the bootstrap's p bottoms out at 1 / RESAMPLES: the larger standard
                # error's normal p carries the tail that hundreds of bins' BH needs
                p_k = max(float(p[k]), float(normal_p(mean, max(se, se_noise))))
                out.append(
                    RegimeBin(
                        name,
                        float(edges[k]),
                        float(edges[k + 1]),
                        comp,
                        rows,
                        int(np.sum(per_flight[:, k] > 0)),
                        mean,
                        float(lo),
                        float(hi),
                        p_k,
                        se=se,
                        noise_se=se_noise,
                        overall=float(overall[ci]),
                    )
                )
    if out:
        adjusted = benjamini_hochberg(np.array([b.p for b in out]))
        out = [replace(b, p_adjusted=float(a)) for b, a in zip(out, adjusted, strict=True)]
    return out


def bonferroni_z(tests: int) -> float:
    """The two-sided normal quantile that ALPHA over `tests` tests asks."""
    from scipy.stats import norm

    return float(norm.isf(ALPHA / (2.0 * max(tests, 1))))


def describe_range(variable: str, low: float, high: float) -> str:
    label, unit, _ = REGIMES[variable]
    unit = "" if unit == "1" else f" {unit}"  # a ratio reads without a unit
    if variable == "saturated":
        return "with a rotor saturated" if low > 0 else "with no rotor saturated"
    if np.isinf(high):
        return f"{label} above {low:g}{unit}"
    if np.isinf(low) or (low == 0 and variable != "vz_m_s"):
        return f"{label} below {high:g}{unit}"
    return f"{label} {low:g} to {high:g}{unit}"


def rules(table: list[RegimeBin], limit: int = 6) -> list[str]:
    """The bins departing most from their baseline, beyond the noise floor, as sentences.
    The floor's standard errors grow with the bins looked at (Bonferroni's z): one table holds
    a few hundred, and the same rows fall in a bin of every variable, which BH counts as
    independent discoveries."""
    k_se = max(K_SE, bonferroni_z(len(table)))
    worthy = [b for b in table if b.rule_worthy(k_se)]
    worthy.sort(key=lambda b: -abs(b.mean - b.baseline))
    out = []
    for b in worthy[:limit]:
        tail = f", {b.flights} flights, {b.rows} samples"
        if b.component in WORLD_COMPONENTS:
            tail += f"; {b.overall * 100:+.1f}% over the whole flights"
        out.append(
            f"{describe_range(b.variable, b.low, b.high)}: the {COMPONENT_WORDS[b.component]} "
            f"residual is {b.mean * 100:+.1f}% of the weight (95% CI {b.ci_low * 100:+.1f} to "
            f"{b.ci_high * 100:+.1f}%{tail})"
        )
    return out
