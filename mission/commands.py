"""The `groundfx` subcommands: each reads its parsed arguments and calls into the packages."""

from __future__ import annotations

import argparse
import json
import signal
import sys

from simbridge.config import ConfigError


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


def cmd_autopilot(args: argparse.Namespace) -> int:
    import dataclasses

    import numpy as np

    from autopilot.commander import CommanderParams
    from autopilot.ground_models import make_model
    from autopilot.metrics import COLUMNS
    from autopilot.recorder import RecordOptions
    from autopilot.runner import AutopilotConfig, fly_mission
    from autopilot.simlink import LinkLost, parse_url
    from mission.missionfile import load_mission
    from mission.recordings import record_path
    from simbridge.vehicle import load_vehicle
    from simbridge.world import load_world

    try:
        parse_url(args.sim)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    mission, takeoff_altitude = load_mission(args.mission)
    vehicle = load_vehicle(args.vehicle)
    if args.origin:
        origin = _origin(args.origin)
    else:
        o = load_world("default").origin
        origin = (o.lat_deg, o.lon_deg, o.alt_m)
    config = AutopilotConfig(
        sim_url=args.sim,
        mission=mission,
        vehicle=vehicle,
        model=make_model(args.model, vehicle, args.rho, args.network),
        origin=origin,
        commander=dataclasses.replace(CommanderParams(), takeoff_altitude_m=takeoff_altitude),
    )
    recording = record_path(args)
    if recording is not None:
        info = {
            "mission": str(args.mission),
            "model": args.model,
            "rho": args.rho,
            "network": args.network,
            "world": args.record_world,
            "sim": args.sim,
        }
        world = load_world(args.record_world) if args.record_world else None
        config = dataclasses.replace(config, record=RecordOptions(recording, world, info))
    signal.signal(signal.SIGTERM, _terminate)
    try:
        flight = fly_mission(config)
    except LinkLost as lost:
        print(f"groundfx autopilot: {lost}", file=sys.stderr)
        return 3
    if args.trajectory:
        args.trajectory.parent.mkdir(parents=True, exist_ok=True)
        np.savez(args.trajectory, log=flight.log, columns=np.array(COLUMNS))
    summary = dict(flight.summary, rho=args.rho, recording=str(recording) if recording else None)
    if args.json:
        print(json.dumps(summary), flush=True)
    else:
        print(
            f"groundfx autopilot: {flight.ended}; "
            + ", ".join(
                f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in summary.items()
            )
        )
    if not flight.summary["landed"]:
        print(f"groundfx autopilot: {flight.ended}", file=sys.stderr)
        return 3
    return 0


def cmd_fly(args: argparse.Namespace) -> int:
    from mission.fly import describe, fly

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
        record=False if args.no_record else (args.record or True),
    )
    print(json.dumps(summary) if args.json else describe(summary))
    return 0 if summary["landed"] else 1


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
            max_epochs=args.max_epochs, seed=args.seed, layer_bound=args.layer_bound
        )
        result = train(datasets, config, sources=[str(p) for p in args.data])
        paths = write_outputs(result, args.out)
        m = result.metrics
        print(
            f"trained on {m['train_samples']} samples ({m['outliers_dropped']} outliers dropped) "
            f"in {m['wall_s']:.1f} s, {m['epochs']} epochs; validation RMSE f_ge,z "
            f"{m['validation_rmse_n']['fge_z'] * 1000:.2f} mN; Lipschitz bound "
            f"{m['lipschitz_bound']:.2f}"
        )
        for kind, path in paths.items():
            print(f"{kind}: {path}")
        return 0
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
