"""GPS (HIL_GPS): position and velocity, the altitude when it is the height reference."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from autopilot.estimation import estimator as ekf
from autopilot.estimation.estimator_params import HEIGHT_BARO
from autopilot.estimation.sources import WAIT, Alignment, Navigation, Source, register
from simbridge.config import param
from simbridge.frames import geodetic_to_local, ned_to_enu

if TYPE_CHECKING:
    from autopilot.estimation.sensors import Imu
    from autopilot.types import Step

GPS_POS, GPS_ALT, GPS_VEL = 1, 2, 4
LABEL = "GPS"


@dataclass(frozen=True)
class GpsParams:
    gps_ctrl: int = param(0, lo=0, hi=7, doc="GPS: 1 lat/lon, 2 altitude, 4 velocity")
    gps_pos_noise_m: float = param(0.5, unit="m", lo=0.01, hi=100.0, doc="GPS position sd")
    gps_vel_noise_m_s: float = param(0.15, unit="m/s", lo=0.01, hi=10.0, doc="GPS velocity sd")


def gps_position(origin: tuple[float, float, float], g: dict) -> tuple[float, float, float]:
    """A fix in the local frame of the geodetic `origin` (lat deg, lon deg, alt m)."""
    east, north = geodetic_to_local(origin[0], origin[1], g["lat"] * 1e-7, g["lon"] * 1e-7)
    return (east, north, g["alt"] * 1e-3 - origin[2])


def fuse(nav: Navigation, step: Step, imu: Imu, s: GpsParams, t: float) -> None:
    if not s.gps_ctrl or "HIL_GPS" not in step.new:
        return
    g = step.latest["HIL_GPS"]
    if g["fix_type"] < 3:
        return
    nav.seen(LABEL, t)
    gate = nav.params.gate_sd
    position, _ = nav.at_capture(g["time_usec"])
    axes = ([0, 1] if s.gps_ctrl & GPS_POS else []) + (
        [2] if s.gps_ctrl & GPS_ALT and nav.height_source == "gps" else []
    )
    if axes:
        measured = np.array(gps_position(nav.origin, g))
        sd = np.array([s.gps_pos_noise_m, s.gps_pos_noise_m, 1.6 * s.gps_pos_noise_m])
        nav.fuse("GPS position", ekf.fuse_position(
            nav.estimate, measured, np.array(position), sd, gate, axes
        ))  # fmt: skip
    if s.gps_ctrl & GPS_VEL:
        v = np.array(ned_to_enu((g["vn"] * 0.01, g["ve"] * 0.01, g["vd"] * 0.01)))
        nav.fuse("GPS velocity", ekf.fuse_velocity(nav.estimate, v, s.gps_vel_noise_m_s, gate))


def align(nav: Navigation, step: Step, imu: Imu, s: GpsParams) -> Alignment | None:
    """Horizontally where the fix says; vertically the vehicle stands on the ground (a fix's
    altitude errs by metres; PX4's local frame starts at its height too)."""
    if not s.gps_ctrl & GPS_POS:
        return None
    g = step.latest.get("HIL_GPS")
    if g is None:
        return WAIT
    east, north, _ = gps_position(nav.origin, g)
    return Alignment((east, north, nav.resting_height_m), s.gps_pos_noise_m)


register(Source(
    name="gps",
    label=LABEL,
    sensor="gps",
    settings=GpsParams,
    names={
        "EKF2_GPS_CTRL": "gps_ctrl",
        "EKF2_GPS_P_NOISE": "gps_pos_noise_m",
        "EKF2_GPS_V_NOISE": "gps_vel_noise_m_s",
    },
    fuse=fuse,
    active=lambda nav, s: bool(s.gps_ctrl),
    switch="EKF2_GPS_CTRL",
    sets={"gps": {"EKF2_GPS_CTRL": 7, "EKF2_HGT_REF": HEIGHT_BARO}},
    gives_position=lambda s: bool(s.gps_ctrl & GPS_POS),
    align=align,
))  # fmt: skip
