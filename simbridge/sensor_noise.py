"""Realistic sensor errors: datasheet-level noise, turn-on biases and bias drift.

The simulator reports what a nano quadrotor's sensors would measure, not the truth. Each
figure is settable in the world file (`sensor_noise:`); `SensorNoise.ideal()` (the
`--ideal-sensors` flag) turns every error off: the truth, on time. The IMU's, magnetometer's
and barometer's figures are here; each other sensor declares its own with it
(`simbridge.sensors`), and `SensorNoise` holds them all.

Sources of the defaults:
- IMU, a Bosch BMI088 (the Crazyflie 2.1's): accelerometer noise density 175 ug/sqrt(Hz)
  (1.7e-3 m/s^2/sqrt(Hz)), gyro 0.014 deg/s/sqrt(Hz) (2.4e-4 rad/s/sqrt(Hz)), datasheet
  BST-BMI088-DS001 table 1-2. Turn-on biases after a level calibration: 5 mg and 0.3 deg/s
  (the uncalibrated datasheet offsets are 20 mg and 1 deg/s). Bias drift as random walks of
  1e-4 m/s^2/sqrt(s) and 1e-5 rad/s/sqrt(s) (bias instability of a few deg/h).
- Magnetometer (BMM150 class): 3 mG white noise. Barometer (BMP388): 1 Pa white noise at
  the vehicle (datasheet RMS noise 0.03 Pa; propeller wash dominates in flight).

Noise is drawn from a seeded generator: a world file and a seed give the same flight.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass
from typing import Any

import numpy as np

from simbridge.config import param
from simbridge.sensors import SENSORS

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class ImuNoise:
    """The seed and the figures of the sensors in HIL_SENSOR."""

    seed: int = param(1, lo=0, hi=2**31 - 1, doc="seed of every sensor error of the flight")
    accel_noise_density: float = param(
        1.7e-3, unit="m/s^2/sqrt(Hz)", lo=0.0, hi=1.0, doc="accelerometer white noise (BMI088)"
    )
    accel_bias_sd_m_s2: float = param(
        0.05, unit="m/s^2", lo=0.0, hi=5.0, doc="turn-on bias per axis, standard deviation"
    )
    accel_bias_walk: float = param(
        1e-4, unit="m/s^2/sqrt(s)", lo=0.0, hi=1.0, doc="accelerometer bias random walk"
    )
    gyro_noise_density: float = param(
        2.4e-4, unit="rad/s/sqrt(Hz)", lo=0.0, hi=1.0, doc="gyro white noise (BMI088)"
    )
    gyro_bias_sd_rad_s: float = param(
        0.005, unit="rad/s", lo=0.0, hi=1.0, doc="gyro turn-on bias per axis, standard deviation"
    )
    gyro_bias_walk: float = param(
        1e-5, unit="rad/s/sqrt(s)", lo=0.0, hi=1.0, doc="gyro bias random walk"
    )
    mag_noise_gauss: float = param(0.003, unit="gauss", lo=0.0, hi=1.0, doc="white noise")
    baro_noise_hpa: float = param(0.01, unit="hPa", lo=0.0, hi=10.0, doc="white noise")

    @classmethod
    def ideal(cls) -> Any:
        """Every error off: the sensors report the truth, on time."""
        return cls(**{f.name: 0.0 for f in dataclasses.fields(cls) if f.name != "seed"})

    @property
    def is_ideal(self) -> bool:
        return self == self.ideal()


def _noise_fields() -> list[tuple[str, Any, Any]]:
    """Each declared sensor's error figures, as fields of `SensorNoise`."""
    fields: list[tuple[str, Any, Any]] = []
    for sensor in SENSORS.values():
        if sensor.noise is None:
            continue
        hints = typing.get_type_hints(sensor.noise)
        for f in dataclasses.fields(sensor.noise):
            field = dataclasses.field(default=f.default, metadata=f.metadata)
            fields.append((f.name, hints[f.name], field))
    names = [name for name, _, _ in fields] + [f.name for f in dataclasses.fields(ImuNoise)]
    if len(set(names)) < len(names):
        raise ValueError(f"sensor noise fields declared twice: {sorted(names)}")
    return fields


SensorNoise = dataclasses.make_dataclass(
    "SensorNoise", _noise_fields(), bases=(ImuNoise,), frozen=True
)
SensorNoise.__module__ = __name__
SensorNoise.__doc__ = "Every sensor's error figures (the world file's `sensor_noise:`)."


def white_sd(noise_density: float, period_s: float) -> float:
    """Standard deviation of a sample averaged over `period_s` of white noise."""
    return noise_density / math.sqrt(period_s) if period_s > 0.0 else 0.0


NORMALS_PER_DRAW = 4096  # standard normals drawn at once: a call per value costs ~1 us


class SensorErrors:
    """The flight's random state: turn-on biases, their walks, and the generator.

    The edge of the pure parameters above: one per simulated flight, advanced once per
    control step by the HIL encoder. Normals come from the seeded generator in blocks, as
    Python floats (a few values a message: numpy's per-call cost would dominate), in the
    order one call per value would draw them: a seed gives the same errors either way.
    """

    def __init__(self, noise: SensorNoise, period_s: float) -> None:
        self.noise, self.period_s = noise, period_s
        self._rng = np.random.default_rng(noise.seed)
        self._normals: list[float] = []
        self._next = 0
        self.accel_bias = self._vector3(noise.accel_bias_sd_m_s2)
        self.gyro_bias = self._vector3(noise.gyro_bias_sd_rad_s)
        self._accel_sd = white_sd(noise.accel_noise_density, period_s)
        self._gyro_sd = white_sd(noise.gyro_noise_density, period_s)
        self._accel_walk = noise.accel_bias_walk * math.sqrt(period_s)
        self._gyro_walk = noise.gyro_bias_walk * math.sqrt(period_s)
        self.ideal = noise.is_ideal
        # every IMU error on (the default): a sample's 12 normals are taken in one slice
        self._imu_sds = (self._accel_walk, self._gyro_walk, self._accel_sd, self._gyro_sd)
        self._imu_all = min(self._imu_sds) > 0.0

    def _normal(self) -> float:
        i = self._next
        if i == len(self._normals):
            self._normals = self._rng.standard_normal(NORMALS_PER_DRAW).tolist()
            i = 0
        self._next = i + 1
        return self._normals[i]

    def _take(self, count: int) -> list[float]:
        """The next `count` normals, the same as `count` calls of `_normal`."""
        i = self._next
        j = i + count
        if j <= len(self._normals):
            self._next = j
            return self._normals[i:j]
        return [self._normal() for _ in range(count)]

    def _vector3(self, sd: float) -> Vec3:
        if sd <= 0.0:
            return (0.0, 0.0, 0.0)
        return (sd * self._normal(), sd * self._normal(), sd * self._normal())

    def imu(self, specific_force_flu: Vec3, rates_flu: Vec3) -> tuple[Vec3, Vec3]:
        """One IMU sample (body FLU) with bias and white noise; the biases walk one step."""
        if self.ideal:
            return specific_force_flu, rates_flu
        ab, gb = self.accel_bias, self.gyro_bias
        a, w = specific_force_flu, rates_flu
        if self._imu_all:  # the same arithmetic as below, in the same order
            z0, z1, z2, z3, z4, z5, z6, z7, z8, z9, z10, z11 = self._take(12)
            aw_sd, gw_sd, a_sd, g_sd = self._imu_sds
            ab = (ab[0] + aw_sd * z0, ab[1] + aw_sd * z1, ab[2] + aw_sd * z2)
            gb = (gb[0] + gw_sd * z3, gb[1] + gw_sd * z4, gb[2] + gw_sd * z5)
            self.accel_bias, self.gyro_bias = ab, gb
            return (
                (a[0] + ab[0] + a_sd * z6, a[1] + ab[1] + a_sd * z7, a[2] + ab[2] + a_sd * z8),
                (w[0] + gb[0] + g_sd * z9, w[1] + gb[1] + g_sd * z10, w[2] + gb[2] + g_sd * z11),
            )
        aw, gw = self._vector3(self._accel_walk), self._vector3(self._gyro_walk)
        ab = (ab[0] + aw[0], ab[1] + aw[1], ab[2] + aw[2])
        gb = (gb[0] + gw[0], gb[1] + gw[1], gb[2] + gw[2])
        self.accel_bias, self.gyro_bias = ab, gb
        an, gn = self._vector3(self._accel_sd), self._vector3(self._gyro_sd)
        return (
            (a[0] + ab[0] + an[0], a[1] + ab[1] + an[1], a[2] + ab[2] + an[2]),
            (w[0] + gb[0] + gn[0], w[1] + gb[1] + gn[1], w[2] + gb[2] + gn[2]),
        )

    def vector(self, value: Vec3, sd: float) -> Vec3:
        if sd <= 0.0:
            return value
        e = self._vector3(sd)
        return (value[0] + e[0], value[1] + e[1], value[2] + e[2])

    def scalar(self, value: float, sd: float) -> float:
        return value + sd * self._normal() if sd > 0.0 else value

    def attitude(
        self, quaternion: tuple[float, float, float, float], sd: float
    ) -> tuple[float, ...]:
        """The quaternion turned by a small random rotation, `sd` rad per axis."""
        if sd <= 0.0:
            return quaternion
        e0, e1, e2 = self._vector3(sd)
        e = (e0 * 0.5, e1 * 0.5, e2 * 0.5)
        w, x, y, z = quaternion
        # q * dq, dq = (1, e) to first order, renormalised
        qw = w - x * e[0] - y * e[1] - z * e[2]
        qx = x + w * e[0] + y * e[2] - z * e[1]
        qy = y + w * e[1] + z * e[0] - x * e[2]
        qz = z + w * e[2] + x * e[1] - y * e[0]
        norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        return (qw / norm, qx / norm, qy / norm, qz / norm)
