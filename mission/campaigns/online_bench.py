"""`groundfx bench online`: does the learner thread disturb the control loop?

The offline rho1 network flies `low_hover` in its own world (rho 1), in lockstep as fast as
it goes, with the learner off and on (asynchronous: the learner process updates at full
rate, every 64 samples, while the control loop runs). Its own world, so that learning
barely changes the trajectory: in a world it must adapt to, the learning flight flies a
different path (nearer the ground, shorter), and the figures would compare two flights
rather than the learner's cost. Pairs alternate so that load from elsewhere falls on
both; the figures are medians over the pairs, and the ratios the medians of each pair's
ratio (a machine whose speed drifts between pairs moves both flights of a pair alike).
Targets: p99 controller step latency at most 20 % higher, real-time factor at least 80 %
of learner-off. How far the learner-off flights' own p99 spread (largest over smallest)
says what a ratio can tell on this machine. The hold lasts `hold_s` (40 s, where the
mission holds 6): the learner works through most of the flight, and each p99 is taken over
10000 control steps rather than 1500. `composite` flies the basis model (`grounds`), off and
on alike.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from learner.online.names import NEEDS_BASIS
from mission import EXAMPLES_DIR
from mission.fly import fly

BENCH_MISSION = EXAMPLES_DIR / "low_hover.yaml"


DEFAULT_HOLD_S = 40.0


def bench_mission(directory: Path, hold_s: float) -> Path:
    """`low_hover` with its 3 cm hold lasting `hold_s`."""
    mission = yaml.safe_load(BENCH_MISSION.read_text())
    mission["waypoints"][-1]["hold_s"] = hold_s
    path = directory / "bench_hover.yaml"
    path.write_text(yaml.safe_dump(mission, sort_keys=False))
    return path


def bench_online(
    method: str = "naive", repeat: int = 5, world: str = "default", hold_s: float = DEFAULT_HOLD_S
) -> dict[str, Any]:
    runs: dict[str, list[dict[str, Any]]] = {"off": [], "on": []}
    network = "grounds" if method in NEEDS_BASIS else "rho1"
    with tempfile.TemporaryDirectory(prefix="groundfx-bench-") as tmp:
        mission = bench_mission(Path(tmp), hold_s)
        for _ in range(repeat):
            for kind in ("off", "on"):
                extra = () if kind == "off" else ("--online", method, "--online-async")
                runs[kind].append(
                    fly(
                        mission,
                        world,
                        "neural",
                        network=network,
                        via_gcs=False,
                        record=False,
                        autopilot_options=extra,
                    )
                )

    def median(kind: str, key: str) -> float:
        return float(np.median([r[key] for r in runs[kind]]))

    out: dict[str, Any] = {
        "mission": str(BENCH_MISSION),
        "hold_s": hold_s,
        "world": world,
        "method": method,
        "network": network,
        "pairs": repeat,
    }
    for kind in ("off", "on"):
        for key in ("controller_us_p50", "controller_us_p99", "rtf", "sim_s"):
            out[f"{key}_{kind}"] = median(kind, key)

    def paired_ratio(key: str) -> float:
        pairs = zip(runs["on"], runs["off"], strict=True)
        return float(np.median([on[key] / off[key] for on, off in pairs]))

    out["p99_ratio"] = paired_ratio("controller_us_p99")
    out["rtf_ratio"] = paired_ratio("rtf")
    reference = [r["controller_us_p99"] for r in runs["off"]]
    out["controller_us_p99_off_spread"] = max(reference) / min(reference)
    on = runs["on"]
    out["online_updates"] = [r.get("online_updates") for r in on]
    out["online_dropped"] = [r.get("online_dropped") for r in on]
    out["online_version"] = [r.get("online_version") for r in on]
    out["meets_p99_target"] = out["p99_ratio"] <= 1.2
    out["meets_rtf_target"] = out["rtf_ratio"] >= 0.8
    return out
