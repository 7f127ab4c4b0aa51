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
        ServerOptions(host=args.host, port=args.port, speedup=args.speedup, timeout_s=args.timeout),
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
        end = server.serve()
    except KeyboardInterrupt:
        end = LinkEnded("stopped by signal")
    print(f"groundfx sim: {server.summary(str(end))}", flush=True)
    return 0 if end.clean else 1


def cmd_bench(args: argparse.Namespace) -> int:
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
    from simbridge.demo import run_demo

    run_demo(args.world, args.logs)
    return 0


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

    p = sub.add_parser("demo", help="the main demo")
    p.add_argument("--world", default="default")
    p.add_argument("--logs", type=Path, default=DEFAULT_LOGS)
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
