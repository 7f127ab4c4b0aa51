"""`groundfx autopilot`: the autopilot process, PX4 simulator protocol to the simulator and
MAVLink to ground stations."""

from __future__ import annotations

import argparse
import json
import signal
import sys
from pathlib import Path
from typing import Any

from autopilot.request import DEFAULT_GCS_URLS, NO_PARAMS_FILE, FlightRequest, add_options
from simbridge.config import ConfigError

READY = "groundfx autopilot: ready to arm:"  # the line `groundfx sitl` waits for


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "autopilot",
        help="run the autopilot: PX4 simulator protocol to the sim, MAVLink to ground stations",
    )
    add_options(p)
    p.set_defaults(func=cmd_autopilot)


def _origin(text: str) -> tuple[float, float, float]:
    try:
        lat, lon, alt = (float(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(f"--origin: expected LAT,LON,ALT, got {text!r}") from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 180 and -500 <= alt <= 9000):
        raise ConfigError(
            f"--origin: lat in [-90, 90], lon in [-180, 180], alt in [-500, 9000] m; got {text!r}"
        )
    return (lat, lon, alt)


def _param_overrides(request: FlightRequest) -> dict[str, float]:
    out: dict[str, float] = {}
    for text in request.param:
        name, sep, value = text.partition("=")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise ConfigError(f"--param {text!r}: expected NAME=NUMBER") from None
        if not sep:
            raise ConfigError(f"--param {text!r}: expected NAME=NUMBER")
    if request.model is not None:
        from autopilot.control.ground_models import MODEL_NAMES

        out["GFX_GE_MODEL"] = float(MODEL_NAMES.index(request.model))
    if request.rho is not None:
        out["GFX_GE_RHO"] = request.rho
    from mission.cli.online import online_overrides

    return out | online_overrides(request)


def _flight_log_writer(request: FlightRequest) -> Any:
    if request.flight_log is None:
        return None
    from autopilot.recording.flight_log import FlightLogWriter

    mission = str(request.mission.resolve()) if request.mission else None
    # in the simulator world's frame: the diagnosis does not look for the ground
    meta = {"mission": mission, "vehicle": request.vehicle, "frame": "world"}
    return FlightLogWriter(request.flight_log, meta)


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("groundfx")
    except PackageNotFoundError:
        return "unknown"


def _sha256(path: str | None) -> str | None:
    import hashlib

    return None if path is None else hashlib.sha256(Path(path).read_bytes()).hexdigest()


def cmd_autopilot(args: argparse.Namespace) -> int:
    return run_autopilot(FlightRequest.from_args(args))


def _config(request: FlightRequest, should_stop: Any) -> Any:
    """The runner's configuration for `request`: vehicle, origin, parameters, mission."""
    from autopilot.commander.mission_items import Home
    from autopilot.flight_config import AutopilotConfig
    from autopilot.gcs.signing import Signing
    from autopilot.params import ParamStore
    from autopilot.simlink import parse_url
    from mission.cli.online import online_options
    from mission.plans.formats import load_mission_file
    from simbridge.vehicle import load_vehicle
    from simbridge.world import load_world

    try:
        parse_url(request.sim)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    if request.auto_start and request.mission is None:
        raise ConfigError("--auto-start: needs --mission")
    vehicle = load_vehicle(request.vehicle)
    if request.origin:
        origin = _origin(request.origin)
    else:
        o = load_world("default").origin
        origin = (o.lat_deg, o.lon_deg, o.alt_m)
    overrides = _param_overrides(request)
    items: tuple = ()
    if request.mission is not None:
        doc = load_mission_file(request.mission, Home(*origin))
        items = doc.items
        if doc.waypoint_timeout_s is not None and "GFX_WP_TIMEOUT" not in overrides:
            overrides["GFX_WP_TIMEOUT"] = doc.waypoint_timeout_s
    params_file = None if str(request.params_file) == NO_PARAMS_FILE else request.params_file
    params = ParamStore(params_file, overrides, request.identity)
    if params.saved:  # never silently: a value set in an earlier run changes this one
        names = ", ".join(sorted(params.saved))
        print(
            f"groundfx autopilot: {len(params.saved)} "
            f"parameter{'s' if len(params.saved) != 1 else ''} from {params_file} "
            f"(set over MAVLink in an earlier run: {names}); "
            f"--params-file {NO_PARAMS_FILE} starts from the defaults",
            file=sys.stderr,
            flush=True,
        )
    gcs_urls = () if request.no_gcs else (request.out or DEFAULT_GCS_URLS)
    signing = request.signing_key_file
    return AutopilotConfig(
        sim_url=request.sim,
        vehicle=vehicle,
        params=params,
        origin=origin,
        network=request.network,
        mission=items,
        auto_start=request.auto_start,
        exit_after_landing=request.exit_after_landing or request.auto_start,
        identity=request.identity,
        gcs_urls=gcs_urls,
        signing=Signing(signing) if signing else None,
        should_stop=should_stop,
        on_ready=lambda text: print(
            f"{READY} {text}", file=sys.stderr if request.json else sys.stdout, flush=True
        ),
        on_step=_flight_log_writer(request),
        max_flight_s=request.max_flight_s,
        link_timeout_s=request.link_timeout_s,
        online=online_options(request, reproducible=request.auto_start),
    )


def _recording(request: FlightRequest, config: Any) -> tuple[Path | None, Any]:
    """The recording file (None: off) and the runner's configuration that records there,
    with what the recording's meta tells of the flight."""
    import dataclasses

    from autopilot.control.ground_models import default_network
    from autopilot.recording.record_options import RecordOptions
    from mission.recordings import record_path, recording_label
    from simbridge.world import load_world

    params = config.params
    recording = record_path(request, recording_label(params.model()[0], request.online))
    if recording is None:
        return None, config
    model, rho = params.model()
    network_file = None
    if model == "neural":
        from learner.model import resolve_model_path

        network_file = str(resolve_model_path(request.network or default_network(rho)))
    info = {
        "mission": str(request.mission or request.record_mission or "uploaded by a ground station"),
        "model": model,
        "rho": rho,
        # the network a neural model flies (the packaged one for its rho unless named)
        "network": (request.network or default_network(rho)) if model == "neural" else None,
        "online": request.online or "off",
        "groundfx_version": _version(),
        # the network file flown and its content's hash (a model's version)
        "network_file": network_file,
        "network_sha256": _sha256(network_file),
        "parameters": {k: float(v) for k, v in sorted(params.values.items())},
        "world": request.record_world,
        "sim": request.sim,
        "identity": request.identity,
    }
    world = load_world(request.record_world) if request.record_world else None
    return recording, dataclasses.replace(config, record=RecordOptions(recording, world, info))


def run_autopilot(request: FlightRequest) -> int:
    """Fly `request` until the flight ends; print the summary. The exit code: 0 landed (or
    stopped by a signal), 3 not (the link lost, the time limit)."""
    import numpy as np

    from autopilot.metrics import COLUMNS
    from autopilot.runner import fly_mission
    from autopilot.simlink import LinkLost

    stop = []
    config = _config(request, lambda: bool(stop))

    def on_signal(signum: int, frame: object) -> None:
        stop.append(signum)

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    recording, config = _recording(request, config)
    try:
        flight = fly_mission(config)
    except LinkLost as lost:
        print(f"groundfx autopilot: {lost}", file=sys.stderr)
        return 3
    if request.trajectory:
        request.trajectory.parent.mkdir(parents=True, exist_ok=True)
        np.savez(request.trajectory, log=flight.log, columns=np.array(COLUMNS))
    if config.on_step is not None:
        config.on_step.write()
    summary = dict(
        flight.summary,
        rho=config.params.model()[1],
        recording=str(recording) if recording else None,
    )
    if request.json:
        print(json.dumps(summary), flush=True)
    else:
        from mission.cli.exit_summary import exit_summary

        print(exit_summary(summary), flush=True)
    if not flight.summary["landed"] and flight.ended != "stopped":
        print(f"groundfx autopilot: {flight.ended}", file=sys.stderr)
        return 3
    return 0
