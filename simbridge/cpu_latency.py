"""A lockstep flight's CPU wake-up latency: the kernel's PM QoS request, held while it runs.

In lockstep each process blocks in the kernel until the other's message arrives (no polling
loop in either). An idle CPU, though, halts; on a virtual machine whose idle driver halts at
once (`haltpoll` with `guest_halt_poll_ns` 0, as on the 2-core machines this project is
benchmarked on) every message then pays the wake-up of a halted virtual CPU, tens of
microseconds, twice a step: about 40% of the loop's rate.

Linux lets a program ask for a bound on that latency: open `/dev/cpu_dma_latency`, write a
32-bit number of microseconds, keep the file open (the kernel's PM QoS interface,
Documentation/power/pm_qos_interface.rst; cyclictest and tuned's latency-performance
profile do the same). With 0 the idle CPUs take the cpuidle state whose exit latency is
0, the kernel's polling idle loop, which gives way at once to any runnable task: the
processes still block, and a third process finds the CPUs as free as without it. The price is
power (idle CPUs spin while the request is held; on a virtual machine its host sees the
idle virtual CPUs busy), so the simulator holds it only while it serves a lockstep flight
as fast as possible, and `--no-low-latency-idle` declines it.

Writing the file needs root (or a udev rule); where it cannot be written the flight runs
without it and the simulator's summary says why.
"""

from __future__ import annotations

import os
import struct
from types import TracebackType

PM_QOS_DEVICE = "/dev/cpu_dma_latency"


class CpuLatencyRequest:
    """`with CpuLatencyRequest(0) as request:` holds the bound; `request.held` says whether
    the kernel took it, `request.reason` why not. `not_asked` (a reason) enters nothing."""

    def __init__(
        self, latency_us: int = 0, device: str = PM_QOS_DEVICE, not_asked: str = ""
    ) -> None:
        if not 0 <= latency_us <= 2_000_000_000:
            raise ValueError(f"latency_us: {latency_us} outside [0, 2000000000]")
        self.latency_us = latency_us
        self.device = device
        self._fd: int | None = None
        self._granted = False  # the kernel took it (still true after the request ends)
        self.reason = not_asked

    @property
    def held(self) -> bool:
        return self._fd is not None

    def __enter__(self) -> CpuLatencyRequest:
        if self.reason:
            return self
        try:
            fd = os.open(self.device, os.O_WRONLY)
        except OSError as err:
            self.reason = f"{self.device}: {(err.strerror or str(err)).lower()}"
            return self
        try:
            os.write(fd, struct.pack("i", self.latency_us))
        except OSError as err:
            os.close(fd)
            self.reason = f"{self.device}: {(err.strerror or str(err)).lower()}"
            return self
        self._fd, self._granted = fd, True
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing the file withdraws the request
            self._fd = None

    def describe(self) -> str:
        """One phrase for the simulator's summary (during the request or after it)."""
        if self._granted:
            return f"CPU wake-up latency held at {self.latency_us} us"
        return f"CPU wake-up latency not requested ({self.reason})"
