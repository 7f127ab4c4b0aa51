"""`groundfx autopilot`: the autopilot process, PX4 simulator protocol to the simulator and
MAVLink to ground stations."""

from __future__ import annotations

import argparse
import json
import signal
import sys
from pathlib import Path
from typing import Any

from mission.cli.online import add_online_options
from mission.cli.options import DEFAULT_GCS_URLS, gcs_options, max_flight_s, model_options
from mission.recordings import add_record_options
from simbridge.config import ConfigError


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "autopilot",
        help="run the autopilot: PX4 simulator protocol to the sim, MAVLink to ground stations",
    )
    p.add_argument(
        "--sim",
        default="tcp:127.0.0.1:4560",
        help="simulator URL, tcp:HOST:PORT or unix:PATH (default: tcp:127.0.0.1:4560)",
    )
    p.add_argument("--mission", type=Path, help="a mission file to load before any upload")
    p.add_argument(
        "--auto-start",
        action="store_true",
        help="arm and fly --mission at once, without a ground station (reproducible runs)",
    )
    p.add_argument(
        "--exit-after-landing",
        action="store_true",
        help="end (printing the summary) once a flight has landed and disarmed",
    )
    model_options(p, rho_default=None, model_default=None)
    gcs_options(p)
    p.add_argument("--vehicle", default="nano", help="vehicle YAML or packaged name")
    p.add_argument("--origin", metavar="LAT,LON,ALT", help="geodetic origin of the local frame")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.add_argument("--trajectory", type=Path, help="save the flown trajectory (.npz)")
    p.add_argument("--flight-log", type=Path, help="save airborne steps as a gap-diagnosis log")
    p.add_argument(
        "--max-flight-s", type=max_flight_s, default=900.0,
        help="end the flight (exit code 3) after this many simulated seconds (default 900)",
    )  # fmt: skip
    add_online_options(p)
    add_record_options(p, world=True)
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


def _param_overrides(args: argparse.Namespace) -> dict[str, float]:
    out: dict[str, float] = {}
    for text in args.param:
        name, sep, value = text.partition("=")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise ConfigError(f"--param {text!r}: expected NAME=NUMBER") from None
        if not sep:
            raise ConfigError(f"--param {text!r}: expected NAME=NUMBER")
    model = getattr(args, "model", None)
    if model is not None:
        from autopilot.control.ground_models import MODEL_NAMES

        out["GFX_GE_MODEL"] = float(MODEL_NAMES.index(model))
    if getattr(args, "rho", None) is not None:
        out["GFX_GE_RHO"] = args.rho
    from mission.cli.online import online_overrides

    return out | online_overrides(args)


def _flight_log_writer(args: argparse.Namespace) -> Any:
    if args.flight_log is None:
        return None
    from autopilot.recording.flight_log import FlightLogWriter

    mission = str(args.mission.resolve()) if args.mission else None
    return FlightLogWriter(args.flight_log, {"mission": mission, "vehicle": args.vehicle})


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
    import dataclasses

    import numpy as np

    from autopilot.commander.mission_items import Home
    from autopilot.control.ground_models import default_network
    from autopilot.gcs.signing import Signing
    from autopilot.metrics import COLUMNS
    from autopilot.params import ParamStore
    from autopilot.recording.record_options import RecordOptions
    from autopilot.runner import AutopilotConfig, fly_mission
    from autopilot.simlink import LinkLost, parse_url
    from mission.cli.online import online_options
    from mission.plans.formats import load_mission_file
    from mission.recordings import record_path
    from simbridge.vehicle import load_vehicle
    from simbridge.world import load_world

    try:
        parse_url(args.sim)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    if args.auto_start and args.mission is None:
        raise ConfigError("--auto-start: needs --mission")
    vehicle = load_vehicle(args.vehicle)
    if args.origin:
        origin = _origin(args.origin)
    else:
        o = load_world("default").origin
        origin = (o.lat_deg, o.lon_deg, o.alt_m)
    overrides = _param_overrides(args)
    items: tuple = ()
    if args.mission is not None:
        doc = load_mission_file(args.mission, Home(*origin))
        items = doc.items
        if doc.waypoint_timeout_s is not None and "GFX_WP_TIMEOUT" not in overrides:
            overrides["GFX_WP_TIMEOUT"] = doc.waypoint_timeout_s
    params_file = None if str(args.params_file) == "none" else args.params_file
    params = ParamStore(params_file, overrides, args.identity)
    gcs_urls = () if args.no_gcs else tuple(args.out or DEFAULT_GCS_URLS)
    stop = []
    config = AutopilotConfig(
        sim_url=args.sim,
        vehicle=vehicle,
        params=params,
        origin=origin,
        network=args.network,
        mission=items,
        auto_start=args.auto_start,
        exit_after_landing=args.exit_after_landing or args.auto_start,
        identity=args.identity,
        gcs_urls=gcs_urls,
        signing=Signing(args.signing_key_file) if args.signing_key_file else None,
        should_stop=lambda: bool(stop),
        on_step=_flight_log_writer(args),
        max_flight_s=args.max_flight_s,
        online=online_options(args, reproducible=args.auto_start),
    )

    def on_signal(signum: int, frame: object) -> None:
        stop.append(signum)

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    recording = record_path(args, params.model()[0])
    if recording is not None:
        model, rho = params.model()
        network_file = None
        if model == "neural":
            from learner.model import resolve_model_path

            network_file = str(resolve_model_path(args.network or default_network(rho)))
        info = {
            "mission": str(args.mission or args.record_mission or "uploaded by a ground station"),
            "model": model,
            "rho": rho,
            # the network a neural model flies (the packaged one for its rho unless named)
            "network": (args.network or default_network(rho)) if model == "neural" else None,
            "online": args.online or "off",
            "groundfx_version": _version(),
            # the network file flown and its content's hash (a model's version)
            "network_file": network_file,
            "network_sha256": _sha256(network_file),
            "parameters": {k: float(v) for k, v in sorted(params.values.items())},
            "world": args.record_world,
            "sim": args.sim,
            "identity": args.identity,
        }
        world = load_world(args.record_world) if args.record_world else None
        config = dataclasses.replace(config, record=RecordOptions(recording, world, info))
    try:
        flight = fly_mission(config)
    except LinkLost as lost:
        print(f"groundfx autopilot: {lost}", file=sys.stderr)
        return 3
    if args.trajectory:
        args.trajectory.parent.mkdir(parents=True, exist_ok=True)
        np.savez(args.trajectory, log=flight.log, columns=np.array(COLUMNS))
    if config.on_step is not None:
        config.on_step.write()
    summary = dict(
        flight.summary, rho=params.model()[1], recording=str(recording) if recording else None
    )
    if args.json:
        print(json.dumps(summary), flush=True)
    else:
        print(
            f"groundfx autopilot: {flight.ended}; "
            + ", ".join(
                f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in summary.items()
            )
        )
    if not flight.summary["landed"] and flight.ended != "stopped":
        print(f"groundfx autopilot: {flight.ended}", file=sys.stderr)
        return 3
    return 0
