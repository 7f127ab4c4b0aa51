"""The four rotors between their commands and their forces: motor lag, a rotor coasting down
on its drag (spin_down), the thrust decay over the flight, the thrust curve, a weak rotor.
The simulator's edge for these effects (`Simulation` holds one); the rules themselves are
the pure functions of `simbridge.effects`."""

from __future__ import annotations

from simbridge.effects import EffectSet
from simbridge.effects.actuators import freewheel_rad_s, motor_lag_step, thrust_curve_forces_n
from simbridge.effects.uncatalogued import asymmetric_forces_n, thrust_decay_scale
from simbridge.rotors import Quad, rotor_forces_n
from simbridge.vehicle import Vehicle


class RotorDynamics:
    def __init__(self, vehicle: Vehicle, fx: EffectSet, dt_s: float) -> None:
        self.dt_s = dt_s
        # the simulated (true) vehicle's C_T
        self.c_t = vehicle.thrust_coefficient_n_s2 * (
            fx.thrust_coefficient.scale if fx.thrust_coefficient else 1.0
        )
        self.lag_tau = fx.motor_lag.time_constant_s if fx.motor_lag else None
        # a rotor without active braking coasts down: n' >= -n^2 / (n_h tau)
        self.coast = (
            1.0 / (vehicle.hover_rotor_speed_rad_s * fx.spin_down.time_constant_s)
            if fx.spin_down
            else None
        )
        self.decay, self.asym = fx.thrust_decay, fx.rotor_asymmetry
        self.thrust_scale = 1.0
        # a thrust curve about the vehicle file's hover thrust (W/4), applied to the modelled
        # thrust before any C_T scale: s (W/4) (f/(W/4))^gamma is the curve about s W/4 of s f
        self.curve = fx.thrust_curve.gamma if fx.thrust_curve else None
        self.curve_pivot_n = 0.25 * vehicle.weight_n * self.c_t / vehicle.thrust_coefficient_n_s2
        self.speeds_rad_s: list[float] = [0.0, 0.0, 0.0, 0.0]
        self._lag_state: list[float] = [0.0, 0.0, 0.0, 0.0]  # the lag's, before coasting
        # without motor lag, coasting or thrust decay the forces hold over a control period
        self.constant = self.lag_tau is None and self.decay is None and self.coast is None

    def command(self, cmd: Quad) -> list[float]:
        """The speeds at once (no lag, no coasting): `constant` rotors."""
        self.speeds_rad_s[:] = cmd
        return self.speeds_rad_s

    def advance(self, cmd: Quad) -> list[float]:
        """The speeds after one physics step towards `cmd`."""
        n, tau, dt, coast = self.speeds_rad_s, self.lag_tau, self.dt_s, self.coast
        target = n if coast is None else self._lag_state
        if tau is None:
            target[:] = cmd
        else:
            for i in range(4):
                target[i] = motor_lag_step(target[i], cmd[i], dt, tau)
        if coast is not None:  # up as the lag goes, down no faster than coasting
            for i in range(4):
                n[i] = max(target[i], freewheel_rad_s(n[i], dt, coast))
        return n

    def forces(self, n: list[float], time_since_takeoff_s: float) -> Quad:
        """Equation 3.5 with the thrust curve, the thrust decay's scale and a rotor asymmetry,
        if any."""
        if self.decay is None:
            f = rotor_forces_n(self.c_t, n)
            pivot = self.curve_pivot_n
        else:
            self.thrust_scale = thrust_decay_scale(self.decay, time_since_takeoff_s)
            f = rotor_forces_n(self.c_t * self.thrust_scale, n)
            pivot = self.curve_pivot_n * self.thrust_scale
        if self.curve is not None:
            f = thrust_curve_forces_n(f, self.curve, pivot)
        return f if self.asym is None else asymmetric_forces_n(self.asym, f)
