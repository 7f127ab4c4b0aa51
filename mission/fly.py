"""`groundfx fly`: a simulator process and an autopilot process fly a mission in lockstep."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from mission.missionfile import load_mission
from mission.recordings import default_recording_path
from simbridge.config import ConfigError
from simbridge.launch import finish, start_sim
from simbridge.world import load_world, resolve_world_path


def default_rho(world_name: str) -> float:
    """The analytic model's rho when none is given: the world's true rho_sim (the expert)."""
    ge = load_world(world_name).effects.ground_effect
    return ge.rho if ge is not None else 1.0


def autopilot_command(sim_port: int, mission_path: Path, *options: str) -> list[str]:
    """The command line of an autopilot process flying `mission_path` against a local sim."""
    return [
        sys.executable,
        "-m",
        "mission.cli",
        "autopilot",
        "--sim",
        f"tcp:127.0.0.1:{sim_port}",
        "--mission",
        str(mission_path),
        *options,
    ]


def fly(
    mission_path: Path,
    world: str = "default",
    model: str = "analytic",
    rho: float | None = None,
    speedup: str = "max",
    start: str | None = None,
    trajectory: Path | None = None,
    network: str | Path | None = None,
    record: bool | Path = True,
) -> dict[str, Any]:
    """Fly; returns the autopilot's summary with the simulator's last line. `record`: True
    records to a new file in the logs folder, a path records there, False not at all."""
    world_obj = load_world(world)  # refuse a bad world or mission before starting anything
    load_mission(mission_path)
    rho = default_rho(world) if rho is None else rho
    origin = world_obj.origin
    wall0 = time.perf_counter()
    sim, port = start_sim(resolve_world_path(world), speedup=speedup, start=start)
    cmd = autopilot_command(
        port,
        mission_path,
        "--model",
        model,
        "--rho",
        str(rho),
        "--origin",
        f"{origin.lat_deg},{origin.lon_deg},{origin.alt_m}",
        "--json",
    )
    if trajectory is not None:
        cmd += ["--trajectory", str(trajectory)]
    if network is not None:
        cmd += ["--network", str(network)]
    if record is False:
        cmd += ["--no-record"]
    else:
        path = default_recording_path(mission_path, model) if record is True else record
        cmd += ["--record", str(path), "--record-world", str(resolve_world_path(world))]
    try:
        autopilot = subprocess.run(cmd, capture_output=True, text=True, timeout=1800)
    finally:
        sim_line = finish(sim)
    lines = autopilot.stdout.strip().splitlines()
    if autopilot.returncode == 2 or not lines:
        raise ConfigError(
            autopilot.stderr.strip().splitlines()[-1]
            if autopilot.stderr.strip()
            else "the autopilot printed nothing"
        )
    summary = json.loads(lines[-1])
    summary.update(
        world=str(resolve_world_path(world)),
        rho=rho,
        simulator=sim_line,
        total_wall_s=time.perf_counter() - wall0,
    )
    return summary


def describe(summary: dict[str, Any]) -> str:
    """The summary for people."""

    def fmt(key: str, unit: str, scale: float = 1.0, digits: int = 1) -> str:
        value = summary.get(key)
        return "n/a" if value is None else f"{value * scale:.{digits}f} {unit}"

    return "\n".join(
        [
            f"flight {summary['ended']}: model {summary['model']} (rho {summary['rho']:g}), "
            f"{summary.get('steps', 0)} steps",
            f"  landing position error      {fmt('landing_error_m', 'mm', 1000)}",
            f"  z error holding near ground {fmt('hold_z_rms_error_m', 'mm', 1000, 2)} RMS, "
            f"{fmt('hold_z_max_error_m', 'mm', 1000, 2)} max",
            f"  touchdown vertical speed    {fmt('touchdown_speed_m_s', 'm/s', 1, 3)}, "
            f"bounce {fmt('bounce_m', 'mm', 1000, 2)}",
            f"  simulated {fmt('sim_s', 's', 1, 2)} in {fmt('wall_s', 's', 1, 2)} wall: "
            f"{fmt('rtf', 'x real time')}; controller {fmt('controller_us_p50', 'us')} p50, "
            f"{fmt('controller_us_p99', 'us')} p99",
            f"  {summary['simulator']}",
            *([f"  recording: {summary['recording']}"] if summary.get("recording") else []),
        ]
    )
