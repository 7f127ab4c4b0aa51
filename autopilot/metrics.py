"""Flight figures from a logged trajectory: landing error, hold error, touchdown speed, bounce."""

from __future__ import annotations

import hashlib

import numpy as np

# Holds with a setpoint at most this high above the surface count as "near the ground"
# (judged by the setpoint, so that a vehicle the ground effect keeps higher still counts);
# their error is taken over the second half of each hold, once the approach has settled.
NEAR_GROUND_M = 0.1
# 10 rotor radii: the ground effect there is about 0.3 mN x rho in hover (0.6 mN at rho 2)
FAR_FROM_GROUND_M = 0.5
COLUMNS = ("time_s", "x", "y", "z", "vx", "vy", "vz", "zd", "height", "mode")


def flight_metrics(
    log: np.ndarray,
    modes: list[str],
    landing_target_xy: tuple[float, float] | None,
    resting_height_m: float,
) -> dict[str, float | None]:
    """`log` has one row per control step with COLUMNS; `mode` indexes `modes`."""
    t, x, y, z, vz, zd, height = (
        log[:, 0],
        log[:, 1],
        log[:, 2],
        log[:, 3],
        log[:, 6],
        log[:, 7],
        log[:, 8],
    )
    near = near_ground_hold(log, modes)
    out: dict[str, float | None] = {
        "hold_z_rms_error_m": float(np.sqrt(np.mean((z[near] - zd[near]) ** 2)))
        if near.any()
        else None,
        "hold_z_max_error_m": float(np.max(np.abs(z[near] - zd[near]))) if near.any() else None,
        "hold_z_mean_error_m": float(np.mean(z[near] - zd[near])) if near.any() else None,
    }
    # touchdown: the first step in contact (within 1 mm of resting) after the last flight;
    # bounce: how far it rises again after that.
    airborne = np.flatnonzero(height > resting_height_m + 0.02)
    contact = np.flatnonzero(height <= resting_height_m + 0.001)
    later = contact[contact > airborne[-1]] if airborne.size else contact[:0]
    touchdown = int(later[0]) if later.size else None
    if touchdown is not None:
        out["touchdown_time_s"] = float(t[touchdown])
        out["touchdown_speed_m_s"] = float(abs(vz[max(touchdown - 1, 0)]))
        out["bounce_m"] = float(max(np.max(height[touchdown:]) - height[touchdown], 0.0))
    else:
        out.update(touchdown_time_s=None, touchdown_speed_m_s=None, bounce_m=None)
    if landing_target_xy is not None and touchdown is not None:
        out["landing_error_m"] = float(
            np.hypot(x[-1] - landing_target_xy[0], y[-1] - landing_target_xy[1])
        )
    else:
        out["landing_error_m"] = None
    return out


def near_ground_hold(log: np.ndarray, modes: list[str]) -> np.ndarray:
    """The steps of `log` (metrics.COLUMNS) that hold near the ground, once settled."""
    z, zd, height = log[:, 3], log[:, 7], log[:, 8]
    setpoint_height = zd - z + height  # the setpoint above the surface under the vehicle
    holding = (log[:, 9].astype(int) == modes.index("holding")) & (setpoint_height <= NEAR_GROUND_M)
    return settled_halves(holding)


def _rms(values: np.ndarray) -> float | None:
    return float(np.sqrt(np.mean(values**2))) if len(values) else None


def ge_error_metrics(pairs: np.ndarray, hold_times_s: np.ndarray) -> dict[str, float | None]:
    """How well the controller's ground-effect model knew the vertical force in flight: RMS
    of predicted minus true (the simulator's) over the airborne steps; over the near-ground
    hold (`hold_times_s`, as `near_ground_hold` finds it), where the model is what holds the
    vehicle; and over the steps at least FAR_FROM_GROUND_M up, where the ground effect of rho
    1 and rho 2 is under a millinewton: an error there is not the world but the model (a
    network that forgot what it knew). With the mean true force over the hold, for scale.
    `pairs`: (time_s, height_m, predicted_n, true_n)."""
    error = pairs[:, 2] - pairs[:, 3]
    hold = np.isin(pairs[:, 0], hold_times_s)
    return {
        "ge_z_rms_error_n": _rms(error),
        "ge_z_hold_rms_error_n": _rms(error[hold]),
        "ge_z_hold_true_n": float(np.mean(pairs[hold, 3])) if hold.any() else None,
        "ge_z_far_rms_error_n": _rms(error[pairs[:, 1] >= FAR_FROM_GROUND_M]),
        # when the hold ran: what an online model had learnt by then
        "ge_hold_from_s": float(pairs[hold, 0].min()) if hold.any() else None,
        "ge_hold_to_s": float(pairs[hold, 0].max()) if hold.any() else None,
    }


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of every run of True in `mask`, stop exclusive."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    return [(int(a), int(b)) for a, b in zip(edges[0::2], edges[1::2], strict=True)]


def settled_halves(mask: np.ndarray) -> np.ndarray:
    """The second half of every run of True in `mask`: a hold once the approach has settled."""
    out = np.zeros_like(mask)
    for start, stop in runs(mask):
        out[(start + stop) // 2 : stop] = True
    return out


def trajectory_sha256(log: np.ndarray) -> str:
    """A fingerprint of the flown trajectory: equal only if every logged value is equal."""
    return hashlib.sha256(np.ascontiguousarray(log[:, :9]).tobytes()).hexdigest()
