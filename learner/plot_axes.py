"""Log-scale axes labelled with plain numbers (0.02, 0.1, 1e-05).

Matplotlib's default labels for a log axis are powers of ten typeset by mathtext, whose parsing
and layout took a tenth of a diagnosis's time; plain numbers read as well.
"""

from __future__ import annotations

from typing import Any


def plain_log_axis(axis: Any, subs: tuple[float, ...] = (1.0,)) -> None:
    """Label `axis` (an `ax.xaxis` or `ax.yaxis` on a log scale) at `subs` times each power
    of ten, with plain numbers, and leave the other ticks unlabelled."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    axis.set_major_locator(LogLocator(subs=subs))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(NullFormatter())
