"""A diagnosis run as the command line and the gap bench make it: read the logs, diagnose
(`learner.gap`), fly each held-out mission again in the nominal and the corrected world,
write every output."""

from __future__ import annotations

import dataclasses
import hashlib
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml
from tqdm import tqdm

from learner.flightlogs.readers import read_log
from learner.flightlogs.tables import load_mapping
from learner.gap.diagnose import STAGES as DIAGNOSE_STAGES
from learner.gap.diagnose import check_candidates, diagnose
from learner.gap.report import corrected_world_yaml, figures, write_outputs
from learner.gap.rollout import shrink, tracking_difference_m
from mission.campaigns.gap_flights import replay_flight, replay_params
from simbridge.config import ConfigError
from simbridge.vehicle import (
    Vehicle,
    load_vehicle,
    resolve_vehicle_path,
    vehicle_fields,
    with_fields,
)
from simbridge.world import World, load_world, resolve_world_path

READING = "reading the logs"
REPLAYING = "replaying the held-out missions (2 flights each)"
WRITING = "writing the report"
BAR = "{desc:<48} {n_fmt}/{total_fmt} stages, {elapsed}"


def run_diagnosis(
    fitting: list[Path],
    held_out: list[Path],
    world: str,
    out: Path,
    folds: int = 3,
    columns: Path | None = None,
    vehicle_name: str | None = None,
    replay: bool = True,
    z_offset_m: float | None = None,
    candidates: list[str] | None = None,
    progress: bool = False,
    mass_kg: float | None = None,
    workers: int | None = None,
    ray_address: str | None = None,
) -> dict[str, Any]:
    """Diagnose, replay held-out missions closed-loop, write every output; the figures.
    The vehicle is `vehicle_name`, else the world's `vehicle:` (the simulator's, nano by
    default); a `vehicle_name` other than the world's is refused. `z_offset_m`: subtracted
    from every log's z (default: found from where each flight rests on the ground);
    `candidates`: the catalogue candidates the search may choose (default: all); `progress`:
    a bar on stderr naming each stage (on a terminal); `mass_kg`: the vehicle's mass over
    its file's (the replays fly the vehicle with it); `workers`, `ray_address`: where the
    replays' flights run (the campaign runner: local processes, by default one per core, or
    Ray tasks)."""
    if folds < 2:
        raise ConfigError(f"--folds: {folds} is outside the allowed range [2, number of logs]")
    try:
        check_candidates(candidates)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    stages = (READING, *DIAGNOSE_STAGES, *((REPLAYING,) if replay else ()), WRITING)
    with tqdm(total=len(stages), unit="stage", disable=None if progress else True,
              file=sys.stderr, bar_format=BAR) as bar:  # fmt: skip

        def on_stage(stage: str) -> None:
            bar.update(stages.index(stage) - bar.n)
            bar.set_description_str(stage)

        result = _run(fitting, held_out, world, out, folds, columns, vehicle_name, replay,
                      z_offset_m, candidates, on_stage, mass_kg,
                      (workers, ray_address))  # fmt: skip
        bar.update(len(stages) - bar.n)
    return result


def _run(
    fitting: list[Path],
    held_out: list[Path],
    world: str,
    out: Path,
    folds: int,
    columns: Path | None,
    vehicle_name: str | None,
    replay: bool,
    z_offset_m: float | None,
    candidates: list[str] | None,
    on_stage: Callable[[str], None],
    mass_kg: float | None,
    replays_on: tuple[int | None, str | None],
) -> dict[str, Any]:
    on_stage(READING)
    mapping = load_mapping(columns)
    world_path = resolve_world_path(world)
    world_obj = load_world(world_path)
    vehicle = resolve_vehicle(world_path, world_obj, vehicle_name)
    if mass_kg is not None:
        vehicle = with_fields(vehicle, "--mass", mass_kg=mass_kg)
    # the vehicle turns logged thrust into rotor speeds (its C_T)
    fit_logs = [read_log(p, mapping, vehicle) for p in fitting]
    hold_logs = [read_log(p, mapping, vehicle) for p in held_out]
    try:
        diagnosis = diagnose(
            fit_logs, hold_logs, world_obj, vehicle, folds, z_offset_m, candidates, on_stage
        )
    except ValueError as err:
        raise ConfigError(str(err)) from None
    out.mkdir(parents=True, exist_ok=True)
    if mass_kg is not None:
        flown_world = world_with_vehicle_file(world_path, vehicle, out)
        diagnosis.notes.append(
            f"the vehicle: {vehicle.name} at {mass_kg:g} kg (--mass), written to "
            f"{flown_world.parent / VEHICLE_FILE}, which {flown_world.name} (the world the "
            "replays fly) and corrected_world.yaml name"
        )
    else:
        flown_world = world_with_vehicle(world_path, vehicle_name, out)
        if flown_world != world_path:
            diagnosis.notes.append(
                f"the world names no vehicle: `vehicle: {vehicle_name}` is added to "
                f"{flown_world.name} (the world the replays fly) and corrected_world.yaml"
            )
    if replay:
        corrected = out / "corrected_world.yaml"
        corrected.write_text(corrected_world_yaml(flown_world.read_text(), diagnosis))
        on_stage(REPLAYING)
        kept = [log for log in hold_logs if log.name in diagnosis.held_out]  # usable ones
        closed_loop = replay_missions(kept, flown_world, corrected, out / "replays", *replays_on)
    else:
        closed_loop = {"status": "skipped", "why": "not asked for (--no-replay)"}
    on_stage(WRITING)
    write_outputs(diagnosis, out, flown_world, closed_loop)
    return figures(diagnosis, closed_loop)


def _world_vehicle_key(world_path: Path) -> str | None:
    data = yaml.safe_load(world_path.read_text())
    return data.get("vehicle") if isinstance(data, dict) else None


def resolve_vehicle(world_path: Path, world: World, vehicle_name: str | None) -> Vehicle:
    """`vehicle_name` if given, else the world's `vehicle:`; both given and different (in any
    parameter but the name): refused, as the diagnosis and the simulator flying the world
    must model one vehicle."""
    if vehicle_name is None:
        return load_vehicle(world.vehicle)
    given = load_vehicle(vehicle_name)
    key = _world_vehicle_key(world_path)
    if key is not None:
        own = load_vehicle(world.vehicle)
        if dataclasses.replace(own, name=given.name) != given:
            raise ConfigError(
                f"--vehicle {vehicle_name} ({given.name}, {given.mass_kg:g} kg) is not the "
                f"world's vehicle: {world_path} has `vehicle: {key}` ({own.name}, "
                f"{own.mass_kg:g} kg); leave out --vehicle to use the world's, or change "
                "the world's `vehicle:` key"
            )
    return given


def world_with_vehicle(world_path: Path, vehicle_name: str | None, out: Path) -> Path:
    """The world the replays fly: the nominal world itself, or, when it names no vehicle and
    --vehicle was given, a copy naming it (the simulator would fly the nano otherwise)."""
    if vehicle_name is None or _world_vehicle_key(world_path) is not None:
        return world_path
    data = yaml.safe_load(world_path.read_text()) or {}
    vehicle_path = resolve_vehicle_path(vehicle_name)
    data["vehicle"] = str(vehicle_path.resolve()) if vehicle_path.exists() else vehicle_name
    path = out / "nominal_world.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


VEHICLE_FILE = "vehicle.yaml"


def world_with_vehicle_file(world_path: Path, vehicle: Vehicle, out: Path) -> Path:
    """A copy of the world whose `vehicle:` is `vehicle`, written beside it in `out` (a vehicle
    changed on the command line, which the simulator must fly too)."""
    vehicle_path = out / VEHICLE_FILE
    vehicle_path.write_text(yaml.safe_dump(vehicle_fields(vehicle), sort_keys=False))
    data = yaml.safe_load(world_path.read_text()) or {}
    data["vehicle"] = str(vehicle_path.resolve())
    path = out / "nominal_world.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


# a replay may fly this many times the logged flight, plus a margin for the take-off and the
# landing a log leaves out, and at least REPLAY_MIN_S, before it is called one that cannot land
REPLAY_TIME_FACTOR, REPLAY_MARGIN_S, REPLAY_MIN_S = 2.0, 10.0, 30.0


def replay_limit_s(log: Any) -> float:
    """How many simulated seconds a replay of `log`'s mission may fly."""
    logged_s = float(log.time_s[-1] - log.time_s[0]) if len(log) else 0.0
    return max(REPLAY_MIN_S, REPLAY_TIME_FACTOR * logged_s + REPLAY_MARGIN_S)


def replay_missions(
    logs: list,
    nominal: Path,
    corrected: Path,
    out: Path,
    workers: int | None = None,
    ray_address: str | None = None,
) -> dict[str, Any]:
    """Fly each held-out log's mission in the nominal and the corrected world (every flight
    a task of the campaign runner, side by side); the RMS tracking difference to the logged
    flight before and after. A flight that fails (the corrected world cannot take off,
    lands nowhere, ...) is reported with its reason and the others go on: the replays are
    one figure of the report, never its end."""
    from mission.campaigns.runner import Task, run_tasks

    if not logs:
        return {"status": "skipped", "why": "no held-out logs to replay"}
    missions = [(log, log.meta.get("mission")) for log in logs]
    if not any(m for _, m in missions):
        return {"status": "skipped", "why": "the logs carry no mission"}
    failed, tasks = [], []
    for log, mission in missions:
        if not mission or not Path(mission).exists():
            why = "its log carries no mission" if not mission else f"mission {mission} not found"
            failed.append({"flight": log.name, "world": "nominal", "reason": why})
            continue
        params = replay_params(log.meta)
        for label, world in (("nominal", nominal), ("corrected", corrected)):
            # keyed by the world's content and the parameters: a rerun reuses only the same
            # replay's flight
            key = hashlib.sha256(world.read_bytes() + repr(params).encode()).hexdigest()[:10]
            name = f"{log.name}-{label}-{key}.csv"
            args = (str(mission), str(world), str(out / name), replay_limit_s(log), params)
            tasks.append(Task(f"{log.name}/{label}", name, replay_flight, args, (out / name,)))
    records = run_tasks(tasks, out / "results.jsonl", workers, ray_address, False, "replay")
    before, after = [], []
    for log, _ in missions:
        flown = [records.get(f"{log.name}/{label}") for label in ("nominal", "corrected")]
        if not all(flown):
            continue
        labelled = zip(("nominal", "corrected"), flown, strict=True)
        errors = [(label, r["error"]) for label, r in labelled if "error" in r]
        if errors:  # the first world that failed, with its reason
            failed.append({"flight": log.name, "world": errors[0][0], "reason": errors[0][1]})
            continue
        nominal_log, corrected_log = (read_log(Path(r["path"])) for r in flown)
        before.append(tracking_difference_m(log, nominal_log))
        after.append(tracking_difference_m(log, corrected_log))
    if not before:
        return {"status": "failed", "failed": failed}
    bm, am = sum(before) / len(before), sum(after) / len(after)
    return {
        "status": "flown", "flights": len(before), "before_m": bm, "after_m": am,
        "shrink": shrink(bm, am), "failed": failed,
    }  # fmt: skip
