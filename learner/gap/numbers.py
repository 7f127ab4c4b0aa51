"""Figures as the diagnosis prints them: never "nan". In text a figure that could not be
measured reads "n/a, because ..."; in JSON it is null."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

NO_GAP = "there is no gap above the noise to shrink"


def finite(x: Any) -> bool:
    """Whether `x` is a number that can be printed (not None, nan or infinite)."""
    try:
        return x is not None and math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


def fig(value: Any, spec: str = ".2f", scale: float = 1.0, unit: str = "", why: str = "") -> str:
    """`value * scale` formatted with `spec` and `unit`, or "n/a, because `why`"."""
    if not finite(value):
        return f"n/a, because {why or 'it could not be measured'}"
    return f"{float(value) * scale:{spec}}" + (f" {unit}" if unit else "")


def pct(share: Any, why: str = NO_GAP) -> str:
    """A share as a whole percentage ('42%'), or "n/a, because `why`"."""
    return fig(share, ".0f", 100.0, why=why) + ("%" if finite(share) else "")


def json_safe(x: Any) -> Any:
    """`x` with every non-finite float (numpy's too) as None and numpy values as plain ones:
    what `json.dumps` writes as valid JSON."""
    if isinstance(x, dict):
        return {k: json_safe(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_safe(x.tolist())
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x
