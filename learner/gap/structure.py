"""Whether what the catalogue leaves has structure outside it, and what carries it.

The rule: the residual the chosen effects leave has structure outside the catalogue when a
network on the regime features, trained on the fitting flights, removes at least
STRUCTURE_GAIN of it on flights it was not trained on (the held-out flights; without them,
fitting flights left out in turn), and beyond the noise: the mean square of the smoothed
residual it removes there exceeds what noise alone could move it by (1.96 sampling standard
deviations of a mean square of smoothed noise over those rows, `noise_margin_n2`). Only
without both may the report say there is no structure; only with both is the learnt world
offered.

The inputs that carry it: each input group left out of the network's inputs in turn, the
network retrained on a small budget (FAST_EPOCHS, FAST_ROWS), and the loss on the same
unseen rows compared with all inputs'; a group whose absence loses at least CARRIER_MIN of
what the network removes carries it.
"""

from __future__ import annotations

import math
from typing import Any, Protocol

import numpy as np

from learner.gap.residual import (
    SMOOTH_WINDOW_S,
    measured_floor_ms,
    smooth_per_segment,
    white_floor_ms,
)
from learner.gap.residual_net import STATE_INPUTS, train_model
from simbridge.effects.learned import POSITION

STRUCTURE_GAIN = 0.20  # the learnt residual removes at least this share of what is left
Z95 = 1.959964
CARRIER_MIN = 0.25  # an input whose absence loses this share of what the network removes
# the leave-one-input-out networks' budget: ~0.15 s each on these machines, seven in all
FAST_EPOCHS, FAST_ROWS, FAST_LR = 100, 2000, 1e-2
SHARE_MIN = 0.10  # below this share of the gap the catalogue leaves, a remainder is small

INPUT_GROUPS: dict[str, tuple[str, ...]] = {
    "height above the surface": tuple(f"height_{i}" for i in range(4)),
    "tilt": ("tilt_forward", "tilt_left", "body_z_up"),
    "horizontal speed": ("horizontal_speed_m_s",),
    "direction of travel relative to the body": ("travel_forward", "travel_left"),
    "vertical speed": ("vz_m_s",),
    "rotor thrust": tuple(f"thrust_{i}" for i in range(4)),
    "time since take-off": ("time_since_takeoff_s",),
    "position": POSITION,
}


class Rows(Protocol):
    """A flight's rows, as far as the noise test needs them."""

    time_s: np.ndarray
    segment: np.ndarray
    dt_s: float


def removed_n2(parts: list[tuple[Rows, np.ndarray, np.ndarray]]) -> float:
    """The mean square (N^2) of the smoothed residual the network removes on the unseen rows:
    from `left` to `learnt` of each (flight, left, learnt), pooled over rows."""
    total, rows = 0.0, 0
    for d, left, learnt in parts:
        w = max(1, round(SMOOTH_WINDOW_S / d.dt_s))
        a = smooth_per_segment(left, d.segment, w)
        b = smooth_per_segment(learnt, d.segment, w)
        total += float(np.sum(a * a) - np.sum(b * b))
        rows += len(left)
    return total / max(rows, 1)


def noise_margin_n2(parts: list[tuple[Rows, np.ndarray, np.ndarray]], noise_var: float) -> float:
    """What noise alone may move a mean square of the smoothed residual by over the unseen
    rows (N^2): Z95 sampling standard deviations, F sqrt(2 / (3 n)) with F the noise's floor
    in a SMOOTH_WINDOW_S average (the larger of white noise of variance `noise_var` per
    component and the one measured on the learnt residual: coloured noise) and n the
    independent windows the rows hold; inf without rows."""
    floor, rows, windows = 0.0, 0, 0.0
    for d, _, learnt in parts:
        w = max(1, round(SMOOTH_WINDOW_S / d.dt_s))
        f = max(white_floor_ms(noise_var, d.dt_s), measured_floor_ms(learnt, d.segment, d.dt_s))
        floor += f * len(learnt)
        rows += len(learnt)
        windows += len(learnt) / w
    if rows == 0:
        return math.inf
    return Z95 * (floor / rows) * math.sqrt(2.0 / (3.0 * windows))


def has_structure(gain: float | None, removed: float, margin: float) -> bool:
    """The rule of the module's doc: the network removes at least STRUCTURE_GAIN of what is
    left on unseen rows (`gain`), and more than noise could (`removed` over `margin`, N^2)."""
    return gain is not None and math.isfinite(gain) and gain >= STRUCTURE_GAIN and removed > margin


def input_losses(
    x_train: np.ndarray,
    y_train: np.ndarray,
    x_test: np.ndarray,
    y_test: np.ndarray,
    inputs: tuple[str, ...] = STATE_INPUTS,
) -> dict[str, Any]:
    """What each input group carries: the unseen rows' loss (mean square of the smoothed
    residual `y_test`, heading frame, less the network's force) with every one of `inputs`,
    with none of the network, and with each group left out (the network retrained without
    it); each group's `loss_share` is its absence's loss increase over what the network
    removes."""

    def loss(left_out: tuple[str, ...]) -> float:
        kept = tuple(f for f in inputs if f not in left_out)
        model = train_model(
            x_train, y_train, epochs=FAST_EPOCHS, max_rows=FAST_ROWS, lr=FAST_LR, inputs=kept
        )
        return float(np.mean(np.sum((y_test - model.heading_force_n(x_test)) ** 2, axis=1)))

    none = float(np.mean(np.sum(y_test**2, axis=1)))
    full = loss(())
    removed = none - full
    out: dict[str, Any] = {"removed_share": removed / none if none > 0 else None, "inputs": []}
    if removed <= 0.0:
        return out
    for name, group in INPUT_GROUPS.items():
        if any(f in inputs for f in group):
            out["inputs"].append({"input": name, "loss_share": (loss(group) - full) / removed})
    out["inputs"].sort(key=lambda i: -i["loss_share"])
    return out


def carried_by(inputs: list[dict[str, Any]]) -> list[str]:
    """The input groups whose absence loses at least CARRIER_MIN of what the network removes."""
    return [i["input"] for i in inputs if i["loss_share"] >= CARRIER_MIN]


def carriers_text(inputs: list[dict[str, Any]]) -> str:
    """'the inputs that carry it: direction of travel relative to the body (64%) ...' (the
    share of what the network removes lost without it), or why no input is named."""
    named = [i for i in inputs if i["loss_share"] >= CARRIER_MIN]
    if named:
        parts = [f"{i['input']} ({min(i['loss_share'], 1.0) * 100:.0f}%)" for i in named]
        return (
            "the inputs that carry it: " + ", ".join(parts) + " (the share of what the network "
            "removes that is lost when that input is left out of its inputs and it is retrained)"
        )
    if inputs:
        top = inputs[0]
        return (
            "no one input carries it alone: left out of the network's inputs, "
            f"{top['input']} loses the most, {max(top['loss_share'], 0.0) * 100:.0f}% of what "
            "it removes (the inputs share it)"
        )
    return "which inputs carry it could not be told: a small network retrained on them removes none"


def _carried(gain: float | None, where: str) -> str:
    """What a network on the regime features does on flights it was not trained on, in words:
    a share removed, never a negative or undefined one."""
    if gain is None or not np.isfinite(gain):
        return (
            f"a network on the regime features could not be scored on {where}: n/a, because "
            "the catalogue leaves no gap there above the noise to shrink"
        )
    if gain < 0.0:
        return (
            f"a network on the regime features does not carry over to {where} (it leaves "
            f"{-gain * 100:.0f}% more than it was given)"
        )
    return f"a network on the regime features removes {gain * 100:.0f}% of that on {where}"


def sentence(
    share: float,
    gain: float | None,
    structure: bool,
    carriers: list[dict[str, Any]] | None = None,
    where: str = "flights it was not trained on",
) -> str:
    """The unexplained remainder in words, by the rule of the module's doc: "structure outside
    the catalogue" (naming the inputs that carry it) or, only without it, "no structure"."""
    head = f"the catalogue leaves {share * 100:.0f}% of the systematic force gap"
    if structure:
        text = (
            f"{head}, and it is structure outside the catalogue: a network on the regime "
            f"features removes {float(gain or 0.0) * 100:.0f}% of it on {where}"
        )
        if carriers is not None:
            text += "; " + carriers_text(carriers)
        if share < SHARE_MIN:
            return text + "; it is small beside what the catalogue explains"
        return text + (
            ". No catalogue effect explains it; the effects named may stand in for one outside "
            "the catalogue"
        )
    head = f"{head}; {_carried(gain, where)}"
    if gain is not None and np.isfinite(gain) and gain >= STRUCTURE_GAIN:
        head += " (within the noise)"
    elif gain is not None and gain > 0.0:
        head += f" (under the {STRUCTURE_GAIN * 100:.0f}% that structure needs)"
    if share < SHARE_MIN:
        return head + ": no structure, nothing systematic is left that the catalogue misses"
    # a large share no function of the inputs carries from flight to flight: real, but not
    # the vehicle's (a neighbour's wake, gusts), or a function of what the inputs leave out
    return head + (
        ": no structure the learnt residual finds: what is left is no function of the "
        "vehicle's state as the network sees it (height, tilt, speed and direction of travel, "
        "thrust, time in the air) that holds from flight to flight (it differs between them: "
        "another vehicle's wake, gusts, the logs themselves; or it depends on what those "
        "inputs leave out, such as the position; or, where the gap is near the noise floor, "
        "noise)"
    )
