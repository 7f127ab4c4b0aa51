"""An accelerometer bias or a leaning thrust axis (or a wind: `MEASURED_PAIRS`): each puts a
horizontal offset in the residual, and a flight at one heading cannot tell them apart by the
fit. The logs can, where they carry an accelerometer: a bias is in the logged acceleration
only, so its mean departs from the velocity's change over the flight; a leaning thrust or a
wind is a real force, which moves the velocity too, and the logged acceleration agrees with
it.
"""

from __future__ import annotations

import numpy as np

from learner.gap.candidates import Values
from learner.gap.fit import Problem
from learner.gap.flightdata import FlightData

# the logged acceleration's mean offset must account for at least this share of what the
# fitted member puts in the residual's horizontal mean (or stay below it) to tell them apart
SHARE = 0.5
# below this horizontal mean (m/s^2) the member leaves too little for the logged offset to
# judge: a velocity's noise over a flight and a thrust's ripple reach a few mm/s^2
MIN_OFFSET_M_S2 = 0.03
BIAS_OR_TILT = frozenset({"sensor_bias", "thrust_tilt"})
# a bias beside a real horizontal force (a lean, a wind at one heading): the same offset in
# the residual, told apart by the logged acceleration alone
MEASURED_PAIRS = (BIAS_OR_TILT, frozenset({"sensor_bias", "wind"}))


def logged_offset_m_s2(flights: list[FlightData]) -> np.ndarray | None:
    """The world-frame mean of the logged acceleration less the velocity's change over each
    airborne spell, pooled over the flights (m/s^2); None where a log's acceleration was
    differentiated from its velocity (it agrees by construction)."""
    if not flights or not all(d.measured_acceleration for d in flights):
        return None
    integral, change, duration = np.zeros(3), np.zeros(3), 0.0
    for d in flights:
        for s in np.unique(d.segment):
            idx = np.flatnonzero(d.segment == s)
            if len(idx) < 2:
                continue
            # a row's acceleration covers the period ending at its time
            dt = np.diff(d.time_s[idx])
            integral += (d.acceleration_m_s2[idx[1:]] * dt[:, None]).sum(axis=0)
            change += d.velocity_at_m_s[idx[-1]] - d.velocity_at_m_s[idx[0]]
            duration += float(d.time_s[idx[-1]] - d.time_s[idx[0]])
    if duration <= 0.0:
        return None
    return (integral - change) / duration


def member_offset_m_s2(contribution_n: np.ndarray, mass_kg: float) -> np.ndarray:
    """The mean world-frame acceleration a member's (N, 3) contribution puts in the
    residual."""
    return np.asarray(contribution_n).reshape(-1, 3).mean(axis=0) / mass_kg


def ruled_out(other: str, member: np.ndarray, logged: np.ndarray) -> str | None:
    """Why `other` (sensor_bias or thrust_tilt) cannot carry what the chosen member (the
    other of the two) fits, given the member's horizontal mean offset `member` and the
    logged acceleration's `logged` (m/s^2); None when the logs do not tell."""
    m, g = np.asarray(member)[:2], np.asarray(logged)[:2]
    size = float(np.linalg.norm(m))
    if size < MIN_OFFSET_M_S2:
        return None
    text = f"({g[0]:.3f}, {g[1]:.3f}) m/s^2"
    if other == "thrust_tilt" and float(np.linalg.norm(g - m)) <= SHARE * size:
        return (
            f"the logged acceleration's mean departs from the velocity's change by {text} "
            "horizontally, as the bias says: a force would have moved the velocity"
        )
    if other == "sensor_bias" and float(np.linalg.norm(g)) <= SHARE * size:
        return (
            f"the logged acceleration's mean agrees with the velocity's change within {text} "
            f"horizontally, against the {size:.3f} m/s^2 a bias would leave: a real force"
        )
    return None


def measured_bias(member: np.ndarray, logged: np.ndarray) -> bool:
    """Whether the logged acceleration measures the horizontal offset `member` (m/s^2) that a
    fitted bias puts in the residual: at least MIN_OFFSET_M_S2, and the logged offset within
    SHARE of it. Then the bias is told from a lean beside it by the logs themselves."""
    m, g = np.asarray(member)[:2], np.asarray(logged)[:2]
    size = float(np.linalg.norm(m))
    return size >= MIN_OFFSET_M_S2 and float(np.linalg.norm(g - m)) <= SHARE * size


def told_apart(problem: Problem, values: Values, pair: frozenset[str] = BIAS_OR_TILT) -> bool:
    """Whether a bias and a real force (a lean, or a wind: `pair`) fitted together (`values`
    holds both) are each what the logs say: the residual cannot tell them apart at one
    heading, but the logged acceleration's mean departs from the velocity's change by the
    bias alone (a force moves the velocity too)."""
    if pair not in MEASURED_PAIRS or not set(values) >= pair:
        return False
    logged = logged_offset_m_s2(problem.flights)
    if logged is None:
        return False
    return measured_bias(fitted_offset_m_s2(problem, values, "sensor_bias"), logged)


def fitted_offset_m_s2(problem: Problem, values: Values, name: str) -> np.ndarray:
    """The mean world-frame acceleration the member `name` of the fitted `values` puts in
    the residual: the prediction with it less the one without it."""
    rest = {k: v for k, v in values.items() if k != name}
    part = [a - b for a, b in zip(problem.predicted(values), problem.predicted(rest), strict=True)]
    return member_offset_m_s2(np.concatenate(part), problem.vehicle.mass_kg)


def contradicted(name: str, contribution_n: np.ndarray, logged: np.ndarray | None,
                 mass_kg: float) -> str | None:  # fmt: skip
    """Why a fitted sensor_bias or thrust_tilt is the wrong one of the two, by the logged
    acceleration (`logged_offset_m_s2`; None: the logs do not tell): what the search should
    not choose when the other can carry the same offset."""
    if logged is None or name not in ("sensor_bias", "thrust_tilt"):
        return None
    member = member_offset_m_s2(contribution_n, mass_kg)
    # a tilt whose offset the accelerometer alone shows is a bias, and a bias the velocity
    # follows is a force: the reason `ruled_out` gives for the other reading
    return ruled_out(name, member, logged)
