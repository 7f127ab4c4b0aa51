"""Rotor forces, thrust and moments: thesis equations 3.5 and 3.6, and their inverse (the mixer).

Rotors are numbered as in 3.6: 0 front-left, 1 back-left, 2 back-right, 3 front-right.
"""

from __future__ import annotations

import math

Quad = tuple[float, float, float, float]


def rotor_forces_n(thrust_coefficient_n_s2: float, rotor_speeds_rad_s: Quad) -> Quad:
    """Equation 3.5: f_i = C_T n_i^2."""
    c = thrust_coefficient_n_s2
    n0, n1, n2, n3 = rotor_speeds_rad_s
    return (c * n0 * n0, c * n1 * n1, c * n2 * n2, c * n3 * n3)


def thrust_and_moments(
    rotor_forces: Quad, arm_m: float, yaw_moment_coefficient_m: float
) -> tuple[float, float, float, float]:
    """Equation 3.6: (T [N], M_x, M_y, M_z [N m]) in the body frame (x forward, y left, z up)."""
    f0, f1, f2, f3 = rotor_forces
    return (
        f0 + f1 + f2 + f3,
        arm_m * (f0 + f1 - f2 - f3),
        arm_m * (-f0 + f1 + f2 - f3),
        yaw_moment_coefficient_m * (-f0 + f1 - f2 + f3),
    )


def rotor_forces_for(
    thrust_n: float,
    moments_n_m: tuple[float, float, float],
    arm_m: float,
    yaw_moment_coefficient_m: float,
) -> Quad:
    """Inverse of equation 3.6: the rotor forces that give thrust T and moments M."""
    return _mixed(*_per_rotor_shares(thrust_n, moments_n_m, arm_m, yaw_moment_coefficient_m))


def _mixed(t: float, x: float, y: float, z: float) -> Quad:
    return (t + x - y - z, t + x + y + z, t - x + y - z, t - x - y + z)


def _per_rotor_shares(
    thrust_n: float,
    moments_n_m: tuple[float, float, float],
    arm_m: float,
    yaw_moment_coefficient_m: float,
) -> tuple[float, float, float, float]:
    """Each rotor's share of the thrust and of the moments about x, y and z (N)."""
    mx, my, mz = moments_n_m
    return (
        thrust_n / 4.0,
        mx / (4.0 * arm_m),
        my / (4.0 * arm_m),
        mz / (4.0 * yaw_moment_coefficient_m),
    )


def prioritised_rotor_forces(
    thrust_n: float,
    moments_n_m: tuple[float, float, float],
    arm_m: float,
    yaw_moment_coefficient_m: float,
    max_rotor_force_n: float,
) -> Quad:
    """`rotor_forces_for` within [0, f_max], giving up what matters least first, as PX4's
    and the Crazyflie's mixers do: the yaw moment, then the collective thrust, last the roll
    and pitch moments (their direction kept). Clipping each rotor alone instead turns a yaw
    demand into a roll or pitch moment nobody asked for: a laggy or heavy vehicle at full
    tilt then tumbles. The collective is only ever lowered (to keep the top rotor in range),
    never raised above the demand to keep a rotor above zero: there the roll and pitch
    moments shrink instead (PX4's mixer with MC_AIRMODE 0, its default). Raised, a vehicle
    whose corner caught the ground kept full thrust to level itself and hovered pinned,
    tilted, above its landing setpoint. Unchanged (bit for bit) whenever the plain inverse
    fits."""
    t, x, y, z = _per_rotor_shares(thrust_n, moments_n_m, arm_m, yaw_moment_coefficient_m)
    forces = _mixed(t, x, y, z)
    f_max = max_rotor_force_n
    if all(0.0 <= f <= f_max for f in forces):
        return forces
    tilt = (x - y, x + y, -x + y, -x - y)  # roll and pitch, per rotor
    spread = max(tilt) - min(tilt)
    if spread > f_max:  # even at the best thrust: less tilt moment, the same direction
        scale = f_max / spread
        tilt = (tilt[0] * scale, tilt[1] * scale, tilt[2] * scale, tilt[3] * scale)
    # the collective lowered as far as keeps the top rotor in range (spread <= f_max: the
    # bottom one stays at or above zero there)
    t = min(t, f_max - max(tilt))
    low = min(tilt)  # <= 0: the four shares sum to zero
    if t + low < 0.0:  # the bottom rotor below zero: less tilt moment, the thrust kept
        scale = max(t, 0.0) / -low
        tilt = (tilt[0] * scale, tilt[1] * scale, tilt[2] * scale, tilt[3] * scale)
    base = (t + tilt[0], t + tilt[1], t + tilt[2], t + tilt[3])
    yaw = (-z, z, -z, z)
    share = 1.0  # of the yaw moment that fits
    for b, w in zip(base, yaw, strict=True):
        if w > 0.0:
            share = min(share, (f_max - b) / w)
        elif w < 0.0:
            share = min(share, b / -w)
    share = max(share, 0.0)
    return tuple(  # type: ignore[return-value]
        min(max(b + share * w, 0.0), f_max) for b, w in zip(base, yaw, strict=True)
    )


def rotor_speeds_for(
    thrust_coefficient_n_s2: float, rotor_forces: Quad, max_rotor_speed_rad_s: float
) -> Quad:
    """Inverse of equation 3.5, saturated to [0, n_max] (a rotor cannot pull downward)."""
    return tuple(  # type: ignore[return-value]
        min(math.sqrt(max(f, 0.0) / thrust_coefficient_n_s2), max_rotor_speed_rad_s)
        for f in rotor_forces
    )
