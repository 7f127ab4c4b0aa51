"""Seeded landing trials: take off from a random point, descend to hold 3 cm above the ground
at another, land. The seed picks both points; every trial is a real `groundfx fly`."""

from __future__ import annotations

import random
import tempfile
from pathlib import Path
from typing import Any

import yaml

from mission.fly import fly

HOLD_ALTITUDE_M = 0.03


def landing_trial(seed: int) -> tuple[dict[str, Any], str]:
    """(mission as YAML data, start as X,Y,Z) for one trial."""
    rng = random.Random(seed)
    sx, sy = rng.uniform(-0.25, 0.25), rng.uniform(-0.25, 0.25)
    hx, hy = rng.uniform(-0.25, 0.25), rng.uniform(-0.25, 0.25)
    mission = {
        "name": f"landing trial {seed}",
        "takeoff_altitude_m": 1.0,
        "waypoints": [
            {"position_m": [hx, hy, 1.0], "hold_s": 1.0},
            {
                "position_m": [hx, hy, HOLD_ALTITUDE_M],
                "hold_s": 6.0,
                "acceptance_radius_m": 0.01,
                "timeout_s": 8.0,
            },
        ],
        "land": True,
    }
    return mission, f"{sx},{sy},0.0126"


def fly_landing_trials(
    seeds: list[int], model: str, world: str = "default", network: str | Path | None = None
) -> list[dict[str, Any]]:
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            mission, start = landing_trial(seed)
            path = Path(tmp) / f"trial_{seed}.yaml"
            path.write_text(yaml.safe_dump(mission))
            # reproducible: the autopilot arms itself at a fixed simulated time
            flown = fly(
                path, world, model, start=start, network=network, via_gcs=False, record=False
            )
            results.append(flown)
    return results


def landing_trial_flight(
    seed: int, model: str, world: str, network: str | Path | None
) -> dict[str, Any]:
    """One seeded landing trial of `model` (a task of the campaign runner): its summary."""
    (summary,) = fly_landing_trials([seed], model, world, network)
    return summary


def evaluate_models(
    seeds: list[int],
    world: str,
    network: str | Path | None,
    say=print,
    workers: int | None = 1,
    ray_address: str | None = None,
    out: Path | None = None,
    progress: bool = False,
) -> dict[str, Any]:
    """Hold z error of `none`, `analytic` and `neural` over seeded landing trials, flown by
    the campaign runner (`workers` local processes, or Ray tasks at `ray_address`); with
    `out`, each trial lands in out/results.jsonl and a rerun flies only the missing ones."""
    import hashlib

    import numpy as np

    from learner.stats import gap_closed, mean_ci95, welch
    from mission.campaigns.runner import Task, run_tasks, source_fingerprint

    source = source_fingerprint()
    tasks = []
    for model in ("none", "analytic", "neural"):
        net = str(network) if model == "neural" and network is not None else None
        for seed in seeds:
            key = hashlib.sha256(repr((model, seed, world, net, source)).encode()).hexdigest()
            tasks.append(Task(f"{model}/{seed}", key[:16], landing_trial_flight,
                              (seed, model, world, net)))  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="groundfx-evaluate-") as tmp:
        results_path = (out or Path(tmp)) / "results.jsonl"
        records = run_tasks(tasks, results_path, workers, ray_address, progress, "evaluate")
    failed = [r for r in records.values() if "error" in r]
    if failed:
        raise RuntimeError(f"{len(failed)} trials failed: {failed[0]['id']}: {failed[0]['error']}")
    errors = {}
    for model in ("none", "analytic", "neural"):
        errors[model] = np.array([records[f"{model}/{s}"]["hold_z_rms_error_m"] for s in seeds])
        mean, lo, hi = mean_ci95(errors[model])
        say(
            f"{model:9s} hold z RMS error {mean * 1000:7.2f} mm  (95% CI {lo * 1000:.2f} to "
            f"{hi * 1000:.2f}, n = {len(seeds)})"
        )
    closed = gap_closed(errors["none"], errors["analytic"], errors["neural"])
    t, p = welch(errors["neural"], errors["none"])
    say(
        f"neural closes {closed * 100:.1f}% of the gap between none and analytic; "
        f"Welch t-test neural against none: t = {t:.2f}, p = {p:.2g}"
    )
    return {
        "errors_m": {k: v.tolist() for k, v in errors.items()},
        "gap_closed": closed,
        "welch_t": t,
        "welch_p": p,
    }
