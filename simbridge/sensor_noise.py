"""Realistic sensor errors: datasheet-level noise, turn-on biases and bias drift.

The simulator reports what a nano quadrotor's sensors would measure, not the truth. Each
figure is settable in the world file (`sensor_noise:`); `SensorNoise.ideal()` (the
`--ideal-sensors` flag) turns every error off, which is how flights were simulated before.

Sources of the defaults:
- IMU, a Bosch BMI088 (the Crazyflie 2.1's): accelerometer noise density 175 ug/sqrt(Hz)
  (1.7e-3 m/s^2/sqrt(Hz)), gyro 0.014 deg/s/sqrt(Hz) (2.4e-4 rad/s/sqrt(Hz)), datasheet
  BST-BMI088-DS001 table 1-2. Turn-on biases after a level calibration: 5 mg and 0.3 deg/s
  (the uncalibrated datasheet offsets are 20 mg and 1 deg/s). Bias drift as random walks of
  1e-4 m/s^2/sqrt(s) and 1e-5 rad/s/sqrt(s) (bias instability of a few deg/h).
- Magnetometer (BMM150 class): 3 mG white noise. Barometer (BMP388): 1 Pa white noise at
  the vehicle (datasheet RMS noise 0.03 Pa; propeller wash dominates in flight).
- Range, a ST VL53L1x (Crazyflie flow deck v2): 2.5 mm standard deviation at short range,
  growing 1 % per metre, the Crazyflie firmware's measurement model.
- Optical flow, a PixArt PMW3901: 2 pixels per measurement (the Crazyflie firmware's
  flowStdFixed) at 4.2 deg / 35 pixels: 2.1e-3 rad of integrated flow.
- Motion capture (Vicon/OptiTrack class, as indoor nano drones fly): 1 mm and 0.1 deg,
  100 Hz, about 10 ms latency (sent by `simbridge.world.SensorRates.odometry_hz`).
- GPS (u-blox M8 class): 0.5 m horizontal and 0.8 m vertical white noise, 0.1 m/s velocity.

Noise is drawn from a seeded generator: a world file and a seed give the same flight.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from simbridge.config import param

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class SensorNoise:
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
    range_noise_m: float = param(
        0.0025, unit="m", lo=0.0, hi=1.0, doc="range standard deviation at short range"
    )
    range_noise_per_m: float = param(
        0.01, unit="1", lo=0.0, hi=1.0, doc="added range standard deviation per metre"
    )
    flow_noise_rad: float = param(
        2.1e-3, unit="rad", lo=0.0, hi=1.0, doc="integrated optical flow per measurement"
    )
    mocap_position_m: float = param(0.001, unit="m", lo=0.0, hi=1.0, doc="per axis")
    mocap_attitude_rad: float = param(0.0017, unit="rad", lo=0.0, hi=1.0, doc="per axis")
    mocap_latency_s: float = param(
        0.012, unit="s", lo=0.0, hi=1.0, doc="delay of the motion-capture pose (whole periods)"
    )
    gps_horizontal_m: float = param(0.5, unit="m", lo=0.0, hi=100.0, doc="per axis")
    gps_vertical_m: float = param(0.8, unit="m", lo=0.0, hi=100.0, doc="altitude")
    gps_velocity_m_s: float = param(0.1, unit="m/s", lo=0.0, hi=10.0, doc="per axis")

    @staticmethod
    def ideal() -> SensorNoise:
        """Every error off: the sensors report the truth, on time."""
        zeros = {f.name: 0.0 for f in dataclasses.fields(SensorNoise) if f.name != "seed"}
        return SensorNoise(**zeros)

    @property
    def is_ideal(self) -> bool:
        return self == SensorNoise.ideal()


def white_sd(noise_density: float, period_s: float) -> float:
    """Standard deviation of a sample averaged over `period_s` of white noise."""
    return noise_density / math.sqrt(period_s) if period_s > 0.0 else 0.0


NORMALS_PER_DRAW = 4096  # standard normals drawn at once: a call per value costs ~1 us


class SensorErrors:
    """The flight's random state: turn-on biases, their walks, and the generator.

    The edge of the pure parameters above: one per simulated flight, advanced once per
    control step by the HIL encoder. Normals come from the seeded generator in blocks, as
    Python floats (a few values a message: numpy's per-call cost would dominate), in the
    order one call per value would draw them: a seed gives the same errors as before.
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

    def range_m(self, range_m: float) -> float:
        n = self.noise
        if not math.isfinite(range_m):
            return range_m
        return max(0.0, self.scalar(range_m, n.range_noise_m + n.range_noise_per_m * range_m))

    def attitude(self, quaternion: tuple[float, float, float, float]) -> tuple[float, ...]:
        """The quaternion turned by a small random rotation (mocap attitude noise)."""
        sd = self.noise.mocap_attitude_rad
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
