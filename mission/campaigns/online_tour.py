"""`groundfx learn tour`: composite's memory of grounds across flights, measured in flight.

A tour is a chain of seeded landing flights over a sequence of grounds (by default rho 1,
rho 2, the `obstacles` world's box, rho 1, rho 2), each flight starting from the model the one
before saved. Per flight it reports what a user of the memory would ask: which grounds were
created and recalled, how long after the vehicle first came down near the surface the first
recall came, how many changes were published, the hold error and the model error over the
hold. Per tour: grounds created against distinct grounds flown; on every return to a ground
seen before, the recall's delay, the changes against the first visit's and the hold error
against the first visit's.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from mission.campaigns.experiments.missions import obstacle_landing
from mission.campaigns.online_eval import CONTROLLERS, flight_summary, world_file
from mission.campaigns.trials import landing_trial
from simbridge.config import ConfigError
from simbridge.world import resolve_world_path

DEFAULT_TOUR = ("rho1", "rho2", "box", "rho1", "rho2")
HOLD_S = 10.0  # the landing trial's hold 3 cm up, as the online evaluation's


def parse_grounds(text: str) -> tuple[str, ...]:
    """`rho1,rho2,box,...`: rhoX a flat ground of rho_sim X, box the obstacles world's box."""
    grounds = tuple(g.strip() for g in text.split(",") if g.strip())
    for g in grounds:
        if g == "box":
            continue
        try:
            rho = float(g.removeprefix("rho")) if g.startswith("rho") else -1.0
        except ValueError:
            rho = -1.0
        if not 0.1 <= rho <= 10.0:
            raise ConfigError(
                f"--grounds: {g!r} is not a ground: rhoX with X from 0.1 to 10, or box"
            )
    if len(grounds) < 2:
        raise ConfigError("--grounds: a tour needs at least two grounds")
    return grounds


def leg(directory: Path, seed: int, ground: str) -> tuple[Path, str, Path, float]:
    """(mission, start, world, rho) of one flight of the tour."""
    if ground == "box":
        mission, start = obstacle_landing("box", seed)
        world, rho = resolve_world_path("obstacles"), 1.0
    else:
        rho = float(ground.removeprefix("rho"))
        mission, start = landing_trial(seed)
        world = world_file(directory, rho)
    mission["waypoints"][-1]["hold_s"] = HOLD_S
    path = directory / f"{ground}_{seed}.yaml"
    path.write_text(yaml.safe_dump(mission))
    return path, start, world, rho


def fly_tour(
    seed: int, grounds: Sequence[str], directory: Path, basis: str, control: tuple[str, ...]
) -> list[dict[str, Any]]:
    """One tour (a task of the campaign runner): each flight's summary, in order."""
    directory.mkdir(parents=True, exist_ok=True)
    model, summaries = basis, []
    for i, ground in enumerate(grounds):
        mission, start, world, rho = leg(directory, seed, ground)
        saved = directory / f"tour{seed}_leg{i}.npz"
        online = ("--online", "composite", "--save-model", str(saved))
        summary = flight_summary(mission, start, world, "neural", rho, model, *online, *control)
        summaries.append({"ground": ground, **summary})
        model = str(saved)
    return summaries


def tour_task(
    seed: int, grounds: tuple[str, ...], directory: str, basis: str, control: tuple[str, ...]
) -> dict[str, Any]:
    return {"legs": [leg_figures(s) for s in fly_tour(seed, grounds, Path(directory), basis,
                                                       control)]}  # fmt: skip


def leg_figures(summary: dict[str, Any]) -> dict[str, Any]:
    """What one flight did with its memory, from its summary."""
    events = summary.get("online_ground_events") or []
    near = summary.get("online_near_surface_s")
    recalls = [e for e in events if e["event"] == "recalled"]
    merged = {e["ground"] for e in events if e["event"] == "merged"}
    hold = summary.get("hold_z_rms_error_m")
    model = summary.get("ge_z_hold_rms_error_n")
    return {
        "ground": summary["ground"],
        "landed": bool(summary.get("landed")),
        # a ground created and then merged into a stored one is not kept
        "created": [
            e["ground"] for e in events if e["event"] == "created" and e["ground"] not in merged
        ],
        "merged": sorted(merged),
        "recalled": [e["ground"] for e in recalls],
        # how long after first coming down near the surface the first recall came
        "recall_after_s": (recalls[0]["t_s"] - near) if recalls and near is not None else None,
        "published": int(summary.get("online_adapted", 0)),
        "ground_at_end": summary.get("online_ground"),
        "hold_rms_mm": hold * 1000 if hold is not None else None,
        "model_error_mn": model * 1000 if model is not None else None,
        "true_force_mn": (summary.get("ge_z_hold_true_n") or 0.0) * 1000,
    }


def tour_verdicts(legs: list[dict[str, Any]]) -> dict[str, Any]:
    """One tour's figures: grounds created per distinct ground flown, and each return to a
    ground seen before against its first visit."""
    distinct = list(dict.fromkeys(leg["ground"] for leg in legs))
    created = sum(len(leg["created"]) for leg in legs)
    first: dict[str, dict[str, Any]] = {}
    returns = []
    for leg_ in legs:
        ground = leg_["ground"]
        if ground not in first:
            first[ground] = leg_
            continue
        before = first[ground]
        returns.append(
            {
                "ground": ground,
                "recall_after_s": leg_["recall_after_s"],
                "published": leg_["published"],
                "published_first_visit": before["published"],
                "hold_rms_mm": leg_["hold_rms_mm"],
                "hold_rms_mm_first_visit": before["hold_rms_mm"],
            }
        )
    return {"distinct_grounds": len(distinct), "grounds_created": created, "returns": returns}


def run_tour(
    trials: int,
    first_seed: int,
    grounds: tuple[str, ...],
    out: Path,
    basis: str = "grounds",
    controller: str = "default",
    params: Sequence[str] = (),
    workers: int | None = None,
    say: Callable[[str], None] = print,
) -> dict[str, Any]:
    """`trials` seeded tours side by side; their figures to `out`/tour.json and the terminal."""
    from mission.campaigns.runner import Task, run_tasks

    control = tuple(a for p in (*CONTROLLERS[controller], *params) for a in ("--param", p))
    out.mkdir(parents=True, exist_ok=True)
    seeds = list(range(first_seed, first_seed + trials))
    key = json.dumps([grounds, basis, control])
    tasks = [Task(f"tour{s}", key, tour_task, (s, grounds, str(out / "flights"), basis, control),
                  (out / "flights",)) for s in seeds]  # fmt: skip
    records = run_tasks(tasks, out / "tours.jsonl", workers, None, True, desc="tours")
    failed = [records[t.id] for t in tasks if "error" in records[t.id]]
    if failed:
        raise RuntimeError(f"a tour failed: {failed[0]['error']}")
    tours = [records[t.id]["legs"] for t in tasks]
    result = {
        "grounds": list(grounds),
        "seeds": seeds,
        "controller": controller,
        "tours": [
            {"seed": s, "legs": legs, **tour_verdicts(legs)}
            for s, legs in zip(seeds, tours, strict=True)
        ],
    }
    (out / "tour.json").write_text(json.dumps(result, indent=2) + "\n")
    for line in describe_tours(result):
        say(line)
    return result


def _mean(values: list[float | None]) -> str:
    known = [v for v in values if v is not None]
    return f"{np.mean(known):.2f}" if known else "-"


def describe_tours(result: dict[str, Any]) -> list[str]:
    """The terminal's table: each position of the tour over the seeds, then the memory's
    figures."""
    tours = result["tours"]
    lines = [
        f"{len(tours)} tours of {', '.join(result['grounds'])} (composite, controller "
        f"{result['controller']}); means over the tours:",
        f"{'#':>2} {'ground':8} {'created':>8} {'recalled':>9} {'recall after':>13} "
        f"{'published':>10} {'hold rms':>9} {'model error':>12} {'true force':>11}",
    ]
    for i, ground in enumerate(result["grounds"]):
        legs = [t["legs"][i] for t in tours]
        lines.append(
            f"{i + 1:>2} {ground:8} {_mean([len(x['created']) for x in legs]):>8} "
            f"{_mean([len(x['recalled']) for x in legs]):>9} "
            f"{_mean([x['recall_after_s'] for x in legs]):>11} s "
            f"{_mean([x['published'] for x in legs]):>10} "
            f"{_mean([x['hold_rms_mm'] for x in legs]):>6} mm "
            f"{_mean([x['model_error_mn'] for x in legs]):>9} mN "
            f"{_mean([x['true_force_mn'] for x in legs]):>8} mN"
        )
    created = [t["grounds_created"] for t in tours]
    distinct = tours[0]["distinct_grounds"] if tours else 0
    lines.append(
        f"grounds created per tour: {', '.join(map(str, created))} "
        f"({distinct} distinct grounds flown, one of them the home ground)"
    )
    for r in (r for t in tours for r in t["returns"]):
        delay = r["recall_after_s"]
        recall = "nothing recalled"
        if delay is not None:
            recall = f"recalled {delay:.2f} s after reaching the surface"
        lines.append(
            f"back at {r['ground']}: {recall}, {r['published']} changes published (first "
            f"visit {r['published_first_visit']}), hold {_fmt(r['hold_rms_mm'])} mm (first "
            f"visit {_fmt(r['hold_rms_mm_first_visit'])})"
        )
    return lines


def _fmt(value: float | None) -> str:
    return f"{value:.2f}" if value is not None else "-"
