"""A campaign: the trials of the chosen experiments flown by a local process pool or as Ray
tasks, each result appended to `results.jsonl` as it finishes, so an interrupted campaign
resumes where it stopped."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from multiprocessing import get_context
from pathlib import Path
from typing import Any

from tqdm import tqdm

from mission.campaigns.experiments.definitions import MULTI_NETWORK, MULTI_RHOS, Experiment, Trial
from mission.campaigns.experiments.runner import fly_trial
from simbridge.config import ConfigError

RESULTS_FILE = "results.jsonl"
# The network of experiment 4.2, trained once per campaign: small data, capped epochs.
MULTI_SAMPLES_PER_RHO = 6000
MULTI_MAX_EPOCHS = 150
MULTI_CONTROL_GAIN_BOUND = 1.0


def load_results(path: Path) -> dict[str, dict[str, Any]]:
    """Finished trials by id. A torn last line (the campaign was killed while writing) and
    failed trials are left out: they are flown again."""
    results: dict[str, dict[str, Any]] = {}
    if not path.exists():
        return results
    for line in path.read_text().splitlines():
        try:
            record = json.loads(line)
        except json.JSONDecodeError:
            continue
        if isinstance(record, dict) and "id" in record and "error" not in record:
            results[record["id"]] = record
    return results


def append_result(path: Path, record: dict[str, Any]) -> None:
    """One line per trial, on disk before the next trial is counted; after a torn last line
    (a campaign killed while writing) on a line of its own."""
    torn = False
    if path.exists() and path.stat().st_size > 0:
        with path.open("rb") as f:
            f.seek(-1, os.SEEK_END)
            torn = f.read(1) != b"\n"
    with path.open("a") as f:
        f.write(("\n" if torn else "") + json.dumps(record) + "\n")
        f.flush()
        os.fsync(f.fileno())


def prepare_artefacts(
    experiments: list[Experiment], out: Path, say: Callable[[str], None] = print
) -> dict[str, str]:
    """Campaign-made inputs, cached in the out dir: the network trained on several rho."""
    artefacts: dict[str, str] = {}
    if any(e.needs_multi for e in experiments):
        artefacts[MULTI_NETWORK] = str(train_multi_network(out / "models", say))
    return artefacts


def train_multi_network(folder: Path, say: Callable[[str], None] = print) -> Path:
    """The expert gathers MULTI_SAMPLES_PER_RHO samples at each of MULTI_RHOS; one network is
    trained on them together (deterministic: seeded flights and training)."""
    from learner.dataset import load_dataset
    from learner.train import TrainConfig, train, write_outputs
    from mission.campaigns.gather import gather

    name = "multi_rho" + "_".join(f"{r:g}" for r in MULTI_RHOS)
    model = folder / f"{name}.npz"
    if model.exists():
        say(f"network trained on rho {', '.join(f'{r:g}' for r in MULTI_RHOS)}: {model} (cached)")
        return model
    t0 = time.perf_counter()
    data = []
    for i, rho in enumerate(MULTI_RHOS):
        path = folder / "data" / f"rho{rho:g}.npz"
        if not path.exists():
            gather(rho, MULTI_SAMPLES_PER_RHO, 100 + i, path, progress=False)
        data.append(load_dataset(path))
    # rho 2's data: the bound the shipped rho2 network was trained with (README)
    config = TrainConfig(max_epochs=MULTI_MAX_EPOCHS, control_gain_bound=MULTI_CONTROL_GAIN_BOUND)
    result = train(data, config, progress=False)
    write_outputs(result, model)
    say(
        f"trained the rho {' + '.join(f'{r:g}' for r in MULTI_RHOS)} network in "
        f"{time.perf_counter() - t0:.0f} s ({result.metrics['epochs']} epochs): {model}"
    )
    return model


def _pool_results(
    trials: list[Trial], artefacts: dict[str, str], recordings: Path | None, workers: int
) -> Iterator[dict[str, Any]]:
    # spawn: a fresh interpreter per worker, no inherited threads or sockets
    with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as pool:
        pending = {pool.submit(fly_trial, t, artefacts, recordings) for t in trials}
        try:
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for future in done:
                    yield future.result()
        finally:
            for future in pending:
                future.cancel()


def ray_init(address: str, workers: int | None = None) -> None:
    """Connect to a Ray cluster (`auto`, `HOST:PORT`, `ray://HOST:PORT`), or `local`: start
    a Ray instance on this machine."""
    try:
        import ray
    except ImportError:
        raise ConfigError(
            "--ray: ray is not installed; install the extra: pip install -c constraints.txt "
            "-e '.[ray]'"
        ) from None
    if ray.is_initialized():
        return
    if address == "local":
        ray.init(num_cpus=workers or os.cpu_count(), include_dashboard=False, log_to_driver=False)
    else:
        ray.init(address=address, log_to_driver=False)


def _ray_results(
    trials: list[Trial], artefacts: dict[str, str], recordings: Path | None
) -> Iterator[dict[str, Any]]:
    import ray

    task = ray.remote(num_cpus=1)(fly_trial)  # one flight per core, as the pool
    pending = [task.remote(t, artefacts, recordings) for t in trials]
    try:
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                yield ray.get(ref)
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)


def _shared(record: dict[str, Any], trial: Trial) -> dict[str, Any]:
    """`record`'s flight as the result of `trial` (the same seeded flight, another trial)."""
    return {**record, "id": trial.id, "trial": trial.to_dict(), "same_flight_as": record["id"]}


def run_trials(
    trials: list[Trial],
    out: Path,
    artefacts: dict[str, str],
    workers: int | None = None,
    ray_address: str | None = None,
    keep_recordings: bool = False,
    progress: bool = True,
) -> dict[str, dict[str, Any]]:
    """Fly the trials the results file lacks; returns every finished trial's record by id."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / RESULTS_FILE
    done = load_results(path)
    # identical seeded flights of different experiments fly once (the lockstep path is
    # reproducible to the bit); each trial still gets its own record
    flown = {r["id"].split("/", 2)[2]: r for r in done.values()}
    sharing: dict[str, list[Trial]] = {}
    for t in trials:
        if t.id in done:
            continue
        if t.flight_key in flown:
            done[t.id] = _shared(flown[t.flight_key], t)
            append_result(path, done[t.id])
        else:
            sharing.setdefault(t.flight_key, []).append(t)
    todo = [group[0] for group in sharing.values()]
    recordings = out / "recordings" if keep_recordings else None
    workers = workers or os.cpu_count() or 1
    if ray_address is not None:
        ray_init(ray_address, workers)
        stream = _ray_results(todo, artefacts, recordings)
    else:
        stream = _pool_results(todo, artefacts, recordings, workers)
    bar = tqdm(
        total=len(trials),
        initial=len(trials) - sum(len(group) for group in sharing.values()),
        unit="trial",
        desc="experiment",
        disable=not progress,
    )
    failed = 0
    try:
        for record in stream:
            group = sharing[record["id"].split("/", 2)[2]]
            for k, trial in enumerate(group):
                shared = record if k == 0 else _shared(record, trial)
                append_result(path, shared)
                if "error" in shared:
                    failed += 1
                    tqdm.write(f"trial {shared['id']} failed: {shared['error']}")
                else:
                    done[shared["id"]] = shared
                bar.update(1)
            bar.set_postfix(failed=failed)
    finally:
        bar.close()
    return done
