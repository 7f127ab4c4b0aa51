"""The one-page flight report's page: five panels, one per question, and the answers as text
(matplotlib, no display needed), written beside the recording with the answers' JSON."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path
from typing import Any

import numpy as np

from autopilot.metrics import runs, settled_halves
from learner.plot_axes import plain_log_axis
from mission.flight_report import (
    QUESTIONS,
    Series,
    answers,
    online_method,
    read_series,
    report_paths,
)

# the model error's axis is scaled to the hold near the ground: a take-off transient (about
# 1 N) would otherwise flatten the 0.1-0.2 N hold to a line
MODEL_AXIS_MARGIN = 1.5
ROTOR_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728")
LANDING_WINDOW_S = 4.0  # the landing panel: the last seconds before touchdown
DPI = 90


def draw_page(png: Path, title: str, answers: dict[str, Any], s: Series) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 2, figsize=(13, 11), dpi=DPI)
    fig.suptitle(title, fontsize=14)
    _landing(axes[0, 0], answers["landing"], s)
    _hold(axes[0, 1], answers["hold"], s)
    _model(axes[1, 0], answers["model"], s)
    _learner(axes[1, 1], answers["learner"], s)
    _rotors(axes[2, 0], answers["rotors"], s)
    _text(axes[2, 1], answers)
    fig.subplots_adjust(left=0.07, right=0.93, bottom=0.05, top=0.93, wspace=0.3, hspace=0.35)
    fig.savefig(png)
    plt.close(fig)


def _answer(ax: Any, text: str) -> None:
    """The panel's answer in words, inside its top left corner."""
    box = {"facecolor": "white", "alpha": 0.85, "edgecolor": "none"}
    ax.text(0.02, 0.97, textwrap.fill(text, 62), transform=ax.transAxes, va="top", fontsize=8.5,
            bbox=box, zorder=5)  # fmt: skip


def _frame(ax: Any, title: str, ylabel: str, empty: str | None = None) -> bool:
    """A panel's title and axes; with `empty` (the answer when there is no data) that text
    alone, centred. Whether there is data to draw."""
    ax.set_title(title, loc="left")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    if empty is None:
        return True
    ax.text(0.5, 0.5, textwrap.fill(empty, 60), transform=ax.transAxes, ha="center")
    return False


def _clip(ax: Any, values: np.ndarray, bound: float, note: str) -> None:
    """Scale the axis to +-`bound` when `values` go beyond it, saying what runs off (`note`,
    with the largest value as `{largest}`)."""
    largest = float(np.max(np.abs(values)))
    if largest > bound:
        ax.set_ylim(-bound, bound)
        text = note.format(largest=largest)
        ax.text(0.98, 0.03, text, transform=ax.transAxes, ha="right", fontsize=8)


def _landing(ax: Any, a: dict[str, Any], s: Series) -> None:
    """1. Height above the surface over the last seconds: the touchdown, its speed."""
    _frame(ax, "1. Did it land, where and how?", "height (mm)")
    end = s.time_s[-1] if len(s.time_s) else 0.0
    last = s.time_s >= end - LANDING_WINDOW_S
    ax.plot(s.time_s[last], s.height_m[last] * 1e3, color="#1f77b4", label="height above surface")
    if a.get("touchdown_time_s") is not None:
        ax.axvline(a["touchdown_time_s"], color="#2ca02c", ls="--", lw=1, label="touchdown")
        ax.legend(loc="lower left", fontsize=8)
    _answer(ax, a["text"])


def _hold(ax: Any, a: dict[str, Any], s: Series) -> None:
    """2. Height error near the ground in millimetres, on its own axis."""
    title, ylabel = (
        "2. How well did it hold near the ground?",
        "height error, flown minus setpoint (mm)",
    )
    if not _frame(ax, title, ylabel, None if s.near_hold.any() else a["text"]):
        return
    t = np.where(s.near_hold, s.time_s, np.nan)  # gaps between holds left open
    error = (s.z_m - s.z_setpoint_m) * 1e3
    ax.plot(t, error, color="#d62728")
    ax.axhline(0.0, color="grey", lw=0.8)
    settled = settled_halves(s.near_hold)
    for start, stop in runs(settled):
        ax.axvspan(s.time_s[start], s.time_s[stop - 1], color="#2ca02c", alpha=0.08)
    if settled.any():  # scaled to the settled hold; the approach runs off the top
        bound = max(float(np.max(np.abs(error[settled]))) * 3.0, 1.0)
        _clip(ax, error[s.near_hold], bound,
              "shaded: the settled half, scored; the approach runs off the axis")  # fmt: skip
    _answer(ax, a["text"])


def _model(ax: Any, a: dict[str, Any], s: Series) -> None:
    """3. Predicted minus true ground effect (mN), scaled to the hold, not the take-off."""
    title, ylabel = (
        "3. How good was the ground-effect model?",
        "model error, predicted minus true (mN)",
    )
    if not _frame(ax, title, ylabel, None if len(s.ge_time_s) else a["text"]):
        return
    error = s.ge_error_n * 1e3
    ax.plot(s.ge_time_s, error, color="#9467bd")
    ax.axhline(0.0, color="grey", lw=0.8)
    in_hold = np.interp(s.ge_time_s, s.time_s, s.near_hold.astype(float)) > 0.5
    scale = error[in_hold] if in_hold.any() else error
    bound = max(float(np.max(np.abs(scale))) * MODEL_AXIS_MARGIN, 1.0)
    _clip(ax, error, bound,
          "clipped: the largest, {largest:.0f} mN, at take-off or touchdown")  # fmt: skip
    _answer(ax, a["text"])


def _learner(ax: Any, a: dict[str, Any], s: Series) -> None:
    """4. The learner's loss on a log axis and its published weights' version."""
    title, ylabel = "4. What did the learner do?", "loss of each update (standardised, log)"
    if not _frame(ax, title, ylabel, None if len(s.loss_time_s) else a["text"]):
        ax.set_xticks([])
        ax.set_yticks([])
        return
    ax.semilogy(s.loss_time_s, np.maximum(s.loss, 1e-12), ".", color="#d62728", label="loss")
    plain_log_axis(ax.yaxis)
    if len(s.version_time_s):
        twin = ax.twinx()
        twin.step(s.version_time_s, s.version, where="post", color="#1f77b4", label="version")
        twin.set_ylabel("weights version in use")
    _answer(ax, a["text"])


def _rotors(ax: Any, a: dict[str, Any], s: Series) -> None:
    """5. Each rotor its own colour: commanded minus measured."""
    title, ylabel = "5. Rotors: commanded minus measured", "rotor speed difference (rad/s)"
    if not _frame(ax, title, ylabel, None if len(s.rotor_time_s) else a["text"]):
        return
    d = s.rotor_difference_rad_s
    for i, color in enumerate(ROTOR_COLORS):
        ax.plot(s.rotor_time_s, d[:, i], color=color, lw=0.8, label=f"rotor {i}")
    # scaled to the flight, not to the spin-up and touchdown spikes
    bound = max(float(np.percentile(np.abs(d), 99.0)) * 3.0, 1.0)
    _clip(ax, d, bound,
          "clipped: the largest, {largest:.0f} rad/s, at spin-up or touchdown")  # fmt: skip
    ax.legend(loc="upper right", ncol=4, fontsize=8)


def _text(ax: Any, answers: dict[str, Any]) -> None:
    ax.axis("off")
    lines = []
    for k, name in enumerate(QUESTIONS, start=1):
        lines.append(textwrap.fill(f"{k}. {answers[name]['text']}", 64))
    ax.text(0.0, 1.0, "\n\n".join(lines), va="top", fontsize=9.5)


def write_report(recording: Path) -> tuple[Path, Path]:
    """Read `recording`, write its page and its answers beside it; their paths."""
    from learner.flightlogs.recording import SUMMARY, read_recording

    rec = read_recording(recording)
    summary = (
        json.loads(rec.static(SUMMARY, "TextDocument:text")) if SUMMARY in rec.entities else {}
    )
    s = read_series(rec)
    found = answers(summary, rec.meta, s)
    png, js = report_paths(recording)
    title = (
        f"{Path(str(rec.meta.get('mission', recording.stem))).stem}: model "
        f"{rec.meta.get('model', '?')}, rho {rec.meta.get('rho', '?')}"
        + (f", online {method}" if (method := online_method(summary, rec.meta)) else "")
    )
    draw_page(png, title, found, s)
    document = {"recording": str(recording), "title": title, "answers": found}
    js.write_text(json.dumps(document, indent=2) + "\n")
    return png, js
