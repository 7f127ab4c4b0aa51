"""Actuator and inertial errors: motor lag, a rotor that slows only by its own drag (no active
braking), thrust-coefficient error, mass error, a thrust axis leaning from the body's z axis
(a bent frame, motors mounted askew), a thrust curve (the rotors' thrust growing faster or
slower than the modelled C_T n^2 away from hover)."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from simbridge.config import param


@dataclass(frozen=True)
class MotorLagParams:
    """First-order motor: n' = (n_cmd - n) / tau."""

    time_constant_s: float = param(0.02, unit="s", lo=0.0, hi=1.0, lo_open=True, doc="tau")


def motor_lag_step(
    rotor_speed_rad_s: float, command_rad_s: float, dt_s: float, tau_s: float
) -> float:
    """Exact solution of n' = (n_cmd - n) / tau over dt with n_cmd held constant."""
    return command_rad_s + (rotor_speed_rad_s - command_rad_s) * math.exp(-dt_s / tau_s)


@dataclass(frozen=True)
class SpinDownParams:
    """A rotor whose speed controller does not brake (a brushed motor's low-side switch, an
    ESC without active braking): above its command it slows only by its propeller's drag
    torque, I n' = -k_q n^2, so from hover speed n_h it halves its speed in
    `time_constant_s` = I / (k_q n_h) (n = n_h / (1 + t / tau)); towards a higher command
    it follows its lag. A Crazyflie's 46 mm propeller and motor (about 9e-8 kg m^2,
    k_q = k_z C_T = 1.7e-10 N m s^2, n_h 1650 rad/s): 0.3 s; a 12-inch propeller on an
    unbraked ESC about 0.8 s."""

    time_constant_s: float = param(
        0.3, unit="s", lo=0.0, hi=10.0, lo_open=True,
        doc="a freewheeling rotor's time to halve its speed from hover",
    )  # fmt: skip


def freewheel_rad_s(rotor_speed_rad_s: float, dt_s: float, rate_per_rad: float) -> float:
    """n' = -c n^2 over dt (exact): the speed a rotor coasts down to, c = 1 / (n_h tau)."""
    return rotor_speed_rad_s / (1.0 + rotor_speed_rad_s * dt_s * rate_per_rad)


def spin_down_envelope(
    speeds_rad_s: np.ndarray, time_s: np.ndarray, segment: np.ndarray, rate_per_rad: float
) -> np.ndarray:
    """(N, k) rotor speeds following `speeds_rad_s` (N, k) up at once and down no faster
    than freewheeling (`freewheel_rad_s`), over rows at `time_s` within each run of equal
    `segment` values: in u = 1 / n a freewheeling rotor's u grows linearly (u' = c), so u(t)
    is the running minimum of 1 / n(s) + c (t - s). The array form of the simulator's step."""
    ct = (rate_per_rad * time_s)[:, None]
    with np.errstate(divide="ignore"):
        u = 1.0 / speeds_rad_s - ct
    starts = [0, *(np.flatnonzero(segment[1:] != segment[:-1]) + 1).tolist(), len(u)]
    for a, b in itertools.pairwise(starts):
        np.minimum.accumulate(u[a:b], axis=0, out=u[a:b])
    u += ct
    with np.errstate(divide="ignore"):
        return 1.0 / u


@dataclass(frozen=True)
class ThrustCoefficientParams:
    """C_T of the simulated rotors scaled (battery sag, a different propeller)."""

    scale: float = param(1.0, lo=0.2, hi=3.0, doc="true C_T over the vehicle file's C_T")


@dataclass(frozen=True)
class MassErrorParams:
    """The simulated vehicle's true mass (and inertia, in proportion) differs from the file's."""

    scale: float = param(1.0, lo=0.2, hi=5.0, doc="true mass over the vehicle file's mass")


@dataclass(frozen=True)
class ThrustTiltParams:
    """The rotors' common thrust axis leans from body z: a bent frame or motors mounted
    askew push a body-fixed horizontal force proportional to the thrust (`lean_deg` towards
    body +x and +y). A mis-mounted IMU looks the same in a log: the attitude it reports is
    off by the lean, so the thrust seems to lean in the body frame the log gives."""

    lean_deg: tuple[float, float] = param(
        (0.0, 0.0), unit="deg", lo=-30.0, hi=30.0, doc="lean towards body x and y"
    )


def thrust_axis_body(lean_x_deg: float, lean_y_deg: float) -> tuple[float, float, float]:
    """The unit thrust direction in the body frame for leans towards body +x and +y (each
    the angle of the axis's component in that direction: sin(lean) of the thrust; within
    ThrustTiltParams' +-30 deg the vertical part stays above 0.7)."""
    sx, sy = math.sin(math.radians(lean_x_deg)), math.sin(math.radians(lean_y_deg))
    return (sx, sy, math.sqrt(1.0 - sx * sx - sy * sy))


@dataclass(frozen=True)
class ThrustCurveParams:
    """Each rotor's true thrust departs from the modelled f = C_T n^2 as a power law about
    hover: (W/4) (f / (W/4))^gamma, W the vehicle's weight. Hover is unchanged; away from it
    the thrust grows faster (gamma > 1) or slower than modelled: a logged command converted
    to thrust by a linear model while the ESC and propeller give a curve (PX4's
    THR_MDL_FAC, ArduCopter's MOT_THST_EXPO), or a PWM-to-thrust polynomial that is off."""

    gamma: float = param(1.0, lo=0.2, hi=4.0, doc="exponent of the thrust about hover (1: none)")


def thrust_curve_forces_n(
    rotor_forces_n: tuple[float, float, float, float], gamma: float, pivot_n: float
) -> tuple[float, float, float, float]:
    """The four rotors' true thrusts pivot_n (f_i / pivot_n)^gamma for modelled thrusts f_i
    (pivot_n: a quarter of the weight; a rotor at it is unchanged, one at rest gives 0)."""
    f0, f1, f2, f3 = rotor_forces_n
    inv = 1.0 / pivot_n
    return (
        pivot_n * (f0 * inv) ** gamma,
        pivot_n * (f1 * inv) ** gamma,
        pivot_n * (f2 * inv) ** gamma,
        pivot_n * (f3 * inv) ** gamma,
    )


def thrust_curve_array(rotor_forces_n: np.ndarray, gamma: float, pivot_n: float) -> np.ndarray:
    """`thrust_curve_forces_n` over an array of modelled rotor thrusts (any shape)."""
    return pivot_n * (np.maximum(rotor_forces_n, 0.0) / pivot_n) ** gamma
