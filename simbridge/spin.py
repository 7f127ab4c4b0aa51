"""When a lockstep peer may busy-poll for the other's reply instead of sleeping in the kernel.

A reply usually comes within a few hundred microseconds, and waking a sleeping process costs
tens of microseconds on these machines, so on an otherwise idle machine spinning briefly is
worth about a sixth of a flight's wall time. On a busy one it is ruinous: the spinner holds a
core its peer (or another flight) needs, and a flight beside two CPU-bound processes ran 2.2x
slower spinning than sleeping. So each side spins only while the kernel reports no more
runnable threads than cores, sampled every few hundred steps."""

from __future__ import annotations

import os
import time

SPIN_S = 0.0005  # longest busy-poll for a reply before sleeping in the kernel
SAMPLE_EVERY_S = 0.1  # how often the machine's runnable count is read
LOADAVG = "/proc/loadavg"  # its fourth field: runnable scheduling entities / all of them


def runnable_threads(text: str) -> int:
    """The runnable count of a /proc/loadavg line ("0.52 0.58 0.59 3/467 12345")."""
    return int(text.split()[3].split("/")[0])


class SpinPolicy:
    """`spin_s()`: how long to busy-poll now, SPIN_S or 0. Where the runnable count cannot be
    read (not Linux) it never spins: sleeping is never wrong, only slower."""

    def __init__(self, cores: int | None = None, loadavg: str = LOADAVG) -> None:
        self._cores = cores or len(os.sched_getaffinity(0))
        self._loadavg = loadavg
        self._spin = False
        self._next_sample = 0.0
        self.samples = 0
        self.spinning_samples = 0

    def spin_s(self) -> float:
        now = time.perf_counter()
        if now >= self._next_sample:
            self._next_sample = now + SAMPLE_EVERY_S
            self._spin = self._sample()
        return SPIN_S if self._spin else 0.0

    def _sample(self) -> bool:
        try:
            with open(self._loadavg) as f:
                running = runnable_threads(f.read())
        except (OSError, ValueError, IndexError):
            return False
        self.samples += 1
        # this process is one of them; its peer, spinning or working, another
        spin = running <= self._cores
        self.spinning_samples += spin
        return spin
