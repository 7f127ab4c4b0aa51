"""The learner working and resting in turn within one flight (`--online-alternate S`).

What the learner costs the control loop is a difference of a few per cent, and a shared
machine's own speed moves by more than that from one flight to the next and, within a
flight, from one second to the next. Two flights, one learning and one not, compare two
machines. So `groundfx bench online` flies the learner in turns of S simulated seconds:
working (a sample taken for it every 10 ms, as in any learning flight) and resting
(no sample taken, as in a flight without learning; its process waits on its pipe), and
keeps each control step's time with the turn it fell in. A working turn and the resting
turns either side of it ran on the same machine within a fraction of a second.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class Alternation:
    period_s: float
    # one row per turn: working (1) or resting (0), control steps, simulated s, wall s
    turns: list[list[float]] = field(default_factory=list)
    _last: tuple[float, float] | None = None  # the previous step's simulated and wall time

    def working(self, t_s: float) -> bool:
        """Whether the learner works at simulated time `t_s` (it starts working)."""
        return int(t_s // self.period_s) % 2 == 0

    def step(self, t_s: float) -> bool:
        """A control step at `t_s`, counted in its turn; whether the learner works in it.
        The interval since the previous step (simulated and wall) goes to that step's turn."""
        now = time.perf_counter()
        if self._last is not None and self.turns:
            turn = self.turns[-1]
            turn[2] += t_s - self._last[0]
            turn[3] += now - self._last[1]
        self._last = (t_s, now)
        working = self.working(t_s)
        if not self.turns or bool(self.turns[-1][0]) != working:
            self.turns.append([float(working), 0.0, 0.0, 0.0])
        self.turns[-1][1] += 1
        return working

    def summary(self, controller_s: list[float]) -> dict[str, Any]:
        """The turns, and the control steps' times (`controller_s`, one per counted step) in
        microseconds, in order (`groundfx bench online` splits them by turn)."""
        out: dict[str, Any] = {"period_s": self.period_s, "turns": self.turns}
        if sum(int(turn[1]) for turn in self.turns) == len(controller_s):  # else: no split
            out["controller_us"] = np.round(np.asarray(controller_s) * 1e6, 1).tolist()
        return out
