"""The `groundfx` command line: one entry point, one subcommand per job."""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
from pathlib import Path

from simbridge.config import ConfigError

DEFAULT_LOGS = Path("logs")


def _speedup(text: str) -> float | None:
    if text == "max":
        return None
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number > 0 or 'max', got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a number > 0 or 'max', got {text!r}")
    return value


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port in [0, 65535], got {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port in [0, 65535], got {text!r}")
    return value


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
    from autopilot.runner import AutopilotConfig, fly_mission
    from autopilot.simlink import LinkLost, parse_url
    from mission.missionfile import load_mission
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
    signal.signal(signal.SIGTERM, _terminate)
    try:
        flight = fly_mission(config)
    except LinkLost as lost:
        print(f"groundfx autopilot: {lost}", file=sys.stderr)
        return 3
    if args.trajectory:
        args.trajectory.parent.mkdir(parents=True, exist_ok=True)
        np.savez(args.trajectory, log=flight.log, columns=np.array(COLUMNS))
    summary = dict(flight.summary, rho=args.rho)
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

        result = bench_sitl(args.world)
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


def _model_options(p: argparse.ArgumentParser, rho_default: float | None = 1.0) -> None:
    p.add_argument(
        "--model",
        default="analytic",
        choices=["none", "analytic", "neural"],
        help="ground-effect model of the controller (default: analytic)",
    )
    p.add_argument(
        "--rho",
        type=float,
        default=rho_default,
        help="rho of the analytic model (fly's default: the world's rho_sim)",
    )
    p.add_argument(
        "--network",
        help="model file or packaged name for --model neural "
        "(default: the packaged network trained nearest --rho)",
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="groundfx",
        description="SITL autopilot for a nano quadrotor that learns the ground effect.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("sim", help="run the PyBullet drone behind the PX4 simulator protocol (TCP)")
    p.add_argument(
        "--world", default="default", help="world YAML or packaged world name (default: default)"
    )
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default: 127.0.0.1)")
    p.add_argument(
        "--port", type=_port, default=4560, help="TCP port, 0 for any free one (default: 4560)"
    )
    p.add_argument(
        "--start", metavar="X,Y,Z", help="start position in metres, overriding the world's"
    )
    p.add_argument(
        "--speedup",
        type=_speedup,
        default=1.0,
        help="simulated seconds per wall second, or 'max' (default: 1)",
    )
    p.add_argument(
        "--timeout",
        type=float,
        default=10.0,
        help="seconds to wait for an autopilot's reply in lockstep (default: 10)",
    )
    p.add_argument(
        "--wait",
        action="store_true",
        help="after an autopilot leaves, wait for the next one in a fresh world",
    )
    p.set_defaults(func=cmd_sim)

    p = sub.add_parser("bench", help="benchmarks that print figures")
    bench_sub = p.add_subparsers(dest="target", required=True, metavar="TARGET")
    b = bench_sub.add_parser("sim", help="physics and lockstep real-time factors")
    b.add_argument("--world", default="default")
    b.add_argument(
        "--seconds", type=float, default=20.0, help="simulated seconds per figure (default: 20)"
    )
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.add_argument("--out", type=Path, help="also write the JSON to this file")
    b.set_defaults(func=cmd_bench)

    b = bench_sub.add_parser("model", help="the ground-effect network's inference time")
    b.add_argument("--network", default="rho2", help="model file or packaged name")
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.set_defaults(func=cmd_bench)
    b = bench_sub.add_parser("sitl", help="simulator and autopilot processes in lockstep")
    b.add_argument("--world", default="default")
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.set_defaults(func=cmd_bench)

    p = sub.add_parser("autopilot", help="run the autopilot against a PX4-protocol simulator")
    p.add_argument(
        "--sim", default="tcp:127.0.0.1:4560", help="simulator URL (default: tcp:127.0.0.1:4560)"
    )
    p.add_argument("--mission", type=Path, required=True, help="mission YAML")
    _model_options(p)
    p.add_argument("--vehicle", default="nano", help="vehicle YAML or packaged name")
    p.add_argument("--origin", metavar="LAT,LON,ALT", help="geodetic origin of the local frame")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.add_argument("--trajectory", type=Path, help="save the flown trajectory (.npz)")
    p.set_defaults(func=cmd_autopilot)

    p = sub.add_parser("fly", help="fly a mission: simulator and autopilot processes in lockstep")
    p.add_argument("mission", type=Path, help="mission YAML (see mission/examples)")
    p.add_argument("--world", default="default", help="world YAML or packaged world name")
    _model_options(p, rho_default=None)
    p.add_argument(
        "--speedup", type=_speedup, default=None, help="N times real time or 'max' (default)"
    )
    p.add_argument("--start", metavar="X,Y,Z", help="start position, overriding the world's")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.add_argument("--trajectory", type=Path, help="save the flown trajectory (.npz)")
    p.set_defaults(func=cmd_fly)

    p = sub.add_parser("learn", help="gather data, train the ground-effect network, plot it")
    learn = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    g = learn.add_parser("gather", help="the expert flies the thesis's random waypoints")
    g.add_argument("--rho", type=float, required=True, help="rho_sim of the world and the expert")
    g.add_argument("--samples", type=int, default=10000, help="100 Hz samples (default: 10000)")
    g.add_argument("--seed", type=int, default=0)
    g.add_argument("--world", default="default", help="world whose ground effect rho replaces")
    g.add_argument("--out", type=Path, required=True, help="dataset file (.npz)")
    g.set_defaults(func=cmd_learn)
    t = learn.add_parser("train", help="offline training")
    t.add_argument("data", type=Path, nargs="+", help="dataset files")
    t.add_argument("--out", type=Path, required=True, help="model file (.npz)")
    t.add_argument("--max-epochs", type=int, default=1000)
    t.add_argument("--layer-bound", type=float, default=2.0, help="spectral norm bound per layer")
    t.add_argument("--seed", type=int, default=0)
    t.set_defaults(func=cmd_learn)
    e = learn.add_parser("evaluate", help="none, analytic and neural over seeded landing trials")
    e.add_argument("--world", default="rho2")
    e.add_argument(
        "--network", help="model file or packaged name (default: nearest the world's rho)"
    )
    e.add_argument("--trials", type=int, default=10)
    e.add_argument("--seed", type=int, default=0, help="first trial seed")
    e.add_argument("--json", action="store_true")
    e.set_defaults(func=cmd_learn)
    pl = learn.add_parser("plot", help="true against predicted f_ge,z over altitude")
    pl.add_argument("--network", default="rho1", help="model file or packaged name")
    pl.add_argument("--rho-list", default="1,2", help="rho values to draw (default: 1,2)")
    pl.add_argument("--out", type=Path, default=DEFAULT_LOGS / "prediction.png")
    pl.set_defaults(func=cmd_learn)

    p = sub.add_parser("plot", help="figures")
    plot_sub = p.add_subparsers(dest="figure", required=True, metavar="FIGURE")
    g = plot_sub.add_parser(
        "ground-effect", help="ground-effect force against altitude (thesis fig. 3.2)"
    )
    g.add_argument(
        "--rho", default="0.5,1,2,4", help="comma-separated rho values (default: 0.5,1,2,4)"
    )
    g.add_argument("--vehicle", default="nano")
    g.add_argument("--out", type=Path, default=DEFAULT_LOGS / "ground_effect.png")
    g.set_defaults(func=cmd_plot)

    p = sub.add_parser("demo", help="the demo flight (analytic, neural and no model)")
    p.add_argument("--world", help="world YAML or packaged name (default: rho2; --lift: default)")
    p.add_argument("--logs", type=Path, default=DEFAULT_LOGS)
    p.add_argument(
        "--lift",
        action="store_true",
        help="the simulator alone: the ground effect lifts a drone at hover speed",
    )
    p.set_defaults(func=cmd_demo)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ConfigError as err:
        print(f"groundfx {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"groundfx {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
