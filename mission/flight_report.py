"""A flight on one page: the five questions a reviewer asks of a recording, answered in a PNG
beside it (`<recording>.report.png`) and as text and figures in a JSON file
(`<recording>.report.json`).

1. Did it land, where and how? 2. How well did it hold near the ground (mm)? 3. How good was
the ground-effect model (predicted minus true, mN)? 4. What did the online learner do?
5. The rotors: commanded against measured, as a difference.

The answers come from the recording alone (its summary, its series), so `groundfx review
--report REC` gives the page of any recording, and `groundfx fly` writes it after each
recorded flight. This module reads and answers; `mission/flight_report_page.py` draws.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from autopilot.metrics import NEAR_GROUND_M, settled_halves
from autopilot.recording.review import (
    landing_sentence,
    learner_sentence,
    number,
    online_method,
)

PNG_SUFFIX = ".report.png"
JSON_SUFFIX = ".report.json"
QUESTIONS = ("landing", "hold", "model", "learner", "rotors")  # the answers' keys, in order


@dataclass(frozen=True)
class Series:
    """What the page plots, read from a recording."""

    time_s: np.ndarray  # one row per control step
    z_m: np.ndarray
    z_setpoint_m: np.ndarray
    height_m: np.ndarray
    near_hold: np.ndarray  # holding with the setpoint within NEAR_GROUND_M of the surface
    ge_time_s: np.ndarray
    ge_error_n: np.ndarray  # predicted minus true, vertical
    rotor_time_s: np.ndarray
    rotor_difference_rad_s: np.ndarray  # commanded minus measured (ESC), [N, 4]
    loss_time_s: np.ndarray
    loss: np.ndarray
    version_time_s: np.ndarray
    version: np.ndarray


def report_paths(recording: Path) -> tuple[Path, Path]:
    base = recording.with_suffix("")
    return base.with_name(base.name + PNG_SUFFIX), base.with_name(base.name + JSON_SUFFIX)


def _scalars(rec: Any, path: str) -> tuple[np.ndarray, np.ndarray]:
    try:
        return rec.scalars(path)
    except KeyError:  # not recorded, or only its style (a learner that never reported)
        return np.zeros(0), np.zeros((0, 1))


def read_series(rec: Any) -> Series:
    """The page's series from a `learner.flightlogs.recording.Recording`."""
    log = rec.trajectory()
    modes = list(rec.meta.get("modes", []))
    t, z, zd, height, mode = log[:, 0], log[:, 3], log[:, 7], log[:, 8], log[:, 9].astype(int)
    holding = mode == modes.index("holding") if "holding" in modes else np.zeros(len(t), bool)
    near = holding & (zd - z + height <= NEAR_GROUND_M)
    tp, predicted = _scalars(rec, "plots/ground_effect/z/predicted")
    tt, true = _scalars(rec, "plots/ground_effect/z/true")
    if len(tp) and len(tt):
        ge_t, ge_error = tt, np.interp(tt, tp, predicted[:, 0]) - true[:, 0]
    else:
        ge_t, ge_error = np.zeros(0), np.zeros(0)
    tc, commanded = _scalars(rec, "plots/rotors/commanded")
    ta, actual = _scalars(rec, "plots/rotors/actual")
    if len(tc) and len(ta):
        at_esc = np.column_stack([np.interp(ta, tc, commanded[:, i]) for i in range(4)])
        rotor_t, rotor_diff = ta, at_esc - actual
    else:
        rotor_t, rotor_diff = np.zeros(0), np.zeros((0, 4))
    lt, loss = _scalars(rec, "plots/learner/loss")
    vt, version = _scalars(rec, "plots/learner/version")
    return Series(t, z, zd, height, near, ge_t, ge_error, rotor_t, rotor_diff,
                  lt, loss[:, 0], vt, version[:, 0])  # fmt: skip


def _mm(value: Any) -> float | None:
    return None if value is None else float(value) * 1e3


def answers(summary: dict[str, Any], meta: dict[str, Any], s: Series) -> dict[str, Any]:
    """The five answers, each its figures and one sentence (pure: no file is touched)."""
    landed = bool(summary.get("landed"))
    error_mm, speed = _mm(summary.get("landing_error_m")), summary.get("touchdown_speed_m_s")
    landing = {
        "landed": landed,
        "ended": summary.get("ended"),
        "landing_error_mm": error_mm,
        "touchdown_speed_m_s": speed,
        "bounce_mm": _mm(summary.get("bounce_m")),
        "touchdown_time_s": summary.get("touchdown_time_s"),
        "text": landing_sentence(summary),
    }
    settled = settled_halves(s.near_hold)
    err = (s.z_m[settled] - s.z_setpoint_m[settled]) * 1e3 if settled.any() else np.zeros(0)
    hold = {
        "rows": int(s.near_hold.sum()),
        "rms_mm": float(np.sqrt(np.mean(err**2))) if len(err) else None,
        "max_mm": float(np.max(np.abs(err))) if len(err) else None,
        "mean_mm": float(np.mean(err)) if len(err) else None,
    }
    hold["text"] = (
        f"held {number(hold['rms_mm'], '.2f')} mm RMS (worst {number(hold['max_mm'], '.2f')} mm) "
        f"from its setpoint within {NEAR_GROUND_M * 100:.0f} cm of the ground, once settled"
        if len(err)
        else f"no hold within {NEAR_GROUND_M * 100:.0f} cm of the ground"
    )
    in_hold = np.interp(s.ge_time_s, s.time_s, s.near_hold.astype(float)) > 0.5
    hold_error = s.ge_error_n[in_hold] if len(s.ge_time_s) else np.zeros(0)
    model_name = str(summary.get("model") or meta.get("model") or "?")
    model = {
        "model": model_name,
        "rms_mn": _mm(summary.get("ge_z_rms_error_n")),
        "far_rms_mn": _mm(summary.get("ge_z_far_rms_error_n")),
        "hold_rms_mn": float(np.sqrt(np.mean(hold_error**2))) * 1e3 if len(hold_error) else None,
    }
    model["text"] = (
        f"the {model_name} model was {number(model['hold_rms_mn'], '.1f')} mN RMS off the true "
        f"ground effect in the hold, {number(model['far_rms_mn'], '.2f')} mN far from the ground"
        if len(s.ge_time_s)
        else "no true ground effect recorded to compare the model with"
    )
    method = online_method(summary, meta)
    if method:
        learner: dict[str, Any] = {
            "method": method,
            **{k: summary.get(f"online_{k}") for k in
               ("updates", "accepted", "rejected", "held", "version", "loss_first",
                "loss_last", "reject_reasons", "ground", "grounds", "held_evidence")},
        }  # fmt: skip
        learner["text"] = learner_sentence(summary, meta)
    else:
        learner = {"method": None, "text": learner_sentence(summary, meta)}
    d = s.rotor_difference_rad_s
    rotors = {
        "rms_difference_rad_s": [float(np.sqrt(np.mean(d[:, i] ** 2))) for i in range(4)]
        if len(d)
        else None,
    }
    rotors["text"] = (
        "commanded minus measured rotor speed, RMS per rotor: "
        + ", ".join(f"{v:.1f}" for v in rotors["rms_difference_rad_s"])
        + " rad/s"
        if len(d)
        else "no measured rotor speeds (ESC telemetry) in the recording"
    )
    found = {"landing": landing, "hold": hold, "model": model, "learner": learner, "rotors": rotors}
    return {k: found[k] for k in QUESTIONS}
