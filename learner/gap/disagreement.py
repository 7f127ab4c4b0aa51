"""Whether the flights disagree with each other where they fly alike: a test of heterogeneity
across flights within each height regime (Cochran's Q of the flights' mean vertical residual
left by the catalogue).

A per-flight bootstrap pools flights and averages a difference between them away: a landing
pad whose ground effect differs from the floor around it, landed on in one flight and beside
it in another, reads as a weak mean in the height bin both share. Flights that disagree
beyond their own spread in one regime point to what the regime's variables leave out, the
place first of all: the learnt residual then takes the position among its inputs.

Where they disagree, each flight's mean position over the bin's rows is given beside its
mean (the position regime: a pad shows as the place the flights that push harder flew over).

Each flight's mean over a bin carries a standard error from its blocks of BLOCK_S (the
residual is correlated over a block, not over a row); Q = sum w_i (m_i - m)^2 with w = 1/se^2
is chi-square with k - 1 degrees of freedom where the flights agree. A disagreement needs a
Bonferroni-corrected p under ALPHA over every bin tested, and flights apart by at least
MIN_SPREAD of the weight (a long log pins down differences too small to matter).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.stats import chi2

from learner.gap.flightdata import FlightData
from learner.gap.regimes import REGIMES, describe_range
from simbridge.vehicle import Vehicle

BLOCK_S = 1.0
MIN_BLOCKS = 3  # a flight's mean in a bin needs this many blocks to carry a standard error
ALPHA = 0.01
MIN_SPREAD = 0.02  # of the weight: the smallest difference between flights worth a verdict


def _flight_mean(
    d: FlightData, vertical: np.ndarray, rows: np.ndarray
) -> tuple[float, float] | None:
    """The mean of `vertical` over `rows` and its standard error over BLOCK_S blocks."""
    if rows.sum() == 0:
        return None
    blocks = ((d.time_s[rows] - d.time_s[0]) // BLOCK_S).astype(int)
    ids, inverse = np.unique(blocks, return_inverse=True)
    if len(ids) < MIN_BLOCKS:
        return None
    sums = np.bincount(inverse, weights=vertical[rows])
    counts = np.bincount(inverse)
    means = sums / counts
    mean = float(vertical[rows].mean())
    se = float(np.std(means, ddof=1) / np.sqrt(len(ids)))
    return mean, max(se, 1e-12)


def flights_disagree(
    flights: list[FlightData], residuals: list[np.ndarray], vehicle: Vehicle
) -> dict[str, Any] | None:
    """The height bin where the flights' mean vertical residual (`residuals`, N, world) differs
    most beyond their spread, as a record with a sentence; None where they agree (or fewer
    than two flights share a bin)."""
    edges = REGIMES["height_r"][2]
    heights = [d.height_m / vehicle.rotor_radius_m for d in flights]
    vertical = [r[:, 2] / vehicle.weight_n for r in residuals]
    tests = []
    for k in range(len(edges) - 1):
        per_flight, places = {}, {}
        for d, h, v in zip(flights, heights, vertical, strict=True):
            rows = (h >= edges[k]) & (h < edges[k + 1])
            m = _flight_mean(d, v, rows)
            if m is not None:
                per_flight[d.name] = m
                places[d.name] = [float(c) for c in d.position_m[rows, :2].mean(axis=0)]
        if len(per_flight) < 2:
            continue
        means = np.array([m for m, _ in per_flight.values()])
        w = 1.0 / np.array([se for _, se in per_flight.values()]) ** 2
        pooled = float(np.sum(w * means) / np.sum(w))
        q = float(np.sum(w * (means - pooled) ** 2))
        p = float(chi2.sf(q, len(means) - 1))
        spread = float(means.max() - means.min())
        tests.append((p, spread, k, {n: m for n, (m, _) in per_flight.items()}, places))
    if not tests:
        return None
    found = [t for t in tests if t[0] * len(tests) < ALPHA and t[1] >= MIN_SPREAD]
    if not found:
        return None
    p, spread, k, means, places = max(found, key=lambda t: t[1])
    where = describe_range("height_r", float(edges[k]), float(edges[k + 1]))
    # the position regime: where each flight flew that height, so the place can be found
    each = ", ".join(
        f"{m * 100:+.1f}% on {name} (about x {places[name][0]:.2f}, y {places[name][1]:.2f} m)"
        for name, m in means.items()
    )
    return {
        "variable": "height_r",
        "low": float(edges[k]),
        "high": float(edges[k + 1]),
        "per_flight_share": means,
        "per_flight_position_m": places,  # mean x, y over the bin's rows
        "spread_share": spread,
        "p_bonferroni": min(p * len(tests), 1.0),
        "sentence": (
            f"the flights disagree ({where}): the vertical residual the catalogue leaves is "
            f"{each} of the weight (Cochran's Q across flights, Bonferroni p "
            f"{min(p * len(tests), 1.0):.2g}); what differs between them is not in the "
            "regime's variables (the place: a patch of floor, a neighbour), so the learnt "
            "residual takes the position among its inputs"
        ),
    }
