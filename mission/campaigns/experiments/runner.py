"""One trial, flown for real: each flight a simulator and an autopilot process in lockstep on
the reproducible path (the autopilot arms itself at a fixed simulated time), so a trial gives
the same result wherever it runs. This is what a pool worker or a Ray task executes."""

from __future__ import annotations

import tempfile
import time
import traceback
from pathlib import Path
from typing import Any

import yaml

from mission.campaigns.experiments.definitions import MEASURES, MULTI_NETWORK, Flight, Trial
from mission.campaigns.experiments.missions import make_mission
from mission.campaigns.gather import world_yaml_with_rho
from mission.fly import fly
from simbridge.world import resolve_world_path

# The autopilot's options for online learning: the method by name, and the adapted network
# written at the end of the flight (4.4 flies it again).
ONLINE_OPTION = "--online"
SAVE_NETWORK_OPTION = "--save-model"
# A flight whose simulator link was lost (its process gone, or silent past the link timeout)
# is flown again up to this often (it is deterministic, so the retry gives what an
# undisturbed flight would have).
LINK_RETRIES = 2
# Kept from each flight's summary in the results file (the rest is wall-clock noise or bulk).
KEPT = (
    *MEASURES,
    "hold_z_max_error_m",
    "hold_z_mean_error_m",
    "bounce_m",
    "landed",
    "ended",
    "steps",
    "trajectory_sha256",
    "wall_s",
    "rtf",
)


def _world_file(flight: Flight, tmp: Path) -> str:
    if flight.rho_sim is None:
        return flight.world
    path = tmp / f"{flight.world}_rho{flight.rho_sim:g}.yaml"
    base = resolve_world_path(flight.world).read_text()
    path.write_text(world_yaml_with_rho(base, flight.rho_sim))
    return str(path)


def fly_trial(
    trial: Trial, artefacts: dict[str, str], recordings: Path | None = None
) -> dict[str, Any]:
    """Fly the trial's flights in order; the record the results file keeps. A flight that
    fails gives a record with `error` (a resumed campaign flies it again)."""
    wall0 = time.perf_counter()
    record: dict[str, Any] = {"id": trial.id, "trial": trial.to_dict(), "flights": []}
    try:
        with tempfile.TemporaryDirectory(prefix="gfx-trial-") as tmp_name:
            tmp = Path(tmp_name)
            carried: Path | None = None
            for i, flight in enumerate(trial.flights):
                summary = _fly_one(trial, i, flight, tmp, artefacts, carried, recordings)
                record["flights"].append({k: summary.get(k) for k in KEPT})
                carried = tmp / f"adapted_{i}.npz"
        record["metrics"] = {k: record["flights"][-1].get(k) for k in MEASURES}
    except Exception as err:  # a trial's failure is a result to report, not a crash
        record["error"] = f"{type(err).__name__}: {err}"
        record["traceback"] = traceback.format_exc(limit=3)
    record["trial_wall_s"] = time.perf_counter() - wall0
    return record


def _fly_one(
    trial: Trial,
    index: int,
    flight: Flight,
    tmp: Path,
    artefacts: dict[str, str],
    carried: Path | None,
    recordings: Path | None,
) -> dict[str, Any]:
    mission, start = make_mission(flight.mission, trial.seed)
    mission_path = tmp / f"mission_{index}.yaml"
    mission_path.write_text(yaml.safe_dump(mission))
    network = flight.network
    if flight.carry_network:
        network = str(carried)
    elif network == MULTI_NETWORK:
        network = artefacts[MULTI_NETWORK]
    options: list[str] = []
    if flight.online:
        options += [ONLINE_OPTION, flight.online]
        options += [SAVE_NETWORK_OPTION, str(tmp / f"adapted_{index}.npz")]
    record_path = None
    if recordings is not None:
        recordings.mkdir(parents=True, exist_ok=True)
        record_path = recordings / f"{trial.id.replace('/', '_')}_{index}.rrd"
    summary = fly(
        mission_path,
        _world_file(flight, tmp),
        flight.model,
        rho=flight.rho_model,
        start=start,
        network=network if flight.model == "neural" else None,
        via_gcs=False,
        autopilot_options=options,
        record=record_path if record_path is not None else False,
        link_retries=LINK_RETRIES,
    )
    if not summary.get("landed"):
        raise RuntimeError(f"flight {index} did not land: {summary.get('ended')}")
    return summary
