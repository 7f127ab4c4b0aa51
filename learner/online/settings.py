"""The online methods by name and their hyperparameters (DESIGN.md "Learning").

Thesis section 3.5.3: `naive` (the offline loss on each new batch), `constraint` (plus a
penalty on the deviation of every weight from its offline value), `margin` (the penalty only
on the part of the deviation beyond a margin). Beyond the thesis: `ewc` (the deviation
weighted by the diagonal Fisher information of the offline data, Kirkpatrick et al. 2017),
`replay` (stored offline samples mixed into each batch) and `rls` (recursive least squares
on the last layer with a forgetting factor, as Neural-Fly adapts its last layer) and
`composite` (the coefficients of a basis learnt over several grounds, adapted by a Kalman
filter with a tracking-error term, published only past a confidence test, with a memory of
grounds; learner/online/composite.py).

`OnlineSettings` is the one declaration of these settings: a field declared `tunable` is also
the MAVLink parameter it names (GFX_OL_*), whose default, range and description
autopilot/params.py reads from here.
"""

from __future__ import annotations

import dataclasses
import struct
from dataclasses import dataclass
from typing import Any

from learner.online.names import METHODS, NEEDS_BASIS, NEEDS_MEMORY, PROTECTING
from simbridge.config import ConfigError, param, range_text

__all__ = [
    "METHODS",
    "NEEDS_BASIS",
    "NEEDS_MEMORY",
    "PROTECTING",
    "OnlineSettings",
    "check_settings",
    "tuned_in_flight",
]


def tunable(mavlink: str, default: float, *, lo: float, hi: float, unit: str = "", doc: str) -> Any:
    """A setting a ground station tunes in flight as the MAVLink parameter `mavlink`
    (autopilot/params.py reads its name, default, range and doc from here). Its range is
    closed: a parameter is refused outside [lo, hi]."""
    meta = dict(param(default, unit=unit, lo=lo, hi=hi, doc=doc).metadata, mavlink=mavlink)
    return dataclasses.field(default=default, metadata=meta)


@dataclass(frozen=True)
class OnlineSettings:
    """One online method and its hyperparameters. Losses are in standardised target units
    (the offline normaliser), penalties in weight units."""

    method: str = "naive"
    batch_size: int = param(64, lo=8, hi=4096, doc="new samples per update (thesis: 64)")
    learning_rate: float = tunable(
        "GFX_OL_LR", 1e-3, lo=1e-7, hi=1.0, doc="Adam step size of the gradient methods"
    )
    steps: int = param(10, lo=1, hi=1000, doc="Adam steps on each batch")
    penalty: float = tunable(
        "GFX_OL_LAMBDA",
        1.0,
        lo=0.0,
        hi=1e6,
        doc="lambda: weight of the constraint, margin or EWC penalty",
    )
    margin: float = tunable(
        "GFX_OL_MARGIN", 0.02, lo=0.0, hi=10.0, doc="free deviation of each weight (margin)"
    )
    forgetting: float = tunable(
        "GFX_OL_FORGET",
        0.95,
        lo=0.5,
        hi=1.0,
        doc="RLS forgetting factor per sample (1: remember all)",
    )
    rls_initial_covariance: float = tunable(
        "GFX_OL_RLS_P0",
        1e-6,
        lo=1e-9,
        hi=1e6,
        doc="RLS: p0 of P0 = p0 I + s^2 u u^T, the trust in the offline shape",
    )
    rls_scale_sd: float = tunable(
        "GFX_OL_RLS_SC",
        1.0,
        lo=0.0,
        hi=100.0,
        doc="RLS: s, prior sd of a relative change of the effect's size",
    )
    replay_samples: int = param(64, lo=0, hi=4096, doc="offline samples mixed into a batch")
    holdout_every: int = param(
        8, lo=2, hi=1000, doc="every k-th new sample is held back for the guard"
    )
    holdout_size: int = param(8, lo=1, hi=4096, doc="recent held-back samples the guard uses")
    guard_ratio: float = param(
        1.5, lo=1.0, hi=1e6, doc="reject an update whose held-back RMSE exceeds ratio x before"
    )
    guard_slack_n: float = param(
        5e-4, unit="N", lo=0.0, hi=10.0, doc="... plus this much (noise allowance)"
    )
    seed: int = param(0, lo=0, hi=2**31 - 1, doc="replay draws")
    composite_noise_n: float = param(
        2e-3, unit="N", lo=0.0, hi=1.0, lo_open=True, doc="composite: target noise sd (r)"
    )
    composite_prior_scale: float = param(
        3.0, lo=0.0, hi=100.0, doc="composite: s, prior sd in units of the grounds' spread"
    )
    composite_size_sd: float = param(
        2.0, lo=0.0, hi=100.0, doc="composite: prior sd of a relative change of the effect's size"
    )
    composite_prior_p0: float = param(
        1e-4, lo=0.0, hi=1e3, lo_open=True, doc="composite: p0, prior variance in every direction"
    )
    composite_memory_samples: float = param(
        500.0, lo=1.0, hi=1e9, doc="composite: samples after which the prior uncertainty is back"
    )
    composite_tracking_n_s_m: float = tunable(
        "GFX_OL_TRACK",
        0.1,
        unit="N s/m",
        lo=0.0,
        hi=10.0,
        doc="composite: force per m/s of tracking error (0: off)",
    )
    composite_tracking_below_m: float = param(
        0.25,
        unit="m",
        lo=0.0,
        hi=100.0,
        doc="composite: the tracking term only this near the surface",
    )
    composite_confidence: float = tunable(
        "GFX_OL_CONF", 30.0, lo=0.0, hi=1e6, doc="composite: likelihood ratio a change must exceed"
    )
    composite_recall_confidence: float = param(
        10.0,
        lo=0.0,
        hi=1e6,
        doc="composite: likelihood ratio a stored ground must exceed to be recalled",
    )
    composite_far_n: float = param(
        3e-4,
        unit="N",
        lo=0.0,
        hi=1.0,
        lo_open=True,
        doc="composite: prior sd of the prediction's change 0.5 m and more above the surface",
    )
    composite_batch: int = param(
        16, lo=1, hi=4096, doc="composite: samples per update (the filter runs on each one)"
    )
    composite_window: int = param(
        300, lo=8, hi=100000, doc="composite: recent samples the confidence test looks at"
    )
    composite_recall_window: int = param(
        100, lo=8, hi=100000, doc="composite: recent samples a stored ground is judged on"
    )
    composite_min_change_n: float = tunable(
        "GFX_OL_MIN_CHG",
        2e-3,
        unit="N",
        lo=0.0,
        hi=1.0,
        doc="composite: a change published lowers the RMS error over the window by at least this",
    )
    composite_settle: float = tunable(
        "GFX_OL_SETTLE",
        1.0,
        lo=0.0,
        hi=1e6,
        doc="composite: a change waits until the estimate's last batch improved its fit by "
        "at most this likelihood ratio",
    )

    composite_hold_velocity: int = tunable(
        "GFX_OL_HOLD_V",
        1,
        lo=0,
        hi=1,
        doc="composite: while holding, the model is given and learns at the setpoint's "
        "velocity (0: the estimate's)",
    )

    def __post_init__(self) -> None:
        check_settings(self)


def check_settings(settings: OnlineSettings) -> None:
    """A clear error naming the field and its range, never a traceback."""
    if settings.method not in METHODS:
        raise ConfigError(
            f"--online: unknown method {settings.method!r}; choose one of {', '.join(METHODS)}"
        )
    for f in dataclasses.fields(settings):
        if f.name == "method":
            continue
        value = getattr(settings, f.name)
        lo, hi = f.metadata["lo"], f.metadata["hi"]
        if "mavlink" in f.metadata:  # arrives as REAL32: a bound rounded so still counts
            lo, hi = min(lo, _real32(lo)), max(hi, _real32(hi))
        low_ok = value > lo if f.metadata["lo_open"] else value >= lo
        if not (low_ok and value <= hi):
            raise ConfigError(
                f"online {f.name}: {value!r} is outside the allowed range {range_text(f)}"
            )


def _real32(value: float) -> float:
    return struct.unpack("<f", struct.pack("<f", value))[0]


def tuned_in_flight() -> dict[str, str]:
    """MAVLink parameter name -> field, for the settings a ground station tunes in flight."""
    return {
        f.metadata["mavlink"]: f.name
        for f in dataclasses.fields(OnlineSettings)
        if "mavlink" in f.metadata
    }
