"""`--flight-log`: every airborne control step as a row of the gap diagnosis's log format
(learner/flightlogs/flightlog.py), written when the flight ends."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from autopilot.types import FlightState, Step
from learner.flightlogs.flightlog import FlightLog, write_log
from simbridge.frames import frd_to_flu, quat_to_matrix, rotate
from simbridge.rotors import Quad
from simbridge.vehicle import GRAVITY_M_S2


def kinematic_acceleration_m_s2(step: Step, state: FlightState) -> tuple[float, float, float]:
    """The accelerometer's specific force (body FRD) in the world frame, gravity removed: the
    vehicle's acceleration over the control period that ends at this step."""
    s = step.sensor
    a = rotate(quat_to_matrix(state.quaternion), frd_to_flu((s["xacc"], s["yacc"], s["zacc"])))
    return (a[0], a[1], a[2] - GRAVITY_M_S2)


class FlightLogWriter:
    """Collects rows: the state at the step's time, and the accelerometer and rotor commands
    of the control period that just ended."""

    def __init__(self, path: Path, meta: dict[str, Any]) -> None:
        self.path, self.meta = Path(path), meta
        self.rows: list[tuple[float, ...]] = []

    def __call__(self, t_s: float, step: Step, state: FlightState, applied_rad_s: Quad) -> None:
        self.rows.append(
            (
                t_s,
                *state.position_m,
                *state.velocity_m_s,
                *state.quaternion,
                *state.angular_velocity_body_rad_s,
                *applied_rad_s,
                *kinematic_acceleration_m_s2(step, state),
            )
        )

    def write(self) -> Path:
        d = np.asarray(self.rows, dtype=float).reshape(-1, 21)
        log = FlightLog(
            self.path.stem, d[:, 0], d[:, 1:4], d[:, 4:7], d[:, 7:11], d[:, 11:14], d[:, 14:18],
            acceleration_m_s2=d[:, 18:21], meta=self.meta,
        )  # fmt: skip
        return write_log(log, self.path)
