"""Actuator and inertial errors: motor lag, thrust-coefficient error, mass error."""

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
