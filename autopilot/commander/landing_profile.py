"""The landing setpoint's descent (pure): fast high up, at the landing speed near the ground.

As PX4's MPC_LAND_ALT1 / MPC_LAND_ALT2: above `alt1_m` over the ground the setpoint sinks at
the fast speed, below `alt2_m` at the landing speed, and in between at a speed falling
linearly with height. Only the last part of a landing meets the ground effect (a few rotor
radii up), so that is the part flown slowly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class LandingProfile:
    fast_m_s: float  # above alt1_m
    slow_m_s: float  # below alt2_m: the landing speed
    alt1_m: float
    alt2_m: float

    def _blend(self) -> tuple[float, float, float, float]:
        """(fast, slow, alt1, alt2) made consistent: never slower high up than low down,
        alt1 not below alt2."""
        slow = self.slow_m_s
        return max(self.fast_m_s, slow), slow, max(self.alt1_m, self.alt2_m), self.alt2_m

    def speed_m_s(self, height_m: float) -> float:
        """The setpoint's sink rate at `height_m` above the ground."""
        fast, slow, alt1, alt2 = self._blend()
        if height_m >= alt1:
            return fast
        if height_m <= alt2:
            return slow
        return slow + (fast - slow) * (height_m - alt2) / (alt1 - alt2)

    def height_m(self, start_height_m: float, elapsed_s: float) -> float:
        """The setpoint's height above the ground `elapsed_s` after the landing began at
        `start_height_m` (in closed form: the blend is exponential in time)."""
        fast, slow, alt1, alt2 = self._blend()
        h, t = start_height_m, max(elapsed_s, 0.0)
        if fast == slow:
            return h - slow * t
        if h > alt1:  # the fast part
            to_alt1 = (h - alt1) / fast
            if t <= to_alt1:
                return h - fast * t
            h, t = alt1, t - to_alt1
        if h > alt2 and alt1 > alt2:
            # the blend: u = slow + k (h - alt2) decays as exp(-k t), as dh/dt = -u
            k = (fast - slow) / (alt1 - alt2)
            u0 = slow + k * (h - alt2)
            to_alt2 = math.log(u0 / slow) / k
            if t <= to_alt2:
                return alt2 + (u0 * math.exp(-k * t) - slow) / k
            h, t = alt2, t - to_alt2
        return h - slow * t
