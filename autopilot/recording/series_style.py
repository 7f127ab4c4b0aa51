"""How each plotted series is named and coloured in the recording, so that no two series that
share a view share a name or a colour (the blueprint's views: autopilot/recording/blueprint.py)."""

from __future__ import annotations

from collections.abc import Sequence

from learner.flightlogs.recording import COUNTERS, SERIES

Rgb = tuple[int, int, int]

RED, GREEN, BLUE = (214, 39, 40), (44, 160, 44), (31, 119, 180)
ORANGE, GREY, PURPLE = (255, 127, 14), (127, 127, 127), (148, 103, 189)
GE_COLORS: dict[str, Rgb] = {"true": (40, 180, 80), "predicted": (255, 140, 0)}
ROTOR_COLORS: tuple[Rgb, ...] = ((220, 60, 60), (60, 120, 220), (60, 180, 90), (230, 170, 40))
ROTOR_ACTUAL_COLORS: tuple[Rgb, ...] = tuple(
    (min(255, r + 90), min(255, g + 90), min(255, b + 90)) for r, g, b in ROTOR_COLORS
)
XYZ = (RED, GREEN, BLUE)
HOLD_COLOR: Rgb = (31, 119, 180)  # the height error near the ground
MODEL_ERROR_COLOR: Rgb = (148, 103, 189)  # the ground-effect model's error
LINK_COLORS: dict[str, tuple[Rgb, ...]] = {  # received, dropped, rejected
    "sim": ((31, 119, 180), (120, 170, 220), (10, 60, 110)),
    "gcs": ((255, 127, 14), (250, 180, 110), (170, 80, 0)),
}

# path -> (names, colours); paths not listed keep SERIES's names, coloured x, y, z
STYLES: dict[str, tuple[tuple[str, ...], tuple[Rgb, ...]]] = {
    "plots/z": (("z, true", "z setpoint"), (BLUE, GREY)),
    "plots/height": (("height, estimated",), (ORANGE,)),
    "plots/rotors/commanded": (tuple(f"n{i} commanded" for i in range(4)), ROTOR_COLORS),
    "plots/rotors/actual": (tuple(f"n{i} actual (ESC)" for i in range(4)), ROTOR_ACTUAL_COLORS),
    "plots/learner/loss": (("loss (standardised)",), (RED,)),
    "plots/learner/log10_loss": (("log10 of the loss (standardised)",), (RED,)),
    "plots/learner/version": (("weights version",), (BLUE,)),
    # the review's differences: colours no other view of the review uses, so that a
    # screenshot tells the views apart
    "plots/height_error_mm": (("z - setpoint (mm)",), (HOLD_COLOR,)),
    "plots/model_error_mn": (("predicted - true (mN)",), (MODEL_ERROR_COLOR,)),
    **{
        f"plots/rotors/difference/{i}": ((f"n{i} commanded - measured (rad/s)",), (color,))
        for i, color in enumerate(ROTOR_COLORS)
    },
    **{
        f"plots/ground_effect/{axis}/{kind}": ((kind,), (GE_COLORS[kind],))
        for axis in "xyz"
        for kind in ("true", "predicted")
    },
}


def series_style(path: str, modes: Sequence[str] = ()) -> tuple[list[str], list[Rgb]]:
    """The names and colours of the series at `path` (one per column)."""
    if path == "plots/mode":  # the mode's index, its legend naming every index
        legend = ", ".join(f"{i} {m}" for i, m in enumerate(modes))
        return [f"mode ({legend})"], [PURPLE]
    if path in STYLES:
        names, colors = STYLES[path]
        return list(names), list(colors)
    names = SERIES[path]
    palette = (*XYZ, PURPLE)
    return list(names), [palette[i % len(palette)] for i in range(len(names))]


def counter_style(link: str) -> tuple[list[str], list[Rgb]]:
    """A MAVLink link's counters, named by the link ("sim received", "gcs dropped")."""
    colors = LINK_COLORS.get(link, (PURPLE, GREY, (60, 60, 60)))
    return [f"{link} {c}" for c in COUNTERS], list(colors)
