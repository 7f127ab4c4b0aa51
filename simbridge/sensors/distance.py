"""A downward flow-and-range deck (Crazyflie flow deck v2: a VL53L1x and a PMW3901):
DISTANCE_SENSOR (whole cm) and HIL_OPTICAL_FLOW (flow, and the same range in float metres).

Its errors: the range (ST VL53L1x) 2.5 mm standard deviation at short range, growing 1 % per
metre, the Crazyflie firmware's measurement model; the flow (PixArt PMW3901) 2 pixels per
measurement (the Crazyflie firmware's flowStdFixed) at 4.2 deg / 35 pixels: 2.1e-3 rad of
integrated flow.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from simbridge.config import param
from simbridge.frames import flu_to_frd, rotate_transposed
from simbridge.sensors import Frame, SensorContext, SimSensor, mavlink, register

if TYPE_CHECKING:
    from simbridge.sensor_noise import SensorErrors
    from simbridge.sim_state import VehicleState


@dataclass(frozen=True)
class FlowDeckNoise:
    range_noise_m: float = param(
        0.0025, unit="m", lo=0.0, hi=1.0, doc="range standard deviation at short range"
    )
    range_noise_per_m: float = param(
        0.01, unit="1", lo=0.0, hi=1.0, doc="added range standard deviation per metre"
    )
    flow_noise_rad: float = param(
        2.1e-3, unit="rad", lo=0.0, hi=1.0, doc="integrated optical flow per measurement"
    )


def measured_range_m(errors: SensorErrors, range_m: float) -> float:
    """A range with its error (none beyond the sensor's reach)."""
    n = errors.noise
    if not math.isfinite(range_m):
        return range_m
    return max(0.0, errors.scalar(range_m, n.range_noise_m + n.range_noise_per_m * range_m))


class FlowDeck:
    history_steps = 0  # the state through the state's latency

    def __init__(self, ctx: SensorContext) -> None:
        self.ctx = ctx
        self._pack_distance = ctx.packer(mavlink.MAVLink_distance_sensor_message)
        self._pack_flow = ctx.packer(mavlink.MAVLink_hil_optical_flow_message)
        world = ctx.world
        per_step = world.samples_per_step(world.sensors.rate_hz(FLOW_DECK.name))
        # the step of the last sample (the first integrates one nominal period)
        self._last_step = -max(1, round(1.0 / per_step)) if per_step > 0.0 else 0
        self._max_cm = round(ctx.vehicle.range_sensor_max_m * 100.0)

    def __call__(self, time_us: int) -> list[Frame]:
        s = self.ctx.delayed(self.ctx.state_delay)
        range_m = measured_range_m(self.ctx.errors, s.range_m)
        return [self._distance(range_m, time_us), self._flow(s, range_m, time_us)]

    def _distance(self, range_m: float, time_us: int) -> Frame:
        max_cm = self._max_cm
        # MAVLink: max_distance + 1 means nothing in range.
        current = max_cm + 1 if range_m == math.inf else min(max_cm, round(range_m * 100.0))
        return self._pack_distance, (
            time_us // 1000,
            1,
            max_cm,
            current,
            mavlink.MAV_DISTANCE_SENSOR_LASER,
            0,
            mavlink.MAV_SENSOR_ROTATION_PITCH_270,
            0,
            0.0,
            0.0,
            (0.0, 0.0, 0.0, 0.0),
            0,
        )

    def _flow(self, s: VehicleState, range_m: float, time_us: int) -> Frame:
        """The range in float metres; flow integrated over the message interval from the
        current rates and velocity (sensor frame = body FRD):
        x = (p - v_y / h) dt, y = (q + v_x / h) dt."""
        ctx = self.ctx
        # integrated since the last sample (at a rate that is no whole number of steps, the
        # interval alternates)
        steps = max(1, ctx.steps - self._last_step)
        self._last_step = ctx.steps
        dt = steps * ctx.world.control_period_s
        rates = flu_to_frd(s.angular_velocity_body_rad_s)
        v = flu_to_frd(rotate_transposed(s.rotation, s.velocity_m_s))
        h = s.range_m
        known = math.isfinite(h) and h > 0.0
        errors = ctx.errors
        flow_sd = errors.noise.flow_noise_rad
        flow_x = errors.scalar((rates[0] - v[1] / h) * dt, flow_sd) if known else 0.0
        flow_y = errors.scalar((rates[1] + v[0] / h) * dt, flow_sd) if known else 0.0
        return self._pack_flow, (
            time_us,
            0,
            round(dt * 1e6),
            flow_x,
            flow_y,
            rates[0] * dt,
            rates[1] * dt,
            rates[2] * dt,
            2000,
            255 if known else 0,
            0,
            range_m if known else -1.0,
        )


FLOW_DECK = register(SimSensor(
    name="flow_deck",
    rate_key="distance_sensor_hz",
    rate_hz=50.0,
    doc="DISTANCE_SENSOR and HIL_OPTICAL_FLOW (a VL53L1x ranges at 50 Hz)",
    sampler=FlowDeck,
    noise=FlowDeckNoise,
))  # fmt: skip
