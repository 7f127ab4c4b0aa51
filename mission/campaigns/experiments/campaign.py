"""A campaign of experiments: the trials of the chosen experiments, run by the shared campaign
runner (a local process pool or Ray tasks; `results.jsonl` resumes an interrupted campaign);
identical seeded flights of different experiments fly once."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tqdm import tqdm

from mission.campaigns.experiments.definitions import MULTI_NETWORK, MULTI_RHOS, Experiment, Trial
from mission.campaigns.experiments.runner import fly_trial
from mission.campaigns.runner import Task, append_result, load_results, run_tasks

RESULTS_FILE = "results.jsonl"
# The network of experiment 4.2, trained once per campaign: small data, capped epochs.
MULTI_SAMPLES_PER_RHO = 6000
MULTI_MAX_EPOCHS = 150
MULTI_CONTROL_GAIN_BOUND = 1.0


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
    # a trial's id names its definition: it is its key too
    outputs = (recordings,) if recordings is not None else ()
    tasks = [Task(t.id, t.id, fly_trial, (t, artefacts, recordings), outputs) for t in todo]

    def shared_records(record: dict[str, Any]) -> None:
        """The flight's record for every trial that shares it (the first is the runner's)."""
        group = sharing[record["id"].split("/", 2)[2]]
        for trial in group[1:]:
            append_result(path, _shared(record, trial))
        if "error" not in record:
            for trial in group:
                done[trial.id] = record if trial is group[0] else _shared(record, trial)

    if progress and len(trials) > len(todo):
        tqdm.write(f"experiment: {len(trials) - len(todo)} of {len(trials)} trials already flown")
    run_tasks(tasks, path, workers, ray_address, progress, "experiment", shared_records)
    return done
