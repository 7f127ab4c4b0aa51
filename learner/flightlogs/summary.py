"""What a converted flight log holds, in a few lines a user can check against the vehicle:
rows, duration, rate, what was converted, the thrust against the weight and the mean
acceleration (both should be about 1 and 0 over a flight that ends where it started)."""

from __future__ import annotations

import numpy as np

from learner.flightlogs.flightlog import FlightLog
from learner.flightlogs.resting import resting_rows
from simbridge.frames import quat_to_matrices
from simbridge.vehicle import Vehicle

THRUST_RATIO_OK = (0.7, 1.3)  # median vertical thrust over weight of a flight that flies
MEAN_ACCEL_OK_M_S2 = 2.0  # a mean vertical acceleration beyond this is not a flight's
# A logged acceleration whose mean departs this far from the velocity's change over the flight
# is biased (an estimator's tilt or IMU misalignment): the diagnosis sees m x bias as a force.
ACCEL_BIAS_OK_M_S2 = 0.2


def summarize(log: FlightLog, vehicle: Vehicle) -> dict:
    """Figures of the log: rows, duration_s, rate_hz, thrust_over_weight (median of the
    vertical thrust through the vehicle's C_T over its weight), mean_accel_m_s2 (logged, else
    differentiated from the velocity), accel_source, conversions, warnings."""
    t = log.time_s
    steps = np.diff(t)
    steps = steps[steps > 0]
    thrust = vehicle.thrust_coefficient_n_s2 * np.sum(log.rotor_speeds_rad_s**2, axis=1)
    r33 = quat_to_matrices(log.quaternion)[:, 2, 2]
    ratio = float(np.nanmedian(thrust * r33)) / vehicle.weight_n if len(log) else float("nan")
    if log.acceleration_m_s2 is not None:
        acc, source = log.acceleration_m_s2, "logged"
    elif len(log) > 2:
        acc, source = np.gradient(log.velocity_m_s, t, axis=0), "differentiated velocity"
    else:
        acc, source = np.full((len(log), 3), np.nan), "none"
    mean_acc = np.nanmean(acc, axis=0) if len(log) else np.full(3, np.nan)
    # the velocity's change over the flight: what a logged acceleration's mean should be
    dv = (log.velocity_m_s[-1] - log.velocity_m_s[0]) / (t[-1] - t[0]) if len(log) > 2 else acc[0]
    warnings = []
    if not THRUST_RATIO_OK[0] <= ratio <= THRUST_RATIO_OK[1]:
        warnings.append(
            f"the median vertical thrust is {ratio:.2f} x {vehicle.name}'s weight "
            f"({vehicle.mass_kg:g} kg): check the vehicle (--vehicle), the thrust's kind and "
            f"unit, the hover throttle"
        )
    if abs(mean_acc[2]) > MEAN_ACCEL_OK_M_S2:
        g = "included" if mean_acc[2] > 0 else "removed"
        warnings.append(
            f"the mean vertical acceleration is {mean_acc[2]:.2f} m/s^2: is gravity {g} in the "
            f"accelerometer (accelerometer.gravity), its unit or frame wrong?"
        )
    bias = mean_acc - dv
    if source == "logged" and np.max(np.abs(bias)) > ACCEL_BIAS_OK_M_S2:
        bx, by, bz = bias
        warnings.append(
            f"the logged acceleration's mean departs from the velocity's change by "
            f"[{bx:.2f}, {by:.2f}, {bz:.2f}] m/s^2, a bias the diagnosis will see as a force of "
            f"{vehicle.mass_kg * np.max(np.abs(bias)) * 1000:.0f} mN; without the "
            f"accelerometer columns it differentiates the velocity instead"
        )
    rest = resting_rows(log, vehicle)
    resting_z = float(np.median(log.position_m[rest, 2])) if rest.any() else None
    return {
        "rows": len(log),
        "duration_s": float(t[-1] - t[0]) if len(log) else 0.0,
        "rate_hz": 1.0 / float(np.median(steps)) if len(steps) else float("nan"),
        "thrust_over_weight": ratio,
        "mean_accel_m_s2": [float(a) for a in mean_acc],
        "accel_source": source,
        "velocity_change_m_s2": [float(a) for a in dv],
        "conversions": list(log.meta.get("conversions", [])),
        "warnings": warnings,
        "resting_rows": int(rest.sum()),
        "resting_z_m": resting_z,
    }


def summary_lines(s: dict, vehicle: Vehicle) -> list[str]:
    """The summary as the lines `groundfx gap convert` prints."""
    ax, ay, az = s["mean_accel_m_s2"]
    dx, dy, dz = s["velocity_change_m_s2"]
    lines = [
        f"rows {s['rows']}, {s['duration_s']:.2f} s, {s['rate_hz']:.1f} Hz",
        *(f"  {c}" for c in s["conversions"]),
        f"thrust: median vertical {s['thrust_over_weight']:.3f} x {vehicle.name}'s weight "
        f"({vehicle.mass_kg:g} kg)",
        f"acceleration ({s['accel_source']}): mean [{ax:.3f}, {ay:.3f}, {az:.3f}] m/s^2 "
        f"(velocity change over the flight: [{dx:.3f}, {dy:.3f}, {dz:.3f}] m/s^2)",
    ]
    if s.get("resting_z_m") is not None:
        half = vehicle.body_size_m[2] / 2.0
        lines.append(
            f"rests on a surface in {s['resting_rows']} rows at z {s['resting_z_m']:.4f} m: a "
            f"flat floor at z = 0 would put it {(s['resting_z_m'] - half) * 1000:+.1f} mm off the "
            f"simulator's resting height ({half * 1000:.1f} mm; `gap diagnose` shifts by it)"
        )
    return lines + [f"warning: {w}" for w in s["warnings"]]
