"""Where a flight rests on a surface (before take-off, after landing): rows with the rotors
near stopped, the vehicle still and at its lowest. `learner.gap.ground_level` finds the
ground in the log's frame from them; `groundfx gap convert` prints where they sit."""

from __future__ import annotations

import numpy as np

from learner.flightlogs.flightlog import FlightLog
from simbridge.vehicle import Vehicle

# Resting: the rotors carry less than this share of the weight, the vehicle moves slower
# than REST_SPEED_M_S, within REST_BAND_M of the flight's lowest point, for REST_MIN_S (the
# neural-swarm take-off flights rest 0.05-0.1 s between a landing and the next take-off; a
# hover never has its rotors this slow, a free fall never moves this slowly).
REST_THRUST_SHARE = 0.3
REST_SPEED_M_S = 0.1
REST_BAND_M = 0.01
REST_MIN_S = 0.04


def resting_rows(log: FlightLog, vehicle: Vehicle) -> np.ndarray:
    """(N,) rows where the vehicle rests on a surface: rotors near stopped, still, at its
    lowest, for at least REST_MIN_S in a row (a free fall's last rows after the motors cut
    move too fast to count)."""
    if len(log.time_s) < 2:
        return np.zeros(len(log.time_s), bool)
    thrust_n = vehicle.thrust_coefficient_n_s2 * np.sum(log.rotor_speeds_rad_s**2, axis=1)
    speed = np.linalg.norm(log.velocity_m_s, axis=1)
    z = log.position_m[:, 2]
    still = (
        (thrust_n < REST_THRUST_SHARE * vehicle.weight_n)
        & (speed < REST_SPEED_M_S)
        & (z < np.min(z) + REST_BAND_M)
    )
    dt = float(np.median(np.diff(log.time_s)))
    min_rows = max(2, int(np.ceil(REST_MIN_S / dt - 1e-9)))
    # runs of consecutive resting rows, kept when long enough
    edges = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    out = np.zeros(len(z), bool)
    for a, b in zip(starts, ends, strict=True):
        if b - a >= min_rows:
            out[a:b] = True
    return out
