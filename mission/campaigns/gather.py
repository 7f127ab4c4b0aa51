"""`groundfx learn gather`: the expert (the analytic model with the true rho) flies the thesis's
random waypoints in a simulator process, recording 100 Hz learning samples."""

from __future__ import annotations

import dataclasses
import hashlib
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from tqdm import tqdm

from autopilot.commander.mission_items import Home, waypoint_items
from autopilot.flight_config import AutopilotConfig, Flight
from autopilot.params import MODEL_NAMES, ParamStore
from autopilot.runner import fly_mission
from autopilot.simlink import LOST
from learner.dataset import COLUMNS, load_dataset, save_dataset
from mission.campaigns.sampling import thesis_waypoints
from simbridge.config import ConfigError
from simbridge.effects.ground import GroundEffectParams
from simbridge.launch import finish, spawn_local_sim
from simbridge.physics import with_effects
from simbridge.vehicle import load_vehicle
from simbridge.world import load_world, resolve_world_path

SAMPLE_HZ = 100.0


def gather(
    rho: float, samples: int, seed: int, out: Path, world: str = "default", progress: bool = True
) -> Path:
    base = load_world(world)
    world_obj = with_effects(base, ground_effect=GroundEffectParams(rho=rho))
    # the simulator reads a file: write the world with rho_sim = rho beside the dataset
    world_path = out.with_suffix(".world.yaml")
    world_path.parent.mkdir(parents=True, exist_ok=True)
    world_path.write_text(world_yaml_with_rho(resolve_world_path(world).read_text(), rho))
    vehicle = load_vehicle(world_obj.vehicle)
    # about one waypoint per 1.5 s of flight: plenty for the samples asked
    o = world_obj.origin
    origin = (o.lat_deg, o.lon_deg, o.alt_m)
    waypoints = thesis_waypoints(seed, samples // 100 + 20)
    mission = waypoint_items(waypoints, 0.3, False, Home(*origin))
    params = ParamStore(
        None,
        {
            "GFX_GE_MODEL": MODEL_NAMES.index("analytic"),
            "GFX_GE_RHO": rho,
            "GFX_WP_TIMEOUT": max(w.timeout_s or 0.0 for w in waypoints),
        },
    )
    bar = tqdm(total=samples, unit="sample", desc=f"gather rho={rho:g}", disable=not progress)
    counted = [0]

    def on_sample(n: int) -> None:
        bar.update(n - counted[0])
        counted[0] = n

    config = AutopilotConfig(
        sim_url="",  # each try's own simulator
        vehicle=vehicle,
        params=params,
        origin=origin,
        mission=mission,
        auto_start=True,
        record_hz=SAMPLE_HZ,
        stop_after_samples=samples,
        on_sample=on_sample,
        max_flight_s=samples / SAMPLE_HZ * 3 + 60,
    )
    try:
        flight = _fly_expert(world_path, config)
        if flight.ended.startswith(LOST):  # a lost link is flown again, as trials are
            bar.reset()
            counted[0] = 0
            flight = _fly_expert(world_path, config)
    finally:
        bar.close()
    if flight.samples is None or len(flight.samples) < samples:
        got = 0 if flight.samples is None else len(flight.samples)
        raise RuntimeError(f"the flight ended ({flight.ended}) after {got} of {samples} samples")
    meta = {
        "rho": rho,
        "seed": seed,
        "samples": len(flight.samples),
        "sample_hz": SAMPLE_HZ,
        "vehicle": dataclasses.asdict(vehicle),
        "world": str(resolve_world_path(world)),
        "expert": f"analytic rho={rho:g}",
    }
    return save_dataset(out, flight.samples, meta)


def gather_flight(rho: float, samples: int, seed: int, out: Path, world: str) -> dict[str, Any]:
    """One flight of a gathering campaign (a task of the campaign runner)."""
    gather(rho, samples, seed, out, world, progress=False)
    return {"path": str(out), "samples": samples, "seed": seed}


def gather_flights(
    rho: float,
    samples: int,
    seed: int,
    out: Path,
    world: str = "default",
    flights: int = 1,
    workers: int | None = None,
    ray_address: str | None = None,
    progress: bool = True,
) -> Path:
    """`samples` over `flights` flights (flight i: seed `seed * 1000 + i`, its share of the
    samples), run by the campaign runner, each kept in OUT.parts/ as it lands (a rerun flies
    only the missing ones); then one dataset at `out`, the flights' rows in order. One
    flight is `gather` itself."""
    if flights == 1:
        return gather(rho, samples, seed, out, world, progress)
    from mission.campaigns.runner import Task, run_tasks, source_fingerprint

    if not 1 <= flights <= samples:
        raise ConfigError(f"--flights: {flights} must be from 1 to the samples asked ({samples})")
    parts = out.with_name(out.stem + ".parts")
    shares = [samples // flights + (i < samples % flights) for i in range(flights)]
    world_text = resolve_world_path(world).read_text()
    source = source_fingerprint()
    tasks = []
    for i, share in enumerate(shares):
        flight_seed = seed * 1000 + i
        key = hashlib.sha256(repr((rho, share, flight_seed, world_text, source)).encode())
        path = parts / f"flight{i}.npz"
        tasks.append(Task(f"flight{i}", key.hexdigest()[:16], gather_flight,
                          (rho, share, flight_seed, path, world), outputs=(path,)))  # fmt: skip
    records = run_tasks(
        tasks, parts / "results.jsonl", workers, ray_address, progress, f"gather rho={rho:g}"
    )
    failed = [r for r in records.values() if "error" in r]
    if failed:
        raise RuntimeError(f"{len(failed)} of {flights} flights failed: {failed[0]['error']}")
    data = [load_dataset(Path(records[t.id]["path"])) for t in tasks]
    rows = np.column_stack([np.concatenate([d.columns[c] for d in data]) for c in COLUMNS])
    meta = {**data[0].meta, "samples": len(rows), "seed": seed, "flights": flights,
            "flight_seeds": [t.args[2] for t in tasks]}  # fmt: skip
    return save_dataset(out, rows, meta)


def _fly_expert(world_path: Path, config: AutopilotConfig) -> Flight:
    """One flight of `config` against a simulator process of its own."""
    with tempfile.TemporaryDirectory(prefix="groundfx-") as socket_dir:
        socket_path = Path(socket_dir) / "sim.sock"
        sim = spawn_local_sim(world_path, socket_path)  # starts beside this process's flight
        try:
            return fly_mission(dataclasses.replace(config, sim_url=f"unix:{socket_path}"))
        finally:
            finish(sim)


def world_yaml_with_rho(world_yaml: str, rho: float) -> str:
    """The world file's text with its ground-effect rho replaced (or a ground effect added)."""
    data = yaml.safe_load(world_yaml)
    effects = [e for e in data.get("effects") or [] if e.get("name") != "ground_effect"]
    data["effects"] = [{"name": "ground_effect", "rho": rho}, *effects]
    return yaml.safe_dump(data)
