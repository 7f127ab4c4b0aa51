"""Motion capture (ODOMETRY): position and yaw, fused as PX4's EKF2 fuses external vision."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from autopilot.estimation import estimator as ekf
from autopilot.estimation.attitude import yaw_of
from autopilot.estimation.estimator_params import HEIGHT_VISION
from autopilot.estimation.sources import WAIT, Alignment, Navigation, Source, register
from simbridge.config import param
from simbridge.frames import ned_to_enu, quat_ned_frd_to_enu_flu

if TYPE_CHECKING:
    from autopilot.estimation.sensors import Imu
    from autopilot.types import Step

EV_HPOS, EV_VPOS, EV_YAW = 1, 2, 8
LABEL = "motion capture"
FUSED_S = "motion capture fused s"  # the last pose that passed the gate


@dataclass(frozen=True)
class MocapParams:
    ev_ctrl: int = param(
        11, lo=0, hi=15, doc="motion capture: 1 horizontal position, 2 vertical, 8 yaw"
    )
    ev_pos_noise_m: float = param(0.002, unit="m", lo=1e-4, hi=10.0, doc="mocap position sd")
    ev_att_noise_rad: float = param(0.005, unit="rad", lo=1e-4, hi=1.0, doc="mocap yaw sd")
    ev_reset_s: float = param(
        0.5, unit="s", lo=0.01, hi=10.0,
        doc="motion capture arriving but rejected this long: the position reset to it",
    )  # fmt: skip


def fuse(nav: Navigation, step: Step, imu: Imu, s: MocapParams, t: float) -> None:
    if not s.ev_ctrl or "ODOMETRY" not in step.new:
        return
    m = step.latest["ODOMETRY"]
    nav.seen(LABEL, t)
    position, attitude = nav.at_capture(m["time_usec"])
    measured = ned_to_enu((m["x"], m["y"], m["z"]))
    axes = ([0, 1] if s.ev_ctrl & EV_HPOS else []) + (
        [2] if s.ev_ctrl & EV_VPOS and nav.height_source == "vision" else []
    )
    yaw = None
    if s.ev_ctrl & EV_YAW:
        yaw = yaw_of(quat_ned_frd_to_enu_flu(tuple(m["q"]))) - yaw_of(attitude)
    if not axes and yaw is None:
        return
    innovation = np.array([measured[a] - position[a] for a in axes])
    fused = ekf.fuse_pose(
        nav.estimate, innovation, axes, s.ev_pos_noise_m, yaw, s.ev_att_noise_rad,
        nav.params.gate_sd,
    )  # fmt: skip
    last = nav.memory.get(FUSED_S)
    if nav.fuse(LABEL, fused) or last is None:
        nav.memory[FUSED_S] = t
    elif t - last >= s.ev_reset_s and axes:
        # poses keep coming and keep failing the gate (a timing or scale error the filter
        # does not model): reset to them rather than dead-reckon away, as EKF2 resets a
        # position source whose fusion is failing
        nav.estimate = ekf.reset_position(nav.estimate, innovation, axes, s.ev_pos_noise_m)
        nav.memory[FUSED_S] = t
        nav.quality.resets += 1
        nav.events.append("estimator: position reset to motion capture")


def align(nav: Navigation, step: Step, imu: Imu, s: MocapParams) -> Alignment | None:
    if not s.ev_ctrl:
        return None
    m = step.latest.get("ODOMETRY")
    if m is None:
        return WAIT  # the first pose
    return Alignment(
        position_m=ned_to_enu((m["x"], m["y"], m["z"])),
        position_sd_m=s.ev_pos_noise_m,
        quaternion=quat_ned_frd_to_enu_flu(tuple(m["q"])) if s.ev_ctrl & EV_YAW else None,
        attitude_sd_rad=s.ev_att_noise_rad,
        seen=True,
    )


register(Source(
    name="mocap",
    label=LABEL,
    sensor="mocap",
    settings=MocapParams,
    names={
        "EKF2_EV_CTRL": "ev_ctrl",
        "EKF2_EVP_NOISE": "ev_pos_noise_m",
        "EKF2_EVA_NOISE": "ev_att_noise_rad",
        "GFX_EV_RESET_T": "ev_reset_s",
    },
    fuse=fuse,
    active=lambda nav, s: bool(s.ev_ctrl),
    switch="EKF2_EV_CTRL",
    sets={"mocap": {"EKF2_EV_CTRL": 11, "EKF2_HGT_REF": HEIGHT_VISION}},
    gives_position=lambda s: bool(s.ev_ctrl & EV_HPOS),
    align=align,
))  # fmt: skip
