"""`groundfx bench campaign`: the campaign runner's throughput, the same short seeded flights
with 1 and with K local workers, and their ratio (measured in the same run)."""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path
from typing import Any

from mission.campaigns.gather import gather_flight
from mission.campaigns.runner import Task, run_tasks

SAMPLES_PER_FLIGHT = 300  # 3 s of airborne samples at 100 Hz: a short flight, start-up included


def bench_campaign(flights: int = 8, workers: int = 2, rho: float = 2.0) -> dict[str, Any]:
    """Flights per minute with one worker and with `workers`, each setting on its own folder
    (nothing reused), and the ratio: the runner's scaling on this machine."""
    load_before = os.getloadavg()[0]
    rates = {}
    for k in (1, workers):
        with tempfile.TemporaryDirectory(prefix="groundfx-campaign-") as tmp:
            folder = Path(tmp)
            tasks = [
                Task(f"flight{i}", str(i), gather_flight,
                     (rho, SAMPLES_PER_FLIGHT, i, folder / f"flight{i}.npz", "default"))
                for i in range(flights)
            ]  # fmt: skip
            t0 = time.perf_counter()
            records = run_tasks(tasks, folder / "results.jsonl", workers=k, progress=False)
            wall_s = time.perf_counter() - t0
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
        "cpu_count": os.cpu_count(),
        "load_average": (load_before, os.getloadavg()[0]),
    }
