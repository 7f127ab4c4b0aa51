"""The torque residual: per sample, the body-frame torque the model does not explain,
tau = I w' + w x (I w) - M_rotors - M_ground, with w' the mean over each control period from
the logged body rates (no log carries it), M_rotors from equation 3.6 on the rotor thrusts
(motor lag, thrust scale and ceiling boost of the world's values, as in the force model) and
M_ground the ground effect's lift at each hub about the centre of mass (the simulator's only
effect torque). On clean logs of a world the values describe it is 3e-8 N m (0.03% of the
rotor moments); white rate noise of 0.02 rad/s leaves about 1e-5 N m in a 0.1 s mean.
"""

from __future__ import annotations

import numpy as np

from learner.gap.candidates import Values
from learner.gap.flightdata import FlightData
from learner.gap.residual import force_gap_ms
from learner.gap.rotor_forces import rotor_forces_n
from simbridge.effects.ground import CeilingEffectParams, GroundEffectParams, thrust_gain_array
from simbridge.rotors import thrust_and_moments
from simbridge.vehicle import Vehicle


def torque_residual_n_m(d: FlightData, values: Values, vehicle: Vehicle) -> np.ndarray:
    """(N, 3) body-frame torque residual of one flight against a world with `values`."""
    w = d.rates_rad_s
    inertia = np.asarray(vehicle.inertia_kg_m2)
    # the period's mean angular acceleration, as the period's rotor speeds are its mean
    # commands: a centred derivative would sit half a period off the fast attitude loop
    new = np.concatenate([[True], d.segment[1:] != d.segment[:-1]])
    w_prev = np.where(new[:, None], w, np.roll(w, 1, axis=0))
    w_dot = (w - w_prev) / d.dt_s
    w = 0.5 * (w + w_prev)
    f = rotor_forces_n(values, d, vehicle)
    radius = vehicle.rotor_radius_m
    if "ceiling_effect" in values:
        p = CeilingEffectParams(rho=float(values["ceiling_effect"][0]))
        f = f * (1.0 + thrust_gain_array(d.rotor_ceilings_m, p.rho, radius, p.cutoff_for(radius)))
    _, mx, my, mz = thrust_and_moments(tuple(f.T), vehicle.arm_m, vehicle.yaw_moment_coefficient_m)
    modelled = np.column_stack([mx, my, mz])
    if "ground_effect" in values:
        p = GroundEffectParams(rho=float(values["ground_effect"][0]))
        lift = f * thrust_gain_array(d.rotor_heights_m, p.rho, radius, p.cutoff_for(radius))
        up_body = d.rotation[:, 2, :]  # world z in the body frame (R^T e_z)
        hubs = np.asarray(vehicle.rotor_positions_body_m())
        for i in range(4):
            modelled += np.cross(hubs[i], up_body * lift[:, i : i + 1])
    return inertia * w_dot + np.cross(w, inertia * w) - modelled


def torque_gap(
    flights: list[FlightData], nominal: Values, corrected: Values, vehicle: Vehicle
) -> dict[str, float]:
    """The systematic torque residual (RMS over samples of the 0.1 s average, N m) before
    and after the correction, pooled over `flights`."""
    out = {}
    for key, values in (("before", nominal), ("after", corrected)):
        parts = [
            force_gap_ms(torque_residual_n_m(d, values, vehicle), d.segment, d.dt_s) * len(d.time_s)
            for d in flights
        ]
        out[key] = float(np.sqrt(sum(parts) / sum(len(d.time_s) for d in flights)))
    before, after = out["before"], out["after"]
    out["shrink"] = (before - after) / before if before > 0 else 0.0
    return out
