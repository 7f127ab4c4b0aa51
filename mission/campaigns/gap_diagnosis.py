"""A diagnosis run as the command line and the gap bench make it: read the logs, diagnose
(`learner.gap`), fly each held-out mission again in the nominal and the corrected world,
write every output."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

from learner.flightlogs.readers import read_log
from learner.flightlogs.tables import load_mapping
from learner.gap.diagnose import diagnose
from learner.gap.report import corrected_world_yaml, figures, write_outputs
from learner.gap.rollout import shrink, tracking_difference_m
from mission.campaigns.gap_flights import fly_log
from simbridge.config import ConfigError
from simbridge.vehicle import load_vehicle
from simbridge.world import load_world, resolve_world_path


def run_diagnosis(
    fitting: list[Path],
    held_out: list[Path],
    world: str,
    out: Path,
    folds: int = 3,
    columns: Path | None = None,
    vehicle_name: str = "nano",
    replay: bool = True,
) -> dict[str, Any]:
    """Diagnose, replay held-out missions closed-loop, write every output; the figures."""
    if folds < 2:
        raise ConfigError(f"--folds: {folds} is outside the allowed range [2, number of logs]")
    mapping = load_mapping(columns)
    world_path = resolve_world_path(world)
    world_obj = load_world(world_path)
    vehicle = load_vehicle(vehicle_name)
    fit_logs = [read_log(p, mapping) for p in fitting]
    hold_logs = [read_log(p, mapping) for p in held_out]
    try:
        diagnosis = diagnose(fit_logs, hold_logs, world_obj, vehicle, folds)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    out.mkdir(parents=True, exist_ok=True)
    closed_loop = None
    if replay:
        corrected = out / "corrected_world.yaml"
        corrected.write_text(corrected_world_yaml(world_path.read_text(), diagnosis))
        closed_loop = replay_missions(hold_logs, world_path, corrected, out / "replays")
    write_outputs(diagnosis, out, world_path, closed_loop)
    return figures(diagnosis, closed_loop)


def replay_missions(logs: list, nominal: Path, corrected: Path, out: Path) -> dict | None:
    """Fly each held-out log's mission in the nominal and the corrected world; the RMS
    tracking difference to the logged flight before and after."""

    before, after = [], []
    for log in logs:
        mission = log.meta.get("mission")
        if not mission or not Path(mission).exists():
            continue
        a = read_log(fly_log(Path(mission), nominal, out / f"{log.name}-{nominal.stem}.csv"))
        # keyed by the corrected world's content: a rerun reuses only the same world's flight
        key = hashlib.sha256(corrected.read_bytes()).hexdigest()[:10]
        b = read_log(fly_log(Path(mission), corrected, out / f"{log.name}-corrected-{key}.csv"))
        before.append(tracking_difference_m(log, a))
        after.append(tracking_difference_m(log, b))
    if not before:
        return None
    bm, am = sum(before) / len(before), sum(after) / len(after)
    return {"flights": len(before), "before_m": bm, "after_m": am, "shrink": shrink(bm, am)}
