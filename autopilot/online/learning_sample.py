"""One row of a learning dataset from a control step's measurements (thesis equation 3.16)."""

from __future__ import annotations

import math

from autopilot.types import FlightState, Step
from simbridge.frames import Vec3, frd_to_flu, quat_to_matrix, rotate
from simbridge.rotors import Quad
from simbridge.sensors.esc import RAD_S_TO_RPM
from simbridge.vehicle import GRAVITY_M_S2, Vehicle


def learning_sample(
    t: float,
    step: Step,
    state: FlightState,
    height: float,
    applied_rad_s: Quad,
    vehicle: Vehicle,
    accel_bias_m_s2: Vec3 = (0.0, 0.0, 0.0),
) -> tuple[float, ...]:
    """One row of a learning dataset (learner.dataset.COLUMNS), from this step's messages.

    The accelerometer's specific force is the mean over the control period that just ended,
    under the rotor speeds sent for it (`applied_rad_s`); equation 3.16 then gives the force
    nothing else explains: f_ge = m a - m g - R f_rotors (g pointing down).
    """
    m = quat_to_matrix(state.quaternion)
    sensor = step.sensor
    f = frd_to_flu((sensor["xacc"], sensor["yacc"], sensor["zacc"]))
    b = accel_bias_m_s2  # the estimator's: a real vehicle's corrected accelerometer
    a = rotate(m, (f[0] - b[0], f[1] - b[1], f[2] - b[2]))
    a = (a[0], a[1], a[2] - GRAVITY_M_S2)
    thrust = vehicle.thrust_coefficient_n_s2 * sum(n * n for n in applied_rad_s)
    mass = vehicle.mass_kg
    target = (
        mass * a[0] - m[2] * thrust,
        mass * a[1] - m[5] * thrust,
        mass * a[2] + mass * GRAVITY_M_S2 - m[8] * thrust,
    )
    esc = step.latest.get("ESC_TELEMETRY_1_TO_4")
    actual = tuple(r / RAD_S_TO_RPM for r in esc["rpm"]) if esc else (math.nan,) * 4
    truth = step.latest.get("DEBUG_VECT")
    true_ge = (truth["x"], truth["y"], truth["z"]) if truth else (math.nan,) * 3
    v, q = state.velocity_m_s, state.quaternion
    return (t, height, *v, *q, *applied_rad_s, *a, *actual, *target, *true_ge)
