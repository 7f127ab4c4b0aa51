"""The sensors' readings out of the HIL messages, in the autopilot's frames and units."""

from __future__ import annotations

from dataclasses import dataclass

from autopilot.types import Step
from simbridge.frames import Vec3, frd_to_flu


@dataclass(frozen=True)
class Imu:
    """Floats: the prediction on the control path takes them as they are (three numpy arrays
    would cost more than the prediction's arithmetic); the fusions make arrays as needed."""

    time_us: int
    specific_force: Vec3  # body FLU, m/s^2
    rates: Vec3  # body FLU, rad/s
    field: Vec3  # body FLU, gauss
    pressure_hpa: float


def imu_from(step: Step) -> Imu:
    s = step.sensor
    return Imu(
        s["time_usec"],
        frd_to_flu((s["xacc"], s["yacc"], s["zacc"])),
        frd_to_flu((s["xgyro"], s["ygyro"], s["zgyro"])),
        frd_to_flu((s["xmag"], s["ymag"], s["zmag"])),
        s["abs_pressure"],
    )


def pressure_altitude_m(pressure_hpa: float) -> float:
    """The international standard atmosphere's altitude of a pressure (troposphere)."""
    return (1.0 - (pressure_hpa / 1013.25) ** (1.0 / 5.25588)) / 2.25577e-5
