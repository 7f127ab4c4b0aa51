"""The `groundfx` subcommands: each reads its parsed arguments and calls into the packages."""

from __future__ import annotations

import argparse
import json
import signal
import sys
from typing import Any

from autopilot.params import MODEL_NAMES
from simbridge.config import ConfigError

DEFAULT_GCS_URLS = ("udpout:127.0.0.1:14550", "udpin:0.0.0.0:14540")


def _terminate(_signum: int, _frame: object) -> None:
    raise KeyboardInterrupt


def cmd_sim(args: argparse.Namespace) -> int:
    from simbridge.server import LinkEnded, ServerOptions, SimServer
    from simbridge.vehicle import load_vehicle
    from simbridge.world import load_world, parse_start, with_start

    world = load_world(args.world)
    if args.start:
        world = with_start(world, parse_start(args.start))
    vehicle = load_vehicle(world.vehicle)
    server = SimServer(
        world,
        vehicle,
        ServerOptions(
            host=args.host,
            port=args.port,
            speedup=args.speedup,
            timeout_s=args.timeout,
            wait=args.wait,
        ),
    )
    try:
        port = server.listen()
    except OSError as err:
        print(
            f"groundfx sim: cannot listen on {args.host}:{args.port}: {err.strerror}",
            file=sys.stderr,
        )
        return 1
    print(f"groundfx sim: listening on tcp:{args.host}:{port}", flush=True)
    signal.signal(signal.SIGTERM, _terminate)
    try:
        end = server.serve(lambda e: print(f"groundfx sim: {server.summary(str(e))}", flush=True))
    except KeyboardInterrupt:
        end = LinkEnded("stopped by signal")
    print(f"groundfx sim: {server.summary(str(end))}", flush=True)
    return 0 if end.clean else 1


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
        out["GFX_GE_MODEL"] = float(MODEL_NAMES.index(model))
    if getattr(args, "rho", None) is not None:
        out["GFX_GE_RHO"] = args.rho
    from mission.online_cli import online_overrides

    return out | online_overrides(args)


def _flight_log_writer(args: argparse.Namespace) -> Any:
    if args.flight_log is None:
        return None
    from autopilot.flight_log import FlightLogWriter

    mission = str(args.mission.resolve()) if args.mission else None
    return FlightLogWriter(args.flight_log, {"mission": mission, "vehicle": args.vehicle})


def cmd_autopilot(args: argparse.Namespace) -> int:
    import dataclasses

    import numpy as np

    from autopilot.metrics import COLUMNS
    from autopilot.mission_items import Home
    from autopilot.params import ParamStore
    from autopilot.recorder import RecordOptions
    from autopilot.runner import AutopilotConfig, fly_mission
    from autopilot.signing import Signing
    from autopilot.simlink import LinkLost, parse_url
    from mission.formats import load_mission_file
    from mission.online_cli import online_options
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
    params = ParamStore(params_file, overrides)
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
        info = {
            "mission": str(args.mission),
            "model": params.model()[0],
            "rho": params.model()[1],
            "network": args.network,
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


def cmd_fly(args: argparse.Namespace) -> int:
    from mission.fly import describe, fly
    from mission.online_cli import online_overrides, pass_through

    online_overrides(args)  # refuse --online without --model neural before starting anything
    extra = pass_through(args) + [a for p in args.param for a in ("--param", p)]
    speedup = "max" if args.speedup is None else f"{args.speedup:g}"
    summary = fly(
        args.mission,
        args.world,
        args.model,
        args.rho,
        speedup,
        args.start,
        args.trajectory,
        args.network,
        via_gcs=not args.no_gcs,
        identity=args.identity,
        say=print if args.verbose else (lambda text: None),
        autopilot_options=extra,
        record=False if args.no_record else (args.record or True),
    )
    print(json.dumps(summary) if args.json else describe(summary))
    return 0 if summary["landed"] else 1


def cmd_sitl(args: argparse.Namespace) -> int:
    from mission.sitl import parse_location, run_sitl

    location = parse_location(args.location) if args.location else None
    options = ["--identity", args.identity, "--params-file", str(args.params_file)]
    options += ["--vehicle", args.vehicle]
    options += [a for p in args.param for a in ("--param", p)]
    if args.model is not None:
        options += ["--model", args.model]
    if args.rho is not None:
        options += ["--rho", str(args.rho)]
    if args.network is not None:
        options += ["--network", args.network]
    if args.signing_key_file is not None:
        options += ["--signing-key-file", str(args.signing_key_file)]
    gcs_urls = [] if args.no_gcs else list(args.out or DEFAULT_GCS_URLS)
    if args.no_gcs:
        options.append("--no-gcs")
    if args.no_record:
        options.append("--no-record")
    elif args.record is not None:
        options += ["--record", str(args.record)]
    speedup = "max" if args.speedup is None else f"{args.speedup:g}"
    return run_sitl(args.world, speedup, options, gcs_urls, location)


def cmd_learn(args: argparse.Namespace) -> int:
    if args.action == "gather":
        from mission.gather import gather

        if not 0 < args.rho <= 50:
            raise ConfigError(f"--rho: {args.rho:g} is outside the allowed range (0, 50]")
        if args.samples < 1:
            raise ConfigError(f"--samples: {args.samples} must be at least 1")
        print(gather(args.rho, args.samples, args.seed, args.out, args.world))
        return 0
    if args.action == "train":
        from learner.dataset import load_dataset
        from learner.train import TrainConfig, train, write_outputs

        datasets = [load_dataset(p) for p in args.data]
        config = TrainConfig(
            max_epochs=args.max_epochs,
            seed=args.seed,
            layer_bound=args.layer_bound,
            control_gain_bound=args.control_gain_bound,
        )
        result = train(datasets, config, sources=[str(p) for p in args.data])
        paths = write_outputs(result, args.out)
        m = result.metrics
        print(
            f"trained on {m['train_samples']} samples ({m['outliers_dropped']} outliers dropped) "
            f"in {m['wall_s']:.1f} s, {m['epochs']} epochs; validation RMSE f_ge,z "
            f"{m['validation_rmse_n']['fge_z'] * 1000:.2f} mN; Lipschitz bound "
            f"{m['lipschitz_bound']:.2f}; rotor-speed columns {m['control_column_norm']:.4f}"
        )
        for kind, path in paths.items():
            print(f"{kind}: {path}")
        return 0
    if args.action in ("memory", "online-eval"):
        from mission.online_cli import cmd_online_learn

        return cmd_online_learn(args)
    if args.action == "evaluate":
        from mission.trials import evaluate_models

        result = evaluate_models(
            list(range(args.seed, args.seed + args.trials)), args.world, args.network
        )
        if args.json:
            print(json.dumps(result))
        return 0
    from learner.model import load_model
    from learner.plots import plot_prediction
    from simbridge.vehicle import load_vehicle

    rhos = [float(r) for r in args.rho_list.split(",")]
    print(plot_prediction(load_model(args.network), load_vehicle(), rhos, args.out))
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    if args.target == "model":
        from learner.bench import bench_model

        result = bench_model(args.network)
        print(
            json.dumps(result) if args.json else "\n".join(f"{k}: {v}" for k, v in result.items())
        )
        return 0
    if args.target == "online":
        from mission.online_bench import bench_online

        if args.repeat < 1:
            raise ConfigError(f"--repeat: {args.repeat} must be at least 1")
        result = bench_online(args.method, args.repeat)
        print(
            json.dumps(result) if args.json else "\n".join(f"{k}: {v}" for k, v in result.items())
        )
        return 0
    if args.target == "sitl":
        from mission.bench import bench_sitl

        result = bench_sitl(args.world, args.repeat)
        print(
            json.dumps(result) if args.json else "\n".join(f"{k}: {v}" for k, v in result.items())
        )
        return 0
    from simbridge.bench import bench_sim

    result = bench_sim(args.world, args.seconds)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=2) + "\n")
    if args.json:
        print(json.dumps(result))
    else:
        print(
            f"physics:  {result['physics_rtf']:.1f}x real time "
            f"({result['physics_us_per_step']:.1f} us per {result['physics_hz']} Hz step, "
            f"effects: {', '.join(result['effects']) or 'none'})"
        )
        print(
            f"lockstep: {result['lockstep_rtf']:.1f}x real time "
            f"({result['lockstep_us_per_step']:.0f} us per {result['control_hz']} Hz round trip)"
        )
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from simbridge.plots import plot_ground_effect
    from simbridge.vehicle import load_vehicle

    rhos = []
    for part in args.rho.split(","):
        try:
            rho = float(part)
        except ValueError:
            raise ConfigError(
                f"--rho: expected numbers > 0 separated by commas, got {args.rho!r}"
            ) from None
        if not 0 < rho <= 50:
            raise ConfigError(f"--rho: each rho must be in (0, 50], got {part}")
        rhos.append(rho)
    out = plot_ground_effect(load_vehicle(args.vehicle), rhos, args.out)
    print(out)
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    if args.lift:
        from simbridge.demo import run_demo

        run_demo(args.world or "default", args.logs)
        return 0
    from mission.demo import run_flight_demo

    return 0 if run_flight_demo(args.world or "rho2", args.logs) else 1
