"""Actuator and inertial errors: motor lag, thrust-coefficient error, mass error, a thrust
axis leaning from the body's z axis (a bent frame, motors mounted askew)."""

from __future__ import annotations

import math
from dataclasses import dataclass

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
