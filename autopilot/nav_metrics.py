"""The estimator's quality against the simulator's truth, for the flight summary."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from autopilot.estimation.navigation import Navigation
from autopilot.types import FlightState


def estimation_error(estimate: FlightState, truth: FlightState) -> tuple[float, ...]:
    """(position error x y z m, velocity error x y z m/s, attitude error rad)."""
    p, tp = estimate.position_m, truth.position_m
    v, tv = estimate.velocity_m_s, truth.velocity_m_s
    q, tq = estimate.quaternion, truth.quaternion
    dot = abs(q[0] * tq[0] + q[1] * tq[1] + q[2] * tq[2] + q[3] * tq[3])
    angle = 2.0 * math.acos(min(1.0, dot))
    return (
        p[0] - tp[0], p[1] - tp[1], p[2] - tp[2],
        v[0] - tv[0], v[1] - tv[1], v[2] - tv[2],
        angle,
    )  # fmt: skip


def estimator_metrics(errors: np.ndarray, nav: Navigation) -> dict[str, Any]:
    """RMS and largest errors in the air, innovation test ratios and resets per source."""
    out: dict[str, Any] = {"estimator_height_source": nav.height_source}
    q = nav.quality
    out["estimator_fused"] = dict(q.fused)
    out["estimator_rejected"] = dict(q.rejected)
    out["estimator_test_ratio_max"] = {k: round(v, 3) for k, v in q.ratio_max.items()}
    out["estimator_resets"] = q.resets
    if len(errors) == 0:
        return out
    position = np.linalg.norm(errors[:, 0:3], axis=1)
    velocity = np.linalg.norm(errors[:, 3:6], axis=1)
    out.update(
        est_position_rms_m=float(np.sqrt(np.mean(position**2))),
        est_position_max_m=float(position.max()),
        est_z_rms_m=float(np.sqrt(np.mean(errors[:, 2] ** 2))),
        est_velocity_rms_m_s=float(np.sqrt(np.mean(velocity**2))),
        est_velocity_max_m_s=float(velocity.max()),
        est_attitude_rms_deg=float(np.degrees(np.sqrt(np.mean(errors[:, 6] ** 2)))),
        est_attitude_max_deg=float(np.degrees(errors[:, 6].max())),
    )
    return out
