"""When the loop takes a learning sample: at a fixed rate, on the control steps' clock."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SampleSchedule:
    next_s: float = 0.0  # the next sample is due at this simulated time

    def due(self, time_s: float, rate_hz: float, in_the_air: bool) -> bool:
        """A sample is due now: sampling is on, its time has come, and the vehicle flies (on
        the ground the contact force would pass for ground effect in equation 3.16)."""
        return rate_hz > 0.0 and time_s >= self.next_s and in_the_air

    def after_sample(self, time_s: float, rate_hz: float) -> SampleSchedule:
        """The schedule once a sample was taken at `time_s`: the next period on the grid (a
        100 Hz schedule on 250 Hz steps keeps its mean rate), or a period from now if the
        grid fell behind by more than one (a pause on the ground)."""
        period = 1.0 / rate_hz
        on_grid = time_s - self.next_s < period
        return SampleSchedule(self.next_s + period if on_grid else time_s + period)
