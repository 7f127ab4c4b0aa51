"""The review a recording carries for the viewer: how its difference series are scaled, and
the landing and the learner in a sentence each (the one-page report, mission/flight_report.py,
says them in the same words).

The viewer draws its value axes with ticks at powers of ten only (1, 10, 100, ... times the
unit, never 2 or 5), each at least 20 px from the next: a range of 1.2 mm over 200 px gets
one labelled tick. So the review's ranges are whole numbers of a power of ten, between
MIN_UNITS and MAX_UNITS of them: in a view 250 px tall or more every unit is labelled.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from autopilot.metrics import settled_halves

MIN_UNITS, MAX_UNITS = 4, 10
SPREAD_PERCENTILE = 99.0  # the range holds this share of the samples; the rest is clipped


def nice_range(low: float, high: float) -> tuple[float, float]:
    """The narrowest range around [low, high] spanning MIN_UNITS to MAX_UNITS whole units of
    a power of ten (widened evenly on both sides when the data spans fewer)."""
    span = max(high - low, 1e-12)
    unit = 10.0 ** math.floor(math.log10(span / MAX_UNITS))
    while True:
        a, b = math.floor(low / unit - 1e-9) * unit, math.ceil(high / unit + 1e-9) * unit
        if round((b - a) / unit) <= MAX_UNITS:
            break
        unit *= 10.0
    while round((b - a) / unit) < MIN_UNITS:
        a, b = a - unit, b + unit
    return (round(a / unit) * unit, round(b / unit) * unit)


# The review's series and how each view is scaled: "error" around zero over the settled
# half of each hold near the ground (the whole flight if it held nowhere near it): a
# take-off's metre-sized error, or the approach to the hold, would squash a hold's
# millimetres; they leave the view instead. "span": over the whole flight.
SCALED: dict[str, str] = {
    "plots/height_error_mm": "error",
    "plots/model_error_mn": "error",
    "plots/ground_effect/z/true": "span",
    "plots/learner/log10_loss": "span",
    "plots/rotors/difference": "error",  # the four rotors share one range: they compare
}


def _scaled(values: np.ndarray, how: str) -> tuple[float, float] | None:
    values = values[np.isfinite(values)]
    if not len(values):
        return None
    if how == "span":
        low, high = np.percentile(values, [100.0 - SPREAD_PERCENTILE, SPREAD_PERCENTILE])
        return nice_range(float(low), float(high))
    w = float(np.percentile(np.abs(values), SPREAD_PERCENTILE))
    return nice_range(-w, w) if w > 0 else None


class ReviewSpread:
    """The spread of the review's series (SCALED), gathered as the rows leave."""

    def __init__(self) -> None:
        self._parts: dict[str, list[tuple[np.ndarray, np.ndarray | None]]] = {}

    def add(self, path: str, values: np.ndarray, hold: np.ndarray | None = None) -> None:
        """Values of one flush (NaN: none at that row), and which rows are in a hold near the
        ground."""
        self._parts.setdefault(path, []).append((np.asarray(values, float).reshape(-1), hold))

    def ranges(self) -> dict[str, tuple[float, float]]:
        """Entity path -> the y range of its view (none where nothing was recorded)."""
        out = {}
        for path, parts in self._parts.items():
            values = np.concatenate([v for v, _ in parts])
            how = SCALED[path]
            if how == "error" and all(h is not None for _, h in parts):
                # the settled half of each hold, which the summary's hold figures score
                hold = settled_halves(np.concatenate([h for _, h in parts if h is not None]))
                if (hold & np.isfinite(values)).any():
                    values = values[hold]
            found = _scaled(values, how)
            if found is None:
                continue
            if path == "plots/rotors/difference":
                out.update({f"{path}/{i}": found for i in range(4)})
            else:
                out[path] = found
        return out


def online_method(summary: dict[str, Any], meta: dict[str, Any]) -> str | None:
    """The online learning method the flight used; None for none ("off" in the metadata)."""
    method = summary.get("online_method") or meta.get("online")
    return None if method in (None, "", "off", "none") else str(method)


def number(value: float | None, fmt: str) -> str:
    return "n/a" if value is None or not math.isfinite(value) else format(value, fmt)


def landing_sentence(summary: dict[str, Any]) -> str:
    """Did it land, where and how: from the flight's summary."""
    if not summary.get("landed"):
        return f"did not land: {summary.get('ended')}"
    error = summary.get("landing_error_m")
    error_mm = None if error is None else float(error) * 1e3
    speed = summary.get("touchdown_speed_m_s")
    return (
        f"landed {number(error_mm, '.1f')} mm from the landing point at {number(speed, '.2f')} m/s"
    )


def learner_sentence(summary: dict[str, Any], meta: dict[str, Any]) -> str:
    """What the online learner did: updates, accepted, rejected and why, the ground in use."""
    method = online_method(summary, meta)
    if method is None:
        return "no online learning: the model stayed as loaded"
    s = {k: summary.get(f"online_{k}") for k in ("updates", "accepted", "rejected", "version")}
    reasons = "; ".join(
        f"{k}: {v}" for k, v in (summary.get("online_reject_reasons") or {}).items()
    )
    held = summary.get("online_held")
    ground = summary.get("online_ground")
    evidence = summary.get("online_held_evidence")
    ratios = (
        f" (likelihood ratio median {evidence['median']:.3g}, largest {evidence['max']:.4g}, "
        f"against {evidence['threshold']:g})"
        if evidence
        else ""
    )
    return (
        f"online {method}: {s['updates']} updates, {s['accepted']} accepted, "
        f"{s['rejected']} rejected; weights version {s['version']}"
        + (f" (rejected for {reasons})" if reasons else "")
        + (
            f"; {held} held: the evidence for a change under its confidence threshold{ratios}"
            if held
            else ""
        )
        + (
            f", {over} of them over it while the estimate converged or for a change too small"
            if held and (over := (evidence or {}).get("over_threshold"))
            else ""
        )
        + (f"; active ground {ground}" if ground else "")
    )


def review_text(summary: dict[str, Any] | None, meta: dict[str, Any], ended: str) -> str:
    """The viewer's review panel: the landing and the learner, one line each."""
    landing = landing_sentence(summary) if summary else f"the flight ended: {ended}"
    speed = (summary or {}).get("touchdown_time_s")
    when = f" (touchdown at {speed:.2f} s)" if isinstance(speed, float) else ""
    return f"Landing: {landing}{when}.\n\nLearner: {learner_sentence(summary or {}, meta)}.\n"
