"""The flown path as the 3-D view draws it: line strips, redrawn as they grow.

A 3-D view shows the latest value of each entity at the time cursor, so a trail is redrawn
rather than appended to. Redrawing the whole path would grow with the square of the flight's
length; instead it is cut into segments of `segment_s` of flight (`world/trajectory/<k>`),
and only the segment in progress is redrawn, every `period_s`, up to the drone. Points are
kept every `spacing_m` flown: a hover adds none.
"""

from __future__ import annotations

import math

import numpy as np

Drawings = dict[int, tuple[list[float], list[np.ndarray]]]  # segment -> (times s, strips)


def firsts(t_s: np.ndarray, last_s: float, period_s: float) -> np.ndarray:
    """The rows that open a new period (multiples of `period_s`) after time `last_s`."""
    before = np.concatenate(([last_s], t_s[:-1]))
    return np.floor(t_s / period_s) > np.floor(before / period_s)


class Trail:
    def __init__(self, spacing_m: float = 0.01, period_s: float = 0.25, segment_s: float = 10.0):
        self.spacing_m, self.period_s, self.segment_s = spacing_m, period_s, segment_s
        self._segment = 0  # the segment in progress
        self._points = np.zeros((0, 3))  # its points so far
        self._drawn = 0  # how many of them its last drawing had
        self._flown_m = 0.0
        self._last_p: np.ndarray | None = None
        self._last_t = -math.inf

    def update(self, t: np.ndarray, p: np.ndarray) -> Drawings:
        """Feed the positions `p` [n, 3] at times `t` [n]; the drawings due, per segment:
        (times, strips), each strip the segment's points up to the drone at that time."""
        if self._last_p is None:
            self._points, self._last_p = p[:1], p[0]
        steps = np.linalg.norm(np.diff(np.vstack((self._last_p, p)), axis=0), axis=1)
        flown = self._flown_m + np.cumsum(steps)
        before = np.concatenate(([self._flown_m], flown[:-1]))
        keep = np.floor(flown / self.spacing_m) > np.floor(before / self.spacing_m)
        kept_t, kept_p = t[keep], p[keep]
        self._flown_m, self._last_p = float(flown[-1]), p[-1]
        drawn: Drawings = {}
        used = 0
        for i in np.flatnonzero(firsts(t, self._last_t, self.period_s)):
            upto = int(np.searchsorted(kept_t, t[i], side="right"))
            points = np.vstack((self._points, kept_p[used:upto]))
            used = upto
            segment = int(t[i] // self.segment_s)
            if segment != self._segment:  # the next one starts where the last drawing ended
                points = points[max(self._drawn - 1, 0) :]
                self._segment = segment
            self._points, self._drawn = points, len(points)
            times, strips = drawn.setdefault(segment, ([], []))
            times.append(float(t[i]))
            strips.append(np.vstack((points, p[i : i + 1])))
        self._last_t = float(t[-1])
        self._points = np.vstack((self._points, kept_p[used:]))
        return drawn
