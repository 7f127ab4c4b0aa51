"""What a reviewer sees of a recording's time series in the rerun viewer, computed from the
recorded data and the layout's ranges (learner/flightlogs/blueprint_reader.py): which ticks
of a value axis are labelled, and which series lie on top of each other.

The viewer (egui_plot) puts its ticks at multiples of powers of ten only (never 2 or 5 times
one) and labels a tick only where it is at least LABEL_SPACING_PX from the next. A view with
no fixed range shows its data's range and a margin. The review's views are about 250 px tall
in a 1600x1000 window (VIEW_HEIGHT_PX; the assumption these checks rest on).
"""

from __future__ import annotations

import math

import numpy as np

VIEW_HEIGHT_PX = 250.0
LABEL_SPACING_PX = 20.0
AUTO_MARGIN = 0.05  # of the data's range, on each side, in a view without a fixed range
CLOSE_PX = 3.0  # two lines nearer than this read as one


def labelled_ticks(low: float, high: float, height_px: float = VIEW_HEIGHT_PX) -> list[float]:
    """The values of the labelled ticks of a value axis showing [low, high] over height_px."""
    if not high > low:
        return []
    step = 10.0 ** math.ceil(math.log10(LABEL_SPACING_PX * (high - low) / height_px))
    first, last = math.ceil(low / step - 1e-9), math.floor(high / step + 1e-9)
    return [k * step for k in range(first, last + 1)]


def shown_range(series: list[np.ndarray], fixed: tuple[float, float] | None) -> tuple[float, float]:
    """The value range a view shows: its fixed range, or its data's with the viewer's margin."""
    if fixed is not None:
        return fixed
    values = np.concatenate([s[np.isfinite(s)] for s in series])
    low, high = float(values.min()), float(values.max())
    margin = AUTO_MARGIN * (high - low)
    return low - margin, high + margin


def share_on_top(
    a: tuple[np.ndarray, np.ndarray],
    b: tuple[np.ndarray, np.ndarray],
    y_range: tuple[float, float],
    height_px: float = VIEW_HEIGHT_PX,
) -> float:
    """The share of the flight over which two series (times, values) are drawn less than
    CLOSE_PX apart (values clipped to the view: both off it on one side count as together)."""
    (ta, va), (tb, vb) = a, b
    ka, kb = np.isfinite(va), np.isfinite(vb)
    ta, va, tb, vb = ta[ka], va[ka], tb[kb], vb[kb]
    if len(ta) < 2 or len(tb) < 2:
        return 0.0
    both = (ta >= tb[0]) & (ta <= tb[-1])
    low, high = y_range
    px = height_px / (high - low)
    on_a = np.clip(va[both], low, high)
    on_b = np.clip(np.interp(ta[both], tb, vb), low, high)
    return float(np.mean(np.abs(on_a - on_b) * px < CLOSE_PX)) if both.any() else 0.0


# A line's pixels are its colour blended with the white background: alpha * colour + (1 -
# alpha) * white, the same alpha in every channel (grey grid lines and other colours are not).
MIN_ALPHA, ALPHA_SPREAD = 0.35, 0.15
MIN_LINE_PIXELS = 150


def drawn(image: np.ndarray, color: tuple[int, int, int], box: tuple[int, int, int, int]) -> dict:
    """Where a series of `color` is drawn within box (left, top, right, bottom) of a screenshot
    [H, W, 3]: its pixel count, mean row and horizontal extent (share of the box's width)."""
    left, top, right, bottom = box
    part = image[top:bottom, left:right].astype(float)
    alpha = (255.0 - part) / (255.0 - np.asarray(color, dtype=float))
    hit = (alpha.min(axis=2) > MIN_ALPHA) & (alpha.max(axis=2) - alpha.min(axis=2) < ALPHA_SPREAD)
    rows, cols = np.nonzero(hit)
    if len(cols) < MIN_LINE_PIXELS:
        return {"pixels": len(cols), "row": None, "extent": 0.0}
    return {
        "pixels": len(cols),
        "row": float(top + rows.mean()),
        "extent": float((cols.max() - cols.min()) / (right - left)),
    }
