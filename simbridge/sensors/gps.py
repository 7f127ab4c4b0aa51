"""HIL_GPS: a u-blox M8 class fix (3-D, 12 satellites) with its errors: 0.5 m horizontal and
0.8 m vertical white noise, 0.1 m/s velocity."""

from __future__ import annotations

import math
from dataclasses import dataclass

from simbridge.config import param
from simbridge.frames import enu_to_ned
from simbridge.sensors import Frame, SensorContext, SimSensor, int16, mavlink, register


@dataclass(frozen=True)
class GpsNoise:
    gps_horizontal_m: float = param(0.5, unit="m", lo=0.0, hi=100.0, doc="per axis")
    gps_vertical_m: float = param(0.8, unit="m", lo=0.0, hi=100.0, doc="altitude")
    gps_velocity_m_s: float = param(0.1, unit="m/s", lo=0.0, hi=10.0, doc="per axis")


class Gps:
    history_steps = 0  # the state through the state's latency

    def __init__(self, ctx: SensorContext) -> None:
        self.ctx = ctx
        self._pack = ctx.packer(mavlink.MAVLink_hil_gps_message)

    def __call__(self, time_us: int) -> list[Frame]:
        ctx = self.ctx
        s = ctx.delayed(ctx.state_delay)
        errors = ctx.errors
        n = errors.noise
        x, y, z = ctx.position(s)
        lat, lon, alt = ctx.geodetic((
            errors.scalar(x, n.gps_horizontal_m),
            errors.scalar(y, n.gps_horizontal_m),
            errors.scalar(z, n.gps_vertical_m),
        ))  # fmt: skip
        vn, ve, vd = enu_to_ned(errors.vector(s.velocity_m_s, n.gps_velocity_m_s))
        ground = math.hypot(vn, ve)
        cog = (
            round(math.degrees(math.atan2(ve, vn)) % 360.0 * 100.0) % 36000
            if ground > 0.05
            else 65535
        )
        return [(self._pack, (
            time_us,
            3,
            lat,
            lon,
            alt,
            100,
            100,
            min(65535, round(ground * 100.0)),
            int16(vn * 100),
            int16(ve * 100),
            int16(vd * 100),
            cog,
            12,
            0,
            0,
        ))]  # fmt: skip


register(SimSensor(
    name="gps",
    rate_key="gps_hz",
    rate_hz=10.0,
    doc="HIL_GPS; 0 disables",
    sampler=Gps,
    noise=GpsNoise,
))  # fmt: skip
