"""`groundfx fly`: a simulator process and an autopilot process fly a mission in lockstep."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from autopilot.commander.mission_items import Home
from autopilot.metrics import FAR_FROM_GROUND_M
from autopilot.request import NO_PARAMS_FILE, FlightRequest
from autopilot.simlink import LOST
from mission.gcs_client import GroundStation, GroundStationError, VehicleEnded
from mission.plans.formats import load_mission_file
from mission.recordings import default_recording_path, recording_label
from simbridge.config import ConfigError
from simbridge.launch import finish, spawn_local_sim
from simbridge.world import World, load_world, resolve_world_path
from simbridge.zygote import popen


def default_rho(world_name: str) -> float:
    """The analytic model's rho when none is given: the world's true rho_sim (the expert)."""
    ge = load_world(world_name).effects.ground_effect
    return ge.rho if ge is not None else 1.0


def request_command(request: FlightRequest) -> list[str]:
    """The command line of an autopilot process flying `request`."""
    return [sys.executable, "-m", "mission.cli", "autopilot", *request.argv()]


def local_request(sim: int | str, options: Sequence[str] = ()) -> FlightRequest:
    """A request to a local simulator (a TCP port on this machine or a URL), starting from
    default parameters, with `options` as `groundfx autopilot` takes them."""
    url = f"tcp:127.0.0.1:{sim}" if isinstance(sim, int) else sim
    base = FlightRequest(sim=url, params_file=Path(NO_PARAMS_FILE))
    return base.with_options(options)


def autopilot_command(sim: int | str, mission_path: Path, *options: str) -> list[str]:
    """The command line of an autopilot process flying `mission_path` against a local sim on
    its own, with no ground station (reproducible: arming and take-off at fixed sim times)."""
    request = local_request(sim, options)
    return request_command(
        dataclasses.replace(request, mission=mission_path, auto_start=True, no_gcs=True)
    )


def gcs_autopilot_command(sim: int | str, gcs_port: int, *options: str) -> list[str]:
    """An autopilot process that waits for a ground station on udpout:127.0.0.1:`gcs_port`."""
    request = local_request(sim, options)
    out = (f"udpout:127.0.0.1:{gcs_port}", *request.out)
    return request_command(dataclasses.replace(request, out=out, exit_after_landing=True))


def _flight_request(
    mission_path: Path,
    world: str,
    world_obj: World,
    model: str,
    via_gcs: bool,
    record: bool | Path,
    autopilot_options: Sequence[str],
    asked: dict[str, Any],
) -> FlightRequest:
    """What `fly` asks of its autopilot process: the world's origin and vehicle, the model
    (rho by default the world's), the recording, and what the caller asked."""
    o = world_obj.origin
    given = {name: value for name, value in asked.items() if value is not None}
    request = FlightRequest(**given).with_options(autopilot_options)
    rho = default_rho(world) if request.rho is None else request.rho
    origin = f"{o.lat_deg},{o.lon_deg},{o.alt_m}"
    request = dataclasses.replace(
        request, model=model, rho=rho, json=True, origin=origin, params_file=Path(NO_PARAMS_FILE)
    )
    if "--vehicle" not in autopilot_options and "vehicle" not in asked:
        # the simulator's vehicle: with the nano's mass, C_T and rotor speeds a Crazyflie's
        # world never finished its mission
        request = dataclasses.replace(request, vehicle=world_obj.vehicle)
    if record is False:
        request = dataclasses.replace(request, no_record=True)
    else:
        label = recording_label(model, request.online)
        path = default_recording_path(mission_path, label) if record is True else record
        request = dataclasses.replace(
            request,
            record=Path(path),
            record_world=str(resolve_world_path(world)),
            record_mission=str(mission_path),
        )
    if via_gcs:
        return dataclasses.replace(request, exit_after_landing=True)
    return dataclasses.replace(request, mission=mission_path, auto_start=True, no_gcs=True)


LINK_RETRIES = 1  # a lost simulator link is flown again once
# what `groundfx autopilot` imports before its first step, for a zygote to import once
AUTOPILOT_IMPORTS = (
    "mission.cli",
    "mission.cli.main",
    "mission.cli.autopilot",
    "autopilot.request",
    "autopilot.runner",
)


def fly(
    mission_path: Path,
    world: str = "default",
    model: str = "analytic",
    *,
    via_gcs: bool = True,
    speedup: str = "max",
    start: str | None = None,
    record: bool | Path = True,
    say: Callable[[str], None] = lambda text: None,
    sim_options: Sequence[str] = (),
    autopilot_options: Sequence[str] = (),
    link_retries: int = LINK_RETRIES,
    **asked: Any,
) -> dict[str, Any]:
    """Fly; returns the autopilot's summary with the simulator's last line.

    `asked`: fields of the autopilot's `FlightRequest` (rho, network, trajectory,
    flight_log, max_flight_s, identity, param, online, ...); `autopilot_options`: the same
    as `groundfx autopilot` options, set over them. `via_gcs`: a ground station on pymavlink
    uploads the mission, arms, starts it and waits for the disarm, as a user's would.
    Otherwise the autopilot loads the mission and arms by itself at a fixed simulated time,
    so that the same flight gives the same trajectory. `record`: True records to a new file
    in the logs folder, a path records there, False not at all. A flight whose simulator
    link was lost (its process gone, or silent past the link timeout) is flown again up to
    `link_retries` times: a loaded machine must not end a campaign, and lockstep makes the
    retry the same flight.
    """
    # refuse a bad world, request or mission before starting anything
    world_obj = load_world(world)
    request = _flight_request(
        mission_path, world, world_obj, model, via_gcs, record, autopilot_options, asked
    )
    o = world_obj.origin
    doc = load_mission_file(mission_path, Home(o.lat_deg, o.lon_deg, o.alt_m))
    for attempt in range(link_retries + 1):
        summary = _fly_once(request, doc, world, via_gcs, speedup, start, sim_options, say)
        ended = str(summary.get("ended", ""))
        if not ended.startswith(LOST) or attempt == link_retries:
            return summary
        say(f"{ended}: flying it again")
    raise AssertionError("unreachable")


def _fly_once(
    request: FlightRequest,
    doc: Any,
    world: str,
    via_gcs: bool,
    speedup: str,
    start: str | None,
    sim_options: Sequence[str],
    say: Callable[[str], None],
) -> dict[str, Any]:
    """One flight: the simulator, the autopilot, and the ground station when `via_gcs`."""
    wall0 = time.perf_counter()
    station = GroundStation("udpin:127.0.0.1:0") if via_gcs else None
    # both ends are ours: a Unix-domain socket, and the two processes start side by side
    socket_dir = tempfile.TemporaryDirectory(prefix="groundfx-")
    socket_path = Path(socket_dir.name) / "sim.sock"
    request = dataclasses.replace(request, sim=f"unix:{socket_path}")
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
            process = _start(request_command(request), sim)
            try:
                out, err = process.communicate(timeout=1800)
            finally:
                if process.poll() is None:
                    process.kill()
                    process.communicate()
            code = process.returncode
        else:
            gcs_port = station.conn.port.getsockname()[1]
            station.on_text = lambda text: say(f"vehicle: {text}")
            out = (f"udpout:127.0.0.1:{gcs_port}", *request.out)
            request = dataclasses.replace(request, out=out)
            process = _start(request_command(request), sim)
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
    if sim.returncode != 0 and not lines:  # the simulator failed first: its reason
        raise ConfigError(f"the flight ended: {sim_line}")
    if code == 2 or not lines:
        raise ConfigError(
            err.strip().splitlines()[-1] if err.strip() else "the autopilot printed nothing"
        )
    summary = json.loads(lines[-1])
    summary.update(
        world=str(resolve_world_path(world)),
        rho=request.rho,
        simulator=sim_line,
        total_wall_s=time.perf_counter() - wall0,
        ground_station=gcs,
    )
    return summary


def _start(command: list[str], sim: subprocess.Popen[str]) -> subprocess.Popen[str]:
    """The autopilot process, watched beside its simulator: a simulator that fails while the
    autopilot runs ends the flight at once (one that failed before the autopilot connected
    would leave it retrying its connection; one that died mid-flight closed its socket,
    which the autopilot sees itself)."""
    process = popen(
        command, AUTOPILOT_IMPORTS, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )

    def watch() -> None:
        if sim.wait() != 0 and process.poll() is None:
            process.terminate()

    threading.Thread(target=watch, name="simulator watch", daemon=True).start()
    return process


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
    # each loss is on its own batch (a batch nearer the ground has more to explain): the two
    # are not a trend of one quantity
    loss = (
        ""
        if first is None or last is None
        else f"; loss on the first batch {first:.3g}, on the last {last:.3g}"
    )
    reasons = summary.get("online_reject_reasons") or {}
    why = ", ".join(f"{k} {v}" for k, v in reasons.items())
    held = summary.get("online_held")
    evidence = summary.get("online_held_evidence")
    over = (evidence or {}).get("over_threshold") or 0
    over_text = (
        f"; {over} over it, held while the estimate converged or for a change too small"
        if over
        else ""
    )
    held_text = (
        f"{held} held (likelihood ratio median {evidence['median']:.3g}, largest "
        f"{evidence['max']:.4g}, against the threshold {evidence['threshold']:g}{over_text}), "
        if held and evidence
        else (f"{held} held (evidence under the confidence threshold), " if held else "")
    )
    return [
        f"  online learning ({method}, {summary.get('online_mode')}): "
        f"{summary.get('online_samples', 0)} samples, {summary.get('online_updates', 0)} "
        f"updates, {summary.get('online_accepted', 0)} accepted, "
        f"{summary.get('online_rejected', 0)} rejected{f' ({why})' if why else ''}, "
        f"{held_text}weights version {summary.get('online_version', 0)}{loss}",
        *_ground_lines(summary),
        *_why_model_error(summary),
        *[f"  online learning: {e}" for e in summary.get("online_errors") or []],
    ]


def _ground_lines(summary: dict[str, Any]) -> list[str]:
    """composite: the ground in use at the end, each ground created or recalled and when,
    against the moment the vehicle first came near the surface."""
    if summary.get("online_method") != "composite":
        return []
    near = summary.get("online_near_surface_s")
    events = []
    for e in summary.get("online_ground_events") or []:
        after = f" ({e['t_s'] - near:+.1f} s from coming down near the surface)" if near else ""
        into = f" into {e['into']}" if e.get("into") else ""
        events.append(f"{e['ground']} {e['event']}{into} at {e['t_s']:.1f} s{after}")
    known = ", ".join(summary.get("online_grounds") or [])
    return [
        f"  grounds: {summary.get('online_ground')} in use at the end (known: {known}); "
        + ("; ".join(events) if events else "none created or recalled")
    ]


# over the hold, a model error beyond this share of the true force is explained in a line
MODEL_ERROR_SHARE = 0.10


def _why_model_error(summary: dict[str, Any]) -> list[str]:
    """composite: why its model was more than MODEL_ERROR_SHARE off over the hold, where it
    was: when its ground came in against when the hold ran."""
    error, true = summary.get("ge_z_hold_rms_error_n"), summary.get("ge_z_hold_true_n")
    start, end = summary.get("ge_hold_from_s"), summary.get("ge_hold_to_s")
    if summary.get("online_method") != "composite" or None in (error, true, start, end):
        return []
    if error <= MODEL_ERROR_SHARE * abs(true):
        return []
    share = f"{error / abs(true) * 100:.0f}% of the true force over the hold"
    came = [e for e in summary.get("online_ground_events") or [] if e["t_s"] <= end]
    held = f"the hold ran {start:.1f} to {end:.1f} s"
    if not came:
        ground = summary.get("online_ground")
        return [f"  model error: {share}: no ground learnt or recalled by then ({held}): {ground}"]
    last = came[-1]
    if last["t_s"] <= start:
        since = f"{last['ground']} in use from {last['t_s']:.1f} s"
        return [f"  model error: {share}, {since} ({held})"]
    return [
        f"  model error: {share}: {last['ground']} came in at {last['t_s']:.1f} s, "
        f"{last['t_s'] - start:.1f} s into the hold ({held}); until then the hold was flown on "
        "the ground in use before it"
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
            f"  ground-effect model error   {fmt('ge_z_hold_rms_error_n', 'mN', 1000, 2)} RMS "
            f"over the hold (true force {fmt('ge_z_hold_true_n', 'mN', 1000, 1)}), "
            f"{fmt('ge_z_far_rms_error_n', 'mN', 1000, 2)} at {FAR_FROM_GROUND_M:g} m and higher",
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
            *([f"  report: {summary['report']}"] if summary.get("report") else []),
            *([f"  {summary['report_error']}"] if summary.get("report_error") else []),
        ]
    )
