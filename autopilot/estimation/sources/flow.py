"""Optical flow (HIL_OPTICAL_FLOW): the body's horizontal velocity, a fallback while motion
capture gives no position."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from autopilot.estimation import estimator as ekf
from autopilot.estimation.sources import Navigation, Source, register
from autopilot.estimation.sources.mocap import EV_HPOS
from autopilot.estimation.sources.mocap import LABEL as MOCAP
from simbridge.config import param

if TYPE_CHECKING:
    from autopilot.estimation.sensors import Imu
    from autopilot.types import Step

LABEL = "optical flow"


@dataclass(frozen=True)
class FlowParams:
    of_ctrl: int = param(
        1,
        lo=0,
        hi=1,
        doc="optical flow: 1 fused while the range is valid and no motion capture position "
        "comes (a fallback: beside 1 mm poses at 100 Hz it adds nothing but cost)",
    )
    of_noise_rad_s: float = param(0.15, unit="rad/s", lo=1e-3, hi=10.0, doc="flow rate sd")


def fuse(nav: Navigation, step: Step, imu: Imu, s: FlowParams, t: float) -> None:
    """Flow (body FRD, integrated over the message's interval) less the gyro's share, times
    the height: the body's horizontal velocity."""
    if (
        not s.of_ctrl
        or "HIL_OPTICAL_FLOW" not in step.new
        or (nav.settings("mocap").ev_ctrl & EV_HPOS and nav.alive(MOCAP, t))
    ):
        return
    f = step.latest["HIL_OPTICAL_FLOW"]
    dt = f["integration_time_us"] * 1e-6
    height = f["distance"]
    if f["quality"] == 0 or dt <= 0.0 or not height > 0.0:
        return
    nav.seen(LABEL, t)
    rates = np.array(imu.rates) - nav.estimate.gyro_bias_rad_s  # FLU; flow was made in FRD
    # FRD: flow_x = (p - v_y / h) dt, flow_y = (q + v_x / h) dt  (simbridge/sensors/distance.py)
    p_frd, q_frd = rates[0], -rates[1]
    vy_frd = (p_frd - f["integrated_x"] / dt) * height
    vx_frd = (f["integrated_y"] / dt - q_frd) * height
    v_flu = np.array([vx_frd, -vy_frd])
    sd = s.of_noise_rad_s * max(height, 0.05)
    nav.fuse(LABEL, ekf.fuse_body_velocity(nav.estimate, v_flu, sd, nav.params.gate_sd))


register(Source(
    name="flow",
    label=LABEL,
    sensor="flow_deck",
    settings=FlowParams,
    names={"EKF2_OF_CTRL": "of_ctrl", "EKF2_OF_N_MIN": "of_noise_rad_s"},
    fuse=fuse,
    active=lambda nav, s: bool(s.of_ctrl),
    switch="EKF2_OF_CTRL",
    sets={"mocap": {"EKF2_OF_CTRL": 1}, "flow": {"EKF2_OF_CTRL": 1}},
))  # fmt: skip
