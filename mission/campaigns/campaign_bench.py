"""`groundfx bench campaign`: the campaign runner's throughput, the same short seeded flights
with one worker on one core, one worker, and K local workers, and their ratios (measured in
the same run)."""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path
from typing import Any

from mission.campaigns.gather import gather_flight
from mission.campaigns.runner import Task, run_tasks

SAMPLES_PER_FLIGHT = 1000  # 10 s of airborne samples at 100 Hz, after take-off


def bench_campaign(flights: int = 8, workers: int = 2, rho: float = 2.0) -> dict[str, Any]:
    """Flights per minute with one worker on one core, one worker on every core, and
    `workers` workers, each setting on its own folder (nothing reused); their ratios: the
    runner's scaling on this machine."""
    load_before = os.getloadavg()[0]
    cores_here = sorted(os.sched_getaffinity(0))
    one_core = cores_here[:1]
    runs = (("1_on_1_core", 1, one_core), ("1", 1, cores_here), (str(workers), workers, cores_here))
    rates, cores = {}, {}
    for name, k, allowed in runs:
        rates[name], cores[name] = _run(flights, k, rho, allowed)
    return {
        "flights": flights,
        "workers": workers,
        **{f"flights_per_min_{name}": rates[name] for name, _, _ in runs},
        "speedup": rates[str(workers)] / rates["1"],
        # K workers on K cores against one worker held to one core: how the runner scales
        # with the cores it is given
        "speedup_per_core": rates[str(workers)] / rates["1_on_1_core"],
        # one flight is two processes taking turns, yet they overlap (the simulator encodes
        # a step's truth while the autopilot computes): the cores it keeps busy bound the
        # speedup over one unrestricted worker at cpu_count / cores_per_flight
        "cores_per_flight": cores["1"],
        "speedup_bound": min(workers, len(cores_here) / cores["1"]),
        "cpu_count": len(cores_here),
        "load_average": (load_before, os.getloadavg()[0]),
    }


def _run(flights: int, workers: int, rho: float, allowed: list[int]) -> tuple[float, float]:
    """Flights per minute and cores kept busy: `flights` flights by `workers` workers, the
    pool and its flights held to the cores `allowed` (children inherit it)."""
    before = os.sched_getaffinity(0)
    os.sched_setaffinity(0, allowed)
    try:
        with tempfile.TemporaryDirectory(prefix="groundfx-campaign-") as tmp:
            folder = Path(tmp)
            tasks = [
                Task(f"flight{i}", str(i), gather_flight,
                     (rho, SAMPLES_PER_FLIGHT, i, folder / f"flight{i}.npz", "default"),
                     outputs=(folder / f"flight{i}.npz",))
                for i in range(flights)
            ]  # fmt: skip
            t0 = time.perf_counter()
            records = run_tasks(tasks, folder / "results.jsonl", workers=workers, progress=False)
            wall_s = time.perf_counter() - t0
            # each flight's task and its simulator and autopilot
            cores = sum(r["cpu_s"] for r in records.values()) / wall_s
    finally:
        os.sched_setaffinity(0, before)
    failed = sum("error" in r for r in records.values())
    if failed:
        raise RuntimeError(f"{failed} of {flights} flights failed with {workers} workers")
    return flights / wall_s * 60.0, cores
