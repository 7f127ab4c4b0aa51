"""`groundfx fly`: a simulator process and an autopilot process fly a mission in lockstep."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from autopilot.commander.mission_items import Home
from mission.gcs_client import GroundStation, GroundStationError, VehicleEnded
from mission.plans.formats import load_mission_file
from mission.recordings import default_recording_path
from simbridge.config import ConfigError
from simbridge.launch import finish, spawn_local_sim, vehicle_options
from simbridge.world import load_world, resolve_world_path


def default_rho(world_name: str) -> float:
    """The analytic model's rho when none is given: the world's true rho_sim (the expert)."""
    ge = load_world(world_name).effects.ground_effect
    return ge.rho if ge is not None else 1.0


def _autopilot(sim: int | str, *options: str) -> list[str]:
    """An autopilot process against a local simulator (a TCP port on this machine or a URL),
    starting from default parameters."""
    url = f"tcp:127.0.0.1:{sim}" if isinstance(sim, int) else sim
    return [
        *(sys.executable, "-m", "mission.cli", "autopilot"),
        *("--sim", url, "--params-file", "none"),
        *options,
    ]


def autopilot_command(sim: int | str, mission_path: Path, *options: str) -> list[str]:
    """The command line of an autopilot process flying `mission_path` against a local sim on
    its own, with no ground station (reproducible: arming and take-off at fixed sim times)."""
    return _autopilot(sim, "--mission", str(mission_path), "--auto-start", "--no-gcs", *options)


def gcs_autopilot_command(sim: int | str, gcs_port: int, *options: str) -> list[str]:
    """An autopilot process that waits for a ground station on udpout:127.0.0.1:`gcs_port`."""
    return _autopilot(
        sim, "--out", f"udpout:127.0.0.1:{gcs_port}", "--exit-after-landing", *options
    )


def fly(
    mission_path: Path,
    world: str = "default",
    model: str = "analytic",
    rho: float | None = None,
    speedup: str = "max",
    start: str | None = None,
    trajectory: Path | None = None,
    network: str | Path | None = None,
    via_gcs: bool = True,
    identity: str = "px4",
    say: Callable[[str], None] = lambda text: None,
    flight_log: Path | None = None,
    record: bool | Path = True,
    max_flight_s: float | None = None,
    autopilot_options: Sequence[str] = (),
    sim_options: Sequence[str] = (),
) -> dict[str, Any]:
    """Fly; returns the autopilot's summary with the simulator's last line.

    `via_gcs`: a ground station on pymavlink uploads the mission, arms, starts it and waits
    for the disarm, as a user's would. Otherwise the autopilot loads the mission and arms by
    itself at a fixed simulated time, so that the same flight gives the same trajectory.
    `record`: True records to a new file in the logs folder, a path records there, False not
    at all.
    """
    world_obj = load_world(world)  # refuse a bad world or mission before starting anything
    o = world_obj.origin
    doc = load_mission_file(mission_path, Home(o.lat_deg, o.lon_deg, o.alt_m))
    rho = default_rho(world) if rho is None else rho
    options = ["--model", model, "--rho", str(rho), "--json", "--identity", identity]
    options += ["--origin", f"{o.lat_deg},{o.lon_deg},{o.alt_m}"]
    if trajectory is not None:
        options += ["--trajectory", str(trajectory)]
    if network is not None:
        options += ["--network", str(network)]
    if flight_log is not None:
        options += ["--flight-log", str(flight_log)]
    if max_flight_s is not None:
        options += ["--max-flight-s", str(max_flight_s)]
    if record is False:
        options += ["--no-record"]
    else:
        path = default_recording_path(mission_path, model) if record is True else record
        options += ["--record", str(path), "--record-world", str(resolve_world_path(world))]
        options += ["--record-mission", str(mission_path)]
    options += vehicle_options(world_obj.vehicle, autopilot_options)
    options += autopilot_options  # e.g. the experiments' --online METHOD
    wall0 = time.perf_counter()
    station = GroundStation("udpin:127.0.0.1:0") if via_gcs else None
    # both ends are ours: a Unix-domain socket, and the two processes start side by side
    socket_dir = tempfile.TemporaryDirectory(prefix="groundfx-")
    socket_path = Path(socket_dir.name) / "sim.sock"
    sim_url = f"unix:{socket_path}"
    sim = spawn_local_sim(
        resolve_world_path(world),
        socket_path,
        speedup=speedup,
        start=start,
        extra=list(sim_options),
    )
    gcs: dict[str, Any] = {}
    try:
        if station is None:
            cmd = autopilot_command(sim_url, mission_path, *options)
            autopilot = subprocess.run(cmd, capture_output=True, text=True, timeout=1800)
            out, err, code = autopilot.stdout, autopilot.stderr, autopilot.returncode
        else:
            gcs_port = station.conn.port.getsockname()[1]
            station.on_text = lambda text: say(f"vehicle: {text}")
            process = subprocess.Popen(
                gcs_autopilot_command(sim_url, gcs_port, *options),
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            try:
                gcs = _fly_with(station, doc, process, say)
                out, err = process.communicate(timeout=120)
            finally:
                if process.poll() is None:
                    process.terminate()
                    out, err = process.communicate(timeout=30)
            code = process.returncode
    finally:
        sim_line = finish(sim)
        socket_dir.cleanup()
        if station is not None:
            station.close()
    lines = out.strip().splitlines()
    if code == 2 or not lines:
        raise ConfigError(
            err.strip().splitlines()[-1] if err.strip() else "the autopilot printed nothing"
        )
    summary = json.loads(lines[-1])
    summary.update(
        world=str(resolve_world_path(world)),
        rho=rho,
        simulator=sim_line,
        total_wall_s=time.perf_counter() - wall0,
        ground_station=gcs,
    )
    return summary


def _fly_with(
    station: GroundStation, doc: Any, process: subprocess.Popen, say: Callable[[str], None]
) -> dict[str, Any]:
    """The ground station's part: connect, stop the streams it does not show, set the
    waypoint timeout, upload, arm, start, follow to the disarm."""
    station.vehicle_alive = lambda: process.poll() is None
    try:
        station.connect(timeout_s=20.0)
        # it shows the mission's progress (heartbeat, items reached, texts), not the state
        station.stop_streams("ATTITUDE", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED")
        if doc.waypoint_timeout_s is not None:
            station.set_param("GFX_WP_TIMEOUT", doc.waypoint_timeout_s)
        say(f"uploading {len(doc.items)} mission items")
        progress = station.fly_mission(doc.items, timeout_s=1800.0)
    except VehicleEnded:
        if process.returncode == 0:  # it landed and ended before its last heartbeat came
            progress = station.progress
        else:
            why = process.stderr.read().strip().splitlines() if process.stderr else []
            raise ConfigError(f"the autopilot ended: {why[-1] if why else 'no message'}") from None
    except GroundStationError as e:
        raise ConfigError(f"ground station: {e}") from None
    return {
        "items": len(doc.items),
        "reached": progress.reached,
        "mission_state": progress.mission_state,
        "disarmed": not progress.armed,
    }


def _declared(summary: dict[str, Any]) -> str:
    """When the land detector declared the touchdown, against the true contact."""
    declared, contact = summary.get("touchdown_declared_s"), summary.get("touchdown_time_s")
    if declared is None:
        return "never"
    if contact is None:
        return f"at {declared:.2f} s"
    return f"{declared - contact:+.2f} s from contact"


def _online_lines(summary: dict[str, Any]) -> list[str]:
    """What the online learner did, when it ran (`--online METHOD`)."""
    method = summary.get("online_method")
    if method is None or method == "off":
        return [f"  online learning: {e}" for e in summary.get("online_errors") or []]
    first, last = summary.get("online_loss_first"), summary.get("online_loss_last")
    loss = "" if first is None or last is None else f"; loss {first:.3g} -> {last:.3g}"
    reasons = summary.get("online_reject_reasons") or {}
    why = ", ".join(f"{k} {v}" for k, v in reasons.items())
    return [
        f"  online learning ({method}, {summary.get('online_mode')}): "
        f"{summary.get('online_samples', 0)} samples, {summary.get('online_updates', 0)} "
        f"updates, {summary.get('online_accepted', 0)} accepted, "
        f"{summary.get('online_rejected', 0)} rejected{f' ({why})' if why else ''}, "
        f"weights version {summary.get('online_version', 0)}{loss}",
        *[f"  online learning: {e}" for e in summary.get("online_errors") or []],
    ]


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
            f"bounce {fmt('bounce_m', 'mm', 1000, 2)}; declared {_declared(summary)}",
            f"  estimator against truth     position {fmt('est_position_rms_m', 'mm', 1000, 2)}"
            f" RMS ({fmt('est_position_max_m', 'mm', 1000, 2)} max), velocity "
            f"{fmt('est_velocity_rms_m_s', 'm/s', 1, 3)}, attitude "
            f"{fmt('est_attitude_rms_deg', 'deg', 1, 2)} RMS; height from "
            f"{summary.get('estimator_height_source', 'n/a')}",
            *[f"  {text}" for text in summary.get("failsafes") or []],
            *_online_lines(summary),
            f"  simulated {fmt('sim_s', 's', 1, 2)} in {fmt('wall_s', 's', 1, 2)} wall: "
            f"{fmt('rtf', 'x real time')}; estimator and controller "
            f"{fmt('estimator_controller_us_p50', 'us')} p50, "
            f"{fmt('estimator_controller_us_p99', 'us')} p99",
            f"  {summary['simulator']}",
            *([f"  recording: {summary['recording']}"] if summary.get("recording") else []),
        ]
    )
