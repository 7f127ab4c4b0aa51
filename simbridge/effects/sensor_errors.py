"""Sensor latency and bias, applied to what the HIL link reports (never to the physics).

Latency delays the IMU (HIL_SENSOR) and the state (HIL_STATE_QUATERNION, ODOMETRY, GPS)
by whole control periods, the IMU's also by a fraction of one (between two samples); bias
adds constants to accelerometer, gyro and position.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from simbridge.config import param

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class SensorLatencyParams:
    imu_delay_s: float = param(0.0, unit="s", lo=0.0, hi=1.0, doc="accelerometer and gyro delay")
    state_delay_s: float = param(0.0, unit="s", lo=0.0, hi=1.0, doc="state and position delay")


def delay_steps(delay_s: float, control_period_s: float) -> int:
    """A delay as a whole number of control periods (rounded to the nearest)."""
    return round(delay_s / control_period_s)


def delay_periods(delay_s: float, control_period_s: float) -> tuple[int, float]:
    """A delay as whole control periods and the fraction of one beyond them (0 for a whole
    number of periods, to the nanosecond)."""
    periods = delay_s / control_period_s
    whole = math.floor(periods + 1e-9)
    fraction = periods - whole
    return whole, (fraction if fraction > 1e-9 else 0.0)


@dataclass(frozen=True)
class SensorBiasParams:
    accel_bias_m_s2: Vec3 = param(
        (0.0, 0.0, 0.0),
        unit="m/s^2",
        lo=-20.0,
        hi=20.0,
        doc="accelerometer bias, body x forward, y left, z up",
    )
    gyro_bias_rad_s: Vec3 = param(
        (0.0, 0.0, 0.0),
        unit="rad/s",
        lo=-5.0,
        hi=5.0,
        doc="gyro bias, body x forward, y left, z up",
    )
    position_bias_m: Vec3 = param(
        (0.0, 0.0, 0.0), unit="m", lo=-10.0, hi=10.0, doc="position bias, world x, y, z"
    )


def add(v: Vec3, bias: Vec3) -> Vec3:
    return (v[0] + bias[0], v[1] + bias[1], v[2] + bias[2])
