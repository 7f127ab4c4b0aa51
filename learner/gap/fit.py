"""Fitting candidate effects to residuals: bounded nonlinear least squares with intervals
inflated by the effective sample size, flight-level cross-validation, an information
criterion on the effective sample size, excitation and collinearity tests, and a forward
search over combinations."""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from learner.gap.candidates import CANDIDATES, Candidate, Values, catalogue, world_force
from learner.gap.flightdata import FlightData, every_nth
from learner.gap.residual import residual_n, smooth_per_segment
from learner.gap.stats import ess_ratio, trimmed_variance
from simbridge.effects.ground import cutoff_height_m
from simbridge.vehicle import Vehicle

STRIDE = 2  # the search fits every 2nd row: enough to rank sets (`final_fit`: every row)
Z_EXCITE = 8.0  # a typical-size effect must stand this many noise sigmas out of the data
COLLINEAR_R2 = 0.98  # above: the data cannot tell two candidates apart
DRAGS = ("rotor_drag", "body_drag")


@dataclass
class Problem:
    """Flights, their residuals against the nominal world and the nominal world's force."""

    flights: list[FlightData]
    residuals: list[np.ndarray]
    nominal: Values
    vehicle: Vehicle
    nominal_force: list[np.ndarray] = field(default_factory=list)
    ess_ratio: float = 1.0
    noise_var: float = 1.0
    _thinned: Problem | None = field(default=None, repr=False, compare=False)

    @property
    def catalogue(self) -> dict[str, Candidate]:
        """The candidates' bounds and magnitudes for this vehicle."""
        return catalogue(self.vehicle)

    def __post_init__(self) -> None:
        if not self.nominal_force:
            self.nominal_force = [world_force(self.nominal, d, self.vehicle) for d in self.flights]

    def subset(self, idx: list[int]) -> Problem:
        return Problem(
            [self.flights[i] for i in idx],
            [self.residuals[i] for i in idx],
            self.nominal,
            self.vehicle,
            [self.nominal_force[i] for i in idx],
            self.ess_ratio,
            self.noise_var,
        )

    def scored(
        self, names: tuple[str, ...], every_row: bool = False
    ) -> tuple[Problem, list[slice]]:
        """The problem whose `predicted` a fit of `names` scores, and the rows it scores:
        every row with `every_row`, else every STRIDE-th; computed on those rows only when no
        effect needs the rows between them (`Candidate.history`), the same figures for half
        the work."""
        if every_row:
            return self, [slice(None)] * len(self.flights)
        every = [slice(None, None, STRIDE)] * len(self.flights)
        # an effect whose force at a row depends on the rows before it (a lag, a coasting
        # rotor, a late sensor: `Candidate.history`) needs the rows between, and so does a
        # differentiated acceleration's filter
        history = [n for n, c in CANDIDATES.items() if c.history]
        if any(h in names or h in self.nominal for h in history) or not all(
            d.measured_acceleration for d in self.flights
        ):
            return self, every
        if self._thinned is None:
            self._thinned = Problem(
                [every_nth(d, STRIDE) for d in self.flights],
                [r[::STRIDE] for r in self.residuals],
                self.nominal,
                self.vehicle,
                [f[::STRIDE] for f in self.nominal_force],
            )
        return self._thinned, [slice(None)] * len(self.flights)

    def predicted(self, values: Values) -> list[np.ndarray]:
        """Each flight's residual the overriding `values` predict."""
        merged = {**self.nominal, **values}
        return [
            world_force(merged, d, self.vehicle) - f0
            for d, f0 in zip(self.flights, self.nominal_force, strict=True)
        ]


@dataclass(frozen=True)
class Fit:
    names: tuple[str, ...]
    values: Values
    stderr: Values  # standard errors, inflated for the correlated samples
    rss: float
    n: int  # residual components fitted
    p: int
    bic: float
    cov: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # of all parameters
    every_row: bool = False  # fitted on every row (`final_fit`), not every STRIDE-th


def problem_for(flights: list[FlightData], nominal: Values, vehicle: Vehicle) -> Problem:
    """The flights' residuals against the nominal world, with their noise variance."""
    res = [residual_n(d, nominal, vehicle) for d in flights]
    problem = Problem(flights, res, nominal, vehicle)
    problem.noise_var = noise_variance(res, flights)
    return problem


def noise_variance(residuals: list[np.ndarray], flights: list[FlightData]) -> float:
    """Per-component variance of the residual's fast part (minus a 5-row moving average),
    without the values beyond TRIM_SDS robust standard deviations (see `trimmed_variance`)."""
    parts = [
        r - smooth_per_segment(r, d.segment, 5) for r, d in zip(residuals, flights, strict=True)
    ]
    fast = np.concatenate(parts)
    return trimmed_variance(fast) * 5.0 / 4.0  # the average shares 1/5 of each sample's noise


def start_values(name: str, nominal: Values, cat: dict[str, Candidate] | None = None) -> np.ndarray:
    c = (cat or CANDIDATES)[name]
    if name in nominal:
        return np.array(nominal[name], dtype=float)
    if c.null:  # a thrust curve: from its null exponent 1
        return c.null_values()
    if c.start is not None:  # declared: a force of either sign starts from none
        return np.array(c.start, dtype=float)
    return np.array(c.typical, dtype=float)


def _scales(names: tuple[str, ...], cat: dict[str, Candidate] | None = None) -> np.ndarray:
    return np.concatenate([np.abs((cat or CANDIDATES)[n].typical) for n in names])


def _unpack(x: np.ndarray, names: tuple[str, ...]) -> Values:
    out, i = {}, 0
    for n in names:
        k = len(CANDIDATES[n].params)
        out[n] = x[i : i + k]
        i += k
    return out


# A candidate whose least squares is not convex (`Candidate.multi_start`) gets several starts
# when it enters a fit: the ground effect's cut-off height steps with rho, a wall a fit
# started below it does not cross; a lag's and a delay's residual has local minima a period
# apart. One whose force is held constant below a cut-off height that moves in centimetre
# steps with rho (`Candidate.walled`, `simbridge.effects.ground.cutoff_height_m`) is also
# scanned between the steps: the fit's cost jumps where the cut-off moves, and a descent from
# a start on one side stops at the wall (rho 0.6 on the nano came out 0.70, stopped by the
# wall at 0.66 from the starts at 1, 4 and 12).
WALL_MARGIN = 1.03  # the scan's points by an interval's edge: this factor inside it
WALL_GRID = 2000  # points of the grid the walls are looked for on (0.4% apart over 0.01..25)


@functools.lru_cache(maxsize=16)
def cutoff_walls(rotor_radius_m: float, lo: float, hi: float) -> tuple[float, ...]:
    """The rho in (lo, hi) at which the simulator's cut-off height moves
    (`cutoff_height_m`: where the singular height reaches a whole centimetre, or where the
    gain at the cut-off would pass tenfold): found on a fine grid, then bisected."""
    grid = np.geomspace(lo, hi, WALL_GRID)
    heights = [cutoff_height_m(float(rho), rotor_radius_m) for rho in grid]
    walls = []
    for k in np.flatnonzero(np.diff(heights)):
        a, b = float(grid[k]), float(grid[k + 1])
        for _ in range(40):
            mid = 0.5 * (a + b)
            if cutoff_height_m(mid, rotor_radius_m) == heights[k]:
                a = mid
            else:
                b = mid
        walls.append(b)
    return tuple(walls)


def _best_between_walls(
    fun: Any, x0: np.ndarray, i: int, scale: float, lo: float, hi: float, radius_m: float
) -> np.ndarray:
    """`x0` with parameter `i` (a rho, scaled) at the best of three points in each interval
    between the cut-off walls (by each edge and at the geometric middle): a start on the
    optimum's side of every wall."""
    rho_lo, rho_hi = lo * scale, hi * scale
    edges = [rho_lo, *cutoff_walls(radius_m, rho_lo, rho_hi), rho_hi]
    best, best_cost = x0, np.inf
    for a, b in itertools.pairwise(edges):
        for rho in (a * WALL_MARGIN, math.sqrt(a * b), b / WALL_MARGIN):
            x = x0.copy()
            x[i] = min(max(rho, a), b) / scale
            r = fun(x)
            cost = float(r @ r)
            if cost < best_cost:
                best, best_cost = x, cost
    return best


def fit(
    problem: Problem,
    names: tuple[str, ...],
    max_nfev: int | None = None,
    start: Values | None = None,
    multi_start: bool = True,
    every_row: bool = False,
) -> Fit:
    """Least squares of the candidates `names` (with the nominal world's other effects);
    `max_nfev`: at most this many evaluations (an approximate fit is enough); `start`: the
    values a previous fit found (a warm start); a non-convex candidate without one gets the
    starts of its `multi_start`, the best kept (unless not `multi_start`). On every STRIDE-th row,
    or with `every_row` on all (`final_fit`)."""
    stride = 1 if every_row else STRIDE
    rows = [slice(None, None, stride)] * len(problem.flights)
    target = np.concatenate([r[s].ravel() for r, s in zip(problem.residuals, rows, strict=True)])
    n = len(target)
    if not names:
        rss = float(target @ target)
        return Fit((), {}, {}, rss, n, 0, _bic(rss, n, 0, problem.ess_ratio), np.zeros((0, 0)))
    cat = problem.catalogue
    scale = _scales(names, cat)
    lo = np.concatenate([cat[c].lo for c in names]) / scale
    hi = np.concatenate([cat[c].hi for c in names]) / scale
    start = start or {}
    parts = [
        np.asarray(start[c], dtype=float) if c in start else start_values(c, problem.nominal, cat)
        for c in names
    ]
    x0 = np.clip(np.concatenate(parts) / scale, lo, hi)
    starts = [x0]
    offset = 0
    for c, part in zip(names, parts, strict=True):
        if multi_start and cat[c].multi_start and c not in start:
            for v in cat[c].multi_start:
                x = x0.copy()
                x[offset] = np.clip(v / scale[offset], lo[offset], hi[offset])
                if not any(np.allclose(x, y) for y in starts):
                    starts.append(x)
        offset += len(part)

    model, model_rows = problem.scored(names, every_row)

    def fun(x: np.ndarray) -> np.ndarray:
        pred = model.predicted(_unpack(x * scale, names))
        pred = [p[s] for p, s in zip(pred, model_rows, strict=True)]
        return np.concatenate([p.ravel() for p in pred]) - target

    offset = 0
    for c, part in zip(names, parts, strict=True):
        if multi_start and cat[c].walled and c not in start:
            scanned = _best_between_walls(fun, x0, offset, scale[offset], lo[offset], hi[offset],
                                          problem.vehicle.rotor_radius_m)  # fmt: skip
            if not any(np.allclose(scanned, y) for y in starts):
                starts.append(scanned)
        offset += len(part)

    sol = min(
        (
            least_squares(fun, x, bounds=(lo, hi), diff_step=1e-4, x_scale=1.0, max_nfev=max_nfev)
            for x in starts
        ),
        key=lambda r: r.cost,
    )
    rss = float(sol.fun @ sol.fun)
    p = len(x0)
    sigma2 = rss / max(n - p, 1)
    times = [d.time_s[s] for d, s in zip(problem.flights, rows, strict=True)]
    blocks = np.concatenate([_block_ids(t, k) for k, t in enumerate(times)])
    try:
        bread = np.linalg.pinv(sol.jac.T @ sol.jac)
        cov = bread * sigma2 / problem.ess_ratio
        # the wider of 1 s and 5 s blocks: a model that does not fit leaves a residual
        # correlated over seconds, which short blocks take for independent evidence
        robust = block_sandwich(bread, sol.jac, sol.fun, np.repeat(blocks, 3))
        long_ids = np.concatenate([_block_ids(t, k, LONG_BLOCK_S) for k, t in enumerate(times)])
        longer = block_sandwich(bread, sol.jac, sol.fun, np.repeat(long_ids, 3))
        var = np.maximum(np.diag(cov), np.diag(robust))
        if len(np.unique(long_ids)) >= 2 * len(x0) + 4:  # enough blocks to estimate it
            var = np.maximum(var, np.diag(longer))
        var = np.maximum(var, 0.0)  # pinv: tiny negatives
        # the robust correlations (the white ones where a score vanished), the larger variances
        corr_from = np.where(np.outer(np.diag(robust), np.diag(robust)) > 0, robust, cov)
        d = np.sqrt(np.maximum(np.diag(corr_from), 1e-300))
        full = corr_from / np.outer(d, d) * np.sqrt(np.outer(var, var))
    except np.linalg.LinAlgError:
        var = np.full(p, np.inf)
        full = np.diag(var)
    se = np.sqrt(np.maximum(var, 0.0)) * scale
    return Fit(
        names,
        _unpack(sol.x * scale, names),
        _unpack(se, names),
        rss,
        n,
        p,
        _bic(rss, n, p, problem.ess_ratio),
        full * np.outer(scale, scale),
        every_row,
    )


def final_fit(problem: Problem, chosen: Fit) -> Fit:
    """The chosen set's values and intervals from every row. The search ranks sets on every
    STRIDE-th row, which is enough to rank them at half the work; the values it reports take
    all the data: a log's sensor noise is white from one sample to the next, so the rows in
    between carry as much information as those fitted, and a weakly excited parameter's error
    grows without them (the gap bench's hover: a rotor drag's kxy 13.9% low on every 2nd
    row, 3.1% on all). The problem's effective sample size becomes that of every row: a fit compared
    with this one from now on is made on every row too (`every_row=chosen.every_row`)."""
    if not chosen.names:
        return chosen
    after = problem.predicted(chosen.values)
    problem.ess_ratio = ess_ratio([r - p for r, p in zip(problem.residuals, after, strict=True)])
    return fit(problem, chosen.names, start=chosen.values, every_row=True)


BLOCK_S = 1.0  # the sandwich interval's blocks: longer than the residual's correlation
LONG_BLOCK_S = 5.0  # and longer ones, for a misfit correlated over seconds


def _block_ids(t: np.ndarray, flight: int, block_s: float = BLOCK_S) -> np.ndarray:
    """Rows of one flight in blocks of `block_s` (ids unique across flights)."""
    return flight * 100_000 + np.floor((t - t[0]) / block_s).astype(int)


def block_sandwich(
    bread: np.ndarray, jac: np.ndarray, resid: np.ndarray, blocks: np.ndarray
) -> np.ndarray:
    """The cluster-robust covariance (J'J)^-1 (sum over blocks of s_b s_b') (J'J)^-1, with
    s_b = J_b' r_b: valid under correlated and misspecified residuals, which the white-noise
    interval inflated by the effective sample size is not (a model bias of 0.5% in rho
    otherwise sits 5 intervals away)."""
    _, inverse = np.unique(blocks, return_inverse=True)
    scores = np.zeros((inverse.max() + 1, jac.shape[1]))
    np.add.at(scores, inverse, jac * resid[:, None])
    g = len(scores)
    meat = scores.T @ scores * (g / max(g - 1, 1))
    return bread @ meat @ bread


def _bic(rss: float, n: int, p: int, ess_ratio: float) -> float:
    """BIC with the effective sample size: n_eff ln(RSS / n) + p ln(n_eff)."""
    n_eff = max(n * ess_ratio, p + 2.0)
    return float(n_eff * np.log(max(rss, 1e-300) / n) + p * np.log(n_eff))


def cross_validated_ev(problem: Problem, names: tuple[str, ...], folds: int) -> float:
    """Explained variance of the residual on flights left out (pooled over folds)."""
    k = min(folds, len(problem.flights))
    if k < 2:
        return float("nan")
    sse = sst = 0.0
    for fold in range(k):
        test = [i for i in range(len(problem.flights)) if i % k == fold]
        train = [i for i in range(len(problem.flights)) if i % k != fold]
        fitted = fit(problem.subset(train), names)
        held = problem.subset(test)
        for r, p in zip(held.residuals, held.predicted(fitted.values), strict=True):
            sse += float(np.sum((r - p) ** 2))
            sst += float(np.sum(r**2))
    return 1.0 - sse / sst if sst > 0 else 0.0


def sensitivities(problem: Problem, name: str, at: Values | None = None) -> np.ndarray:
    """(samples * 3, params) finite-difference sensitivity of the predicted residual to the
    candidate's parameters, at `at` (default: the nominal value plus a typical size)."""
    c = problem.catalogue[name]
    base = dict(at or {})
    if name not in base:
        base[name] = probe_values(name, problem.nominal, problem.catalogue)
    f0 = np.concatenate([p[::STRIDE].ravel() for p in problem.predicted(base)])
    cols = []
    for j in range(len(c.params)):
        step = 0.1 * abs(c.typical[j])
        moved = dict(base)
        moved[name] = base[name].copy()
        moved[name][j] += step
        f1 = np.concatenate([p[::STRIDE].ravel() for p in problem.predicted(moved)])
        cols.append((f1 - f0) / step * abs(c.typical[j]))  # per typical size
    return np.column_stack(cols)


def probe_values(name: str, nominal: Values, cat: dict[str, Candidate] | None = None) -> np.ndarray:
    c = (cat or CANDIDATES)[name]
    if name in nominal:
        return np.asarray(nominal[name], dtype=float) + 0.5 * np.asarray(c.typical)
    return c.null_values() + np.asarray(c.typical, dtype=float)


def excitation_z(problem: Problem, name: str) -> float:
    """How many noise sigmas a typical-size effect stands out of the data (effective samples):
    sqrt(sum of its squared force / noise variance * ESS ratio)."""
    cat = problem.catalogue
    if name == "wind" and not any(d in problem.nominal for d in DRAGS):
        probe: Values = {"rotor_drag": np.array(cat["rotor_drag"].typical)}
        base = np.concatenate([p[::STRIDE].ravel() for p in problem.predicted(probe)])
        probe["wind"] = probe_values("wind", problem.nominal, cat)
        moved = np.concatenate([p[::STRIDE].ravel() for p in problem.predicted(probe)])
        signal = moved - base
    else:
        probe = {name: probe_values(name, problem.nominal, cat)}
        signal = np.concatenate([p[::STRIDE].ravel() for p in problem.predicted(probe)])
    z2 = float(signal @ signal) / problem.noise_var * problem.ess_ratio
    return float(np.sqrt(z2))


def collinearity_r2(a: np.ndarray, b: np.ndarray) -> float:
    """The smallest share of any of `a`'s columns that `b`'s columns explain (1: every
    direction of a is also a direction of b), uncentred."""
    if not np.any(a) or not np.any(b):
        return 0.0
    coef, *_ = np.linalg.lstsq(b, a, rcond=None)
    explained = b @ coef
    share = np.sum(explained**2, axis=0) / np.maximum(np.sum(a**2, axis=0), 1e-300)
    return float(np.min(share))
