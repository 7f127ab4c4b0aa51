"""The magnetometer (HIL_SENSOR's field): the heading, unless motion capture gives the yaw."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from autopilot.estimation import estimator as ekf
from autopilot.estimation.sources import SLOW_FUSION_EVERY, Navigation, Source, register
from autopilot.estimation.sources.mocap import EV_YAW
from autopilot.estimation.sources.mocap import LABEL as MOCAP
from simbridge.config import param

if TYPE_CHECKING:
    from autopilot.estimation.sensors import Imu
    from autopilot.types import Step


@dataclass(frozen=True)
class MagParams:
    mag_decl_deg: float = param(
        5.5, unit="deg", lo=-180.0, hi=180.0, doc="magnetic declination (packaged worlds: 5.5)"
    )
    mag_noise_rad: float = param(0.05, unit="rad", lo=1e-3, hi=3.0, doc="heading sd")

    def field_world(self) -> np.ndarray:
        """The horizontal direction of the Earth's field (east, north, up)."""
        d = math.radians(self.mag_decl_deg)
        return np.array([math.sin(d), math.cos(d), 0.0])


def _yaw_from_mocap(nav: Navigation) -> bool:
    return bool(nav.settings("mocap").ev_ctrl & EV_YAW)


def fuse(nav: Navigation, step: Step, imu: Imu, s: MagParams, t: float) -> None:
    if (
        nav.steps % SLOW_FUSION_EVERY == 0
        and not (_yaw_from_mocap(nav) and nav.alive(MOCAP, t))
        and any(imu.field)
    ):
        nav.fuse("heading", ekf.fuse_heading(
            nav.estimate, np.array(imu.field), s.field_world(), s.mag_noise_rad,
            nav.params.gate_sd,
        ))  # fmt: skip


register(Source(
    name="magnetometer",
    label="magnetometer",
    sensor="imu",
    settings=MagParams,
    names={"EKF2_MAG_DECL": "mag_decl_deg", "EKF2_HEAD_NOISE": "mag_noise_rad"},
    fuse=fuse,
    active=lambda nav, s: not _yaw_from_mocap(nav),
))  # fmt: skip
