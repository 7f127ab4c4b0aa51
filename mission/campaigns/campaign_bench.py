"""`groundfx bench campaign`: the campaign runner's throughput, the same short seeded flights
with 1 and with K local workers, and their ratio (measured in the same run)."""

from __future__ import annotations

import os
import resource
import tempfile
import time
from pathlib import Path
from typing import Any

from mission.campaigns.gather import gather_flight
from mission.campaigns.runner import Task, run_tasks

SAMPLES_PER_FLIGHT = 1000  # 10 s of airborne samples at 100 Hz, after take-off


def bench_campaign(flights: int = 8, workers: int = 2, rho: float = 2.0) -> dict[str, Any]:
    """Flights per minute with one worker and with `workers`, each setting on its own folder
    (nothing reused), and the ratio: the runner's scaling on this machine."""
    load_before = os.getloadavg()[0]
    rates, cores = {}, {}
    for k in (1, workers):
        with tempfile.TemporaryDirectory(prefix="groundfx-campaign-") as tmp:
            folder = Path(tmp)
            tasks = [
                Task(f"flight{i}", str(i), gather_flight,
                     (rho, SAMPLES_PER_FLIGHT, i, folder / f"flight{i}.npz", "default"))
                for i in range(flights)
            ]  # fmt: skip
            cpu0 = _children_cpu_s()
            t0 = time.perf_counter()
            records = run_tasks(tasks, folder / "results.jsonl", workers=k, progress=False)
            wall_s = time.perf_counter() - t0
            # the pool's processes and their flights' simulators, reaped when it closed
            cores[k] = (_children_cpu_s() - cpu0) / wall_s
            failed = sum("error" in r for r in records.values())
            if failed:
                raise RuntimeError(f"{failed} of {flights} flights failed with {k} workers")
            rates[k] = flights / wall_s * 60.0
    return {
        "flights": flights,
        "workers": workers,
        "flights_per_min_1": rates[1],
        f"flights_per_min_{workers}": rates[workers],
        "speedup": rates[workers] / rates[1],
        # one flight is two processes taking turns, yet they overlap (the simulator encodes
        # a step's truth while the autopilot computes): the cores it keeps busy bound the
        # speedup on this machine at cpu_count / cores_per_flight
        "cores_per_flight": cores[1],
        "speedup_bound": min(workers, (os.cpu_count() or 1) / cores[1]),
        "cpu_count": os.cpu_count(),
        "load_average": (load_before, os.getloadavg()[0]),
    }


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime
