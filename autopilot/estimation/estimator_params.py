"""The estimator's own parameters, named as PX4's EKF2 names them: the height reference, the
barometer, the gate and the sources' timeout. Each source's parameters are declared with it
(`autopilot.estimation.sources`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from simbridge.config import param

HEIGHT_BARO, HEIGHT_GPS, HEIGHT_RANGE, HEIGHT_VISION = 0, 1, 2, 3
HEIGHT_NAMES = {0: "baro", 1: "gps", 2: "range", 3: "vision"}
# parameter name -> field of EstimatorParams
NAMES = {
    "EKF2_BARO_CTRL": "baro_ctrl",
    "EKF2_HGT_REF": "hgt_ref",
    "EKF2_BARO_NOISE": "baro_noise_m",
    "EKF2_GATE": "gate_sd",
    "COM_POS_FS_DELAY": "source_timeout_s",
}


@dataclass(frozen=True)
class EstimatorParams:
    baro_ctrl: int = param(1, lo=0, hi=1, doc="barometer: 1 height when it is the reference")
    hgt_ref: int = param(3, lo=0, hi=3, doc="height reference: 0 baro, 1 GPS, 2 range, 3 vision")
    baro_noise_m: float = param(0.15, unit="m", lo=0.01, hi=100.0, doc="barometer height sd")
    gate_sd: float = param(5.0, lo=1.0, hi=100.0, doc="innovation gate, standard deviations")
    source_timeout_s: float = param(
        0.3, unit="s", lo=0.01, hi=10.0, doc="a source silent this long is lost"
    )
    # each declared source's settings by its name (its declared defaults where missing)
    sources: Mapping[str, Any] = dataclasses.field(default_factory=dict)
