"""The estimator's edge: sensors out of the HIL messages, into the filter, a state out.

The control path reads only what this module estimates from the sensors (HIL_SENSOR's IMU,
magnetometer and barometer; ODOMETRY from motion capture; HIL_GPS; the downward range and
HIL_OPTICAL_FLOW). HIL_STATE_QUATERNION, the simulator's truth, is never read here.

The sources that correct the filter are declared in `autopilot.estimation.sources` (each with
its parameters, named as PX4's EKF2 names them, and its fusion) and fuse in their declared
order. The height reference (EKF2_HGT_REF, `autopilot.estimation.estimator_params`) falls
back, when its source goes quiet, to the next available of range, barometer, GPS. A downward
range reading also feeds a one-state terrain estimate (PX4's terrain estimator), so the height
above the surface below (the ground-effect model's input) is the estimated altitude minus the
terrain's.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from autopilot.estimation import estimator as ekf
from autopilot.estimation.attitude import attitude_from_gravity_and_field
from autopilot.estimation.estimator_params import HEIGHT_BARO, HEIGHT_NAMES, EstimatorParams
from autopilot.estimation.nav_history import PredictionHistory
from autopilot.estimation.sensors import Imu, imu_from, pressure_altitude_m
from autopilot.estimation.sources import SLOW_FUSION_EVERY, SOURCES, WAIT, Alignment
from autopilot.estimation.sources.gps import GPS_ALT
from autopilot.estimation.sources.gps import LABEL as GPS
from autopilot.estimation.sources.mocap import EV_VPOS
from autopilot.estimation.sources.mocap import LABEL as MOCAP
from autopilot.estimation.sources.range import LABEL as RANGE
from autopilot.estimation.terrain import Terrain, terrain_update
from autopilot.types import FlightState, Step
from simbridge.frames import Vec3

RESTING_SD_M = 0.0005  # how well a standing vehicle knows the surface under it
BARO_REF_STEPS = 250.0  # the barometer's reference averages its offset over about a second
# the covariance's prediction step (PX4's EKF2: 10 ms); a fusion between two uses the last
# prediction's covariance, short of at most this much process noise
COVARIANCE_PERIOD_S = 0.01
HISTORY_STEPS = 64  # 0.26 s at 250 Hz: the oldest delayed measurement that can be fused


@dataclass
class Quality:
    """Innovation test ratios (largest seen, last) and counts per source, for the summary."""

    fused: dict[str, int] = field(default_factory=dict)
    rejected: dict[str, int] = field(default_factory=dict)
    ratio_max: dict[str, float] = field(default_factory=dict)
    this_step: dict[str, float] = field(default_factory=dict)  # the ratios of the last update
    resets: int = 0

    def note(self, source: str, fused: ekf.Fused) -> None:
        book = self.fused if fused.accepted else self.rejected
        book[source] = book.get(source, 0) + 1
        self.this_step[source] = fused.test_ratio
        if math.isfinite(fused.test_ratio):
            self.ratio_max[source] = max(self.ratio_max.get(source, 0.0), fused.test_ratio)


class Navigation:
    """One flight's estimator: its state, the delayed-measurement history, the terrain."""

    def __init__(
        self, params: EstimatorParams, origin: tuple[float, float, float], resting_height_m: float
    ) -> None:
        self.params = params
        self.origin = origin
        self.resting_height_m = resting_height_m
        self.noise = ekf.ProcessNoise()
        self.estimate: ekf.Estimate | None = None
        self.quality = Quality()
        self._history = PredictionHistory(HISTORY_STEPS)  # for delayed measurements
        self._steps = 0
        self._pending_dt = 0.0  # IMU time not yet in the covariance, and its sums
        self._baro_sum, self._baro_n = 0.0, 0  # barometer innovations since the last fusion
        self._pending_f: Vec3 = (0.0, 0.0, 0.0)
        self._pending_w: Vec3 = (0.0, 0.0, 0.0)
        self._last_seen: dict[str, float] = {}
        self.memory: dict[str, Any] = {}  # what the sources keep from step to step
        self.range_m: float | None = None  # the step's downward range (the range source's)
        self.terrain = Terrain()
        self._baro_ref_m: float | None = None
        self._standing = False  # resting() was told this step
        self._standing_before = False  # ... and the step before
        self._aligned_z_m = 0.0  # the height the vehicle was aligned at
        self._rest_z_m: float | None = None  # the height it stands at
        self._home_terrain_m = 0.0  # the surface's height where the vehicle last stood
        self.height_source = HEIGHT_NAMES[params.hgt_ref]
        self.events: list[str] = []
        self._imu: Imu | None = None  # the sample `predict` took, for `correct`
        self._before: ekf.Estimate | None = None  # the estimate `predict` started from
        self._predicted: ekf.Estimate | None = None  # ... and the one it made
        self._aligned_now = False  # `predict` aligned the filter: nothing to correct yet

    # -- what the rest of the autopilot reads ---------------------------------------------

    @property
    def ready(self) -> bool:
        return self.estimate is not None

    def state(self) -> FlightState:
        e = self.estimate
        assert e is not None
        return FlightState(
            tuple(e.position_m.tolist()),
            tuple(e.velocity_m_s.tolist()),
            tuple(e.quaternion.tolist()),
            tuple(e.angular_velocity_body_rad_s.tolist()),
        )

    def accel_bias_m_s2(self) -> tuple[float, float, float]:
        assert self.estimate is not None
        b = self.estimate.accel_bias_m_s2
        return (float(b[0]), float(b[1]), float(b[2]))

    def height_m(self) -> float:
        """Centre of mass above the surface below."""
        assert self.estimate is not None
        return float(self.estimate.position_m[2]) - self.terrain_m

    @property
    def terrain_m(self) -> float:
        """The estimated height of the surface below (world z)."""
        return self.terrain.height_m

    def position_lost(self, t: float) -> str | None:
        """Why the horizontal position is no longer measured (a configured position source
        went quiet), or None."""
        timeout = self.params.source_timeout_s
        for source in SOURCES.values():
            seen = self._last_seen.get(source.label)
            wanted = source.gives_position(self.settings(source.name))
            if wanted and seen is not None and t - seen > timeout:
                return f"{source.label} lost"
        return None

    # -- what the sources use (`autopilot.estimation.sources`) -----------------------------

    def settings(self, source: str) -> Any:
        """The parameters of the declared source `source`."""
        settings = self.params.sources.get(source)
        return settings if settings is not None else _declared_defaults(source)

    @property
    def steps(self) -> int:
        """Control steps corrected since the alignment."""
        return self._steps

    def seen(self, label: str, t: float) -> None:
        """The source `label` spoke at `t` (it is lost after the sources' timeout)."""
        self._last_seen[label] = t

    def alive(self, label: str, t: float) -> bool:
        return t - self._last_seen.get(label, -math.inf) <= self.params.source_timeout_s

    def at_capture(self, time_us: int) -> tuple[Any, Any]:
        """The filter's position and attitude when a measurement was captured."""
        return self._history.at_capture(self.estimate, time_us)

    def fuse(self, source: str, fused: ekf.Fused) -> bool:
        """Takes a correction's result, counted under `source`; True if it was accepted."""
        self.quality.note(source, fused)
        self.estimate = fused.estimate
        return fused.accepted

    # -- one control step ------------------------------------------------------------------

    def predict(self, step: Step) -> None:
        """The state brought to this tick by its IMU sample: all the control path waits for.
        The measurements of the tick correct it in `correct`, after the reply (PX4's EKF2
        fuses behind an output predictor the same way), so they act one tick later."""
        self.quality.this_step.clear()
        imu = imu_from(step)
        self._imu = imu
        if self.estimate is None:
            self._initialise(step, imu)
            self._aligned_now = self.estimate is not None
            return
        self._aligned_now = False
        self._before = self.estimate
        self.estimate = ekf.predict_state(self._before, imu.time_us, imu.specific_force, imu.rates)
        self._predicted = self.estimate

    def correct(self, step: Step) -> None:
        """The covariance and the fusions of the tick `predict` took: off the control path."""
        imu = self._imu
        before, predicted = self._before, self._predicted
        if before is None or predicted is None or imu is None or self._aligned_now:
            return
        dt = (predicted.time_us - before.time_us) * 1e-6
        self._steps += 1
        # the covariance follows at COVARIANCE_PERIOD_S from the IMU's mean over the interval
        self._pending_dt += dt
        (sx, sy, sz), (fx, fy, fz) = self._pending_f, imu.specific_force
        self._pending_f = (sx + fx * dt, sy + fy * dt, sz + fz * dt)
        (sx, sy, sz), (wx, wy, wz) = self._pending_w, imu.rates
        self._pending_w = (sx + wx * dt, sy + wy * dt, sz + wz * dt)
        if self._pending_dt >= COVARIANCE_PERIOD_S:
            self._sync()
        # what the prediction moved and turned, for measurements captured in the past
        self._history.advance(before, predicted, dt, imu.time_us)
        t = imu.time_us * 1e-6
        self.range_m = None
        for source in SOURCES.values():
            source.fuse(self, step, imu, self.settings(source.name), t)
        self._fuse_height(imu, self.range_m, t)

    def _sync(self) -> None:
        """The covariance brought up to the present state's time."""
        dt = self._pending_dt
        if dt <= 0.0:
            return
        assert self.estimate is not None
        (fx, fy, fz), (wx, wy, wz) = self._pending_f, self._pending_w
        self.estimate = ekf.predict_covariance(
            self.estimate,
            min(dt, 0.1),
            (fx / dt, fy / dt, fz / dt),
            (wx / dt, wy / dt, wz / dt),
            self.noise,
        )
        self._pending_dt = 0.0
        self._pending_f = (0.0, 0.0, 0.0)
        self._pending_w = (0.0, 0.0, 0.0)

    # -- initial alignment --------------------------------------------------------------------

    def _initialise(self, step: Step, imu: Imu) -> None:
        aligned: list[tuple[str, Alignment]] = []
        for source in SOURCES.values():
            if source.align is not None:
                alignment = source.align(self, step, imu, self.settings(source.name))
                if alignment is WAIT:
                    return  # a source that is on has not spoken yet
                if alignment is not None:
                    aligned.append((source.label, alignment))
        positions = [a for _, a in aligned if a.position_m is not None]
        attitudes = [a for _, a in aligned if a.quaternion is not None]
        if attitudes:
            q = np.array(attitudes[0].quaternion)
            attitude_sd = attitudes[0].attitude_sd_rad
        else:
            q = attitude_from_gravity_and_field(
                np.array(imu.specific_force),
                np.array(imu.field),
                self.settings("magnetometer").field_world(),
            )
            attitude_sd = 0.05
        for label, alignment in aligned:
            if alignment.seen:
                self.seen(label, imu.time_us * 1e-6)
        if positions:
            position = np.array(positions[0].position_m)
            position_sd = positions[0].position_sd_m
        else:  # the local frame starts where the vehicle stands
            position = np.array([0.0, 0.0, self.resting_height_m])
            position_sd = 0.01
        self.estimate = ekf.initial(imu.time_us, position, q, position_sd, attitude_sd)
        self._baro_ref_m = pressure_altitude_m(imu.pressure_hpa) - position[2]
        self._aligned_z_m = float(position[2])
        self._history.record(imu.time_us)
        self.events.append(
            f"estimator aligned ({', '.join(self.sources())}; height {self.height_source})"
        )

    def sources(self) -> list[str]:
        names = [
            source.label
            for source in SOURCES.values()
            if source.active(self, self.settings(source.name))
        ]
        p = self.params
        if p.baro_ctrl and p.hgt_ref == HEIGHT_BARO:
            names.append("barometer")
        return names

    def _height_source(self, t: float, range_m: float | None) -> str:
        """The reference if it is alive, else the first live fallback; over a baro or GPS
        reference, the range while low and slow (range aid, EKF2_RNG_CTRL 1)."""
        p = self.params
        rng = self.settings("range")
        alive = {
            "vision": bool(self.settings("mocap").ev_ctrl & EV_VPOS) and self.alive(MOCAP, t),
            "range": bool(rng.rng_ctrl) and self.alive(RANGE, t),
            "baro": bool(p.baro_ctrl),
            "gps": bool(self.settings("gps").gps_ctrl & GPS_ALT)
            and t - self._last_seen.get(GPS, -math.inf) <= 1.0,
        }
        wanted = HEIGHT_NAMES[p.hgt_ref]
        if (
            wanted in ("baro", "gps")
            and rng.rng_ctrl == 1
            and alive["range"]
            and self._aiding(range_m)
        ):
            return "range"
        if alive[wanted]:
            return wanted
        for name in ("range", "baro", "gps"):
            if alive[name]:
                return name
        return wanted

    def _aiding(self, range_m: float | None) -> bool:
        """Range aid's conditions, with hysteresis: in below 80 % of the height limit, out
        above it (or too fast)."""
        e = self.estimate
        assert e is not None
        if range_m is None:
            return self.height_source == "range"
        rng = self.settings("range")
        limit = rng.rng_aid_max_height_m * (1.0 if self.height_source == "range" else 0.8)
        speed = float(np.hypot(e.velocity_m_s[0], e.velocity_m_s[1]))
        return range_m <= limit and speed <= rng.rng_aid_max_speed_m_s

    def _fuse_height(self, imu: Imu, range_m: float | None, t: float) -> None:
        p = self.params
        rng = self.settings("range")
        source = self._height_source(t, range_m)
        if source != self.height_source:
            self.events.append(f"estimator: height from {source} (was {self.height_source})")
            self.quality.resets += 1
            aid = HEIGHT_NAMES[p.hgt_ref] in ("baro", "gps") and rng.rng_ctrl == 1
            if source == "range":
                # heights above the surface from now on: under range aid, above the surface
                # the vehicle stood on (PX4 resets its height to the range's the same way),
                # so that a low waypoint means its height above the ground, whatever the
                # barometer drifted on the way
                self.terrain = Terrain(self._home_terrain_m if aid else 0.0)
            self.height_source = source
        e = self.estimate
        assert e is not None
        # the barometer's reference follows the estimate while something else gives the
        # height (or the vehicle stands still), averaged over BARO_REF_STEPS: when it takes
        # over, it does so where the estimate is, without a jump
        offset = pressure_altitude_m(imu.pressure_hpa) - float(e.position_m[2])
        if self._baro_ref_m is None:
            self._baro_ref_m = offset
        elif source != "baro" or self._standing:
            self._baro_ref_m += (offset - self._baro_ref_m) / BARO_REF_STEPS
        self._standing_before, self._standing = self._standing, False
        _, qx, qy, _ = e.quaternion.tolist()
        tilt_cos = 1 - 2 * (qx * qx + qy * qy)  # R(q)[2, 2]
        if range_m is not None and rng.rng_ctrl:
            height = range_m * tilt_cos
            sd = rng.sd_m(range_m)
            if source == "range":
                fused = ekf.fuse_height(self.estimate, height, self.terrain_m, sd, p.gate_sd)
                self.fuse(RANGE, fused)
            else:
                self._terrain(float(e.position_m[2]) - height, sd, e)
        if source == "baro" and p.baro_ctrl and self._baro_ref_m is not None:
            # the mean of the readings since the last fusion, against the present height
            # less what it climbed since (the velocity's integral): fused at 50 Hz
            self._baro_sum += (
                pressure_altitude_m(imu.pressure_hpa) - self._baro_ref_m - float(e.position_m[2])
            )
            self._baro_n += 1
            if self._steps % SLOW_FUSION_EVERY == 0:
                z = float(self.estimate.position_m[2]) + self._baro_sum / self._baro_n
                self.fuse("barometer", ekf.fuse_height(
                    self.estimate, z, 0.0, p.baro_noise_m, p.gate_sd
                ))  # fmt: skip
                self._baro_sum, self._baro_n = 0.0, 0

    def resting(self) -> None:
        """The vehicle stands on the surface (disarmed, or idling before take-off): the
        surface is where its height says, to the estimate's precision (PX4 aligns its
        terrain estimate on the ground the same way)."""
        e = self.estimate
        if e is None:
            return
        if not self._standing_before:  # come to rest: aligned here, or landed here
            self._rest_z_m = self._aligned_z_m if self._rest_z_m is None else e.position_m[2]
        self._standing = True
        if (
            self.height_source in ("baro", "gps")
            and self._rest_z_m is not None
            and self._steps % SLOW_FUSION_EVERY == 0
        ):
            e = self.estimate
            # standing still, it does not climb: a barometer's or a fix's noise must not
            # move it (the barometer's reference meanwhile averages its offset)
            self.fuse("at rest", ekf.fuse_height(e, self._rest_z_m, 0.0, RESTING_SD_M, 1e3))
            e = self.estimate
        if self.height_source == "range":
            return
        self._terrain(float(e.position_m[2]) - self.resting_height_m, RESTING_SD_M, e)
        self._home_terrain_m = self.terrain.height_m

    def _terrain(self, measured_m: float, sd_m: float, e: ekf.Estimate) -> None:
        speed = float(np.hypot(e.velocity_m_s[0], e.velocity_m_s[1]))
        variance = sd_m * sd_m + float(e.covariance[2, 2])
        self.terrain, reset = terrain_update(self.terrain, measured_m, variance, speed, e.time_us)
        self.quality.resets += reset


@functools.cache
def _declared_defaults(source: str) -> Any:
    return SOURCES[source].settings()
