"""HIL_ACTUATOR_CONTROLS, the autopilot's half of the HIL link: the flags both ends set and
read, and the decoding of a reply into rotor speed commands (the simulator's, at every
lockstep step; the encoding of the other half is `hil`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

from simbridge.hil import mavlink
from simbridge.vehicle import Vehicle

LOCKSTEP_FLAG = 1  # HIL_ACTUATOR_CONTROLS.flags bit 0
ARMED_MODE = mavlink.MAV_MODE_FLAG_SAFETY_ARMED


class ActuatorCommand(NamedTuple):
    """One HIL_ACTUATOR_CONTROLS decoded: rotor speed commands and the flags that matter (a
    named tuple: one is made at every lockstep step)."""

    time_us: int  # the sensor time it answers (PX4 stamps it with its lockstep clock)
    rotor_speeds_rad_s: tuple[float, float, float, float]
    armed: bool
    lockstep: bool
    clamped: int  # values that were NaN or outside [0, 1]


def _clamped(c: float) -> float:
    return 0.0 if math.isnan(c) else min(max(c, 0.0), 1.0)


def decode_actuators(
    time_us: int, controls: Sequence[float], mode: int, flags: int, vehicle: Vehicle
) -> ActuatorCommand:
    """controls[ch] in [0, 1] is n / n_max of the rotor on channel ch; bad values are clamped."""
    ch0, ch1, ch2, ch3 = vehicle.actuator_channels
    c0, c1, c2, c3 = controls[ch0], controls[ch1], controls[ch2], controls[ch3]
    clamped = 0
    # written out: decoded at every lockstep step; `not 0 <= c <= 1` is also true for NaN
    if not (0.0 <= c0 <= 1.0 and 0.0 <= c1 <= 1.0 and 0.0 <= c2 <= 1.0 and 0.0 <= c3 <= 1.0):
        clamped = sum(not 0.0 <= c <= 1.0 for c in (c0, c1, c2, c3))
        c0, c1, c2, c3 = _clamped(c0), _clamped(c1), _clamped(c2), _clamped(c3)
    n = vehicle.max_rotor_speed_rad_s
    return ActuatorCommand(
        time_us,
        (c0 * n, c1 * n, c2 * n, c3 * n),
        bool(mode & ARMED_MODE),
        bool(flags & LOCKSTEP_FLAG),
        clamped,
    )
