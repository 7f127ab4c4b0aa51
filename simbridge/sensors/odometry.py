"""Motion capture: ODOMETRY, a pose in floats, late by the capture system's latency and
stamped with its capture time.

Its errors, a Vicon/OptiTrack class system as indoor nano drones fly: 1 mm and 0.1 deg at
100 Hz, about 10 ms latency.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from simbridge.config import param
from simbridge.effects.sensor_errors import delay_steps
from simbridge.frames import enu_to_ned, flu_to_frd, quat_enu_flu_to_ned_frd, rotate_transposed
from simbridge.sensors import Frame, SensorContext, SimSensor, mavlink, register

UNKNOWN_COVARIANCE = [math.nan] + [0.0] * 20


@dataclass(frozen=True)
class MocapNoise:
    mocap_position_m: float = param(0.001, unit="m", lo=0.0, hi=1.0, doc="per axis")
    mocap_attitude_rad: float = param(0.0017, unit="rad", lo=0.0, hi=1.0, doc="per axis")
    mocap_latency_s: float = param(
        0.012, unit="s", lo=0.0, hi=1.0, doc="delay of the motion-capture pose (whole periods)"
    )


class Odometry:
    def __init__(self, ctx: SensorContext) -> None:
        self.ctx = ctx
        self._pack = ctx.packer(mavlink.MAVLink_odometry_message)
        # the pose comes later than the state (the capture system's latency)
        self.history_steps = ctx.state_delay + delay_steps(
            ctx.world.sensor_noise.mocap_latency_s, ctx.world.control_period_s
        )
        self._until_s = ctx.world.sensors.odometry_until_s

    def __call__(self, time_us: int) -> list[Frame]:
        """Velocities are NaN (not measured) unless the sensors are ideal."""
        if self._until_s is not None and time_us >= self._until_s * 1e6:
            return []  # tracking lost
        ctx = self.ctx
        s = ctx.delayed(self.history_steps)
        errors = ctx.errors
        p = enu_to_ned(errors.vector(ctx.position(s), errors.noise.mocap_position_m))
        q = quat_enu_flu_to_ned_frd(errors.attitude(s.quaternion, errors.noise.mocap_attitude_rad))
        if errors.ideal:
            v_body = flu_to_frd(rotate_transposed(s.rotation, s.velocity_m_s))
            rates = flu_to_frd(s.angular_velocity_body_rad_s)
        else:
            v_body = rates = (math.nan, math.nan, math.nan)
        captured_us = time_us - (self.history_steps - ctx.state_delay) * ctx.period_us
        return [(self._pack, (
            max(0, captured_us),
            mavlink.MAV_FRAME_LOCAL_NED,
            mavlink.MAV_FRAME_BODY_FRD,
            p[0], p[1], p[2],
            list(q),
            v_body[0], v_body[1], v_body[2],
            rates[0], rates[1], rates[2],
            UNKNOWN_COVARIANCE,
            UNKNOWN_COVARIANCE,
            0,
            mavlink.MAV_ESTIMATOR_TYPE_MOCAP,
            100,
        ))]  # fmt: skip


register(SimSensor(
    name="mocap",
    rate_key="odometry_hz",
    rate_hz=100.0,
    doc="ODOMETRY, a motion-capture pose in floats (a mocap system at 100 Hz); 0: off",
    sampler=Odometry,
    noise=MocapNoise,
))  # fmt: skip
