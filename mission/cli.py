"""The `groundfx` command line: one entry point, one subcommand per job."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from learner.bounds import DEFAULT_CONTROL_GAIN_BOUND, DEFAULT_LAYER_BOUND
from learner.online.names import METHODS
from mission import commands, gap_cli
from mission.experiments.cli import add_experiment_parser
from mission.mission_cli import add_mission_parser
from mission.online_cli import add_online_learn_parsers, add_online_options
from mission.recordings import add_record_options
from mission.review import add_review_parser
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


def _max_flight_s(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 1.0 <= value <= 86400.0:
        raise argparse.ArgumentTypeError(f"expected seconds in [1, 86400], got {text!r}")
    return value


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port in [0, 65535], got {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port in [0, 65535], got {text!r}")
    return value


def _model_options(
    p: argparse.ArgumentParser,
    rho_default: float | None = 1.0,
    model_default: str | None = "analytic",
) -> None:
    p.add_argument(
        "--model",
        default=model_default,
        choices=["none", "analytic", "neural"],
        help="ground-effect model of the controller (default: "
        + (model_default or "parameter GFX_GE_MODEL, analytic")
        + ")",
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


def _gcs_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--out",
        action="append",
        metavar="URL",
        help="ground-station endpoint, repeatable: udpout:HOST:PORT, udpin:HOST:PORT, "
        "tcpin:HOST:PORT (default: udpout:127.0.0.1:14550 and udpin:0.0.0.0:14540)",
    )
    p.add_argument("--no-gcs", action="store_true", help="no ground-station endpoint at all")
    p.add_argument(
        "--identity",
        choices=["px4", "ardupilot"],
        default="px4",
        help="autopilot type and mode numbering in HEARTBEAT (default: px4)",
    )
    p.add_argument(
        "--params-file",
        type=Path,
        default=DEFAULT_LOGS / "params.yaml",
        help="YAML file parameters set over MAVLink persist in (default: logs/params.yaml; "
        "none: nothing persists)",
    )
    p.add_argument(
        "--param",
        action="append",
        metavar="NAME=VALUE",
        default=[],
        help="a parameter for this run only, repeatable (e.g. --param MIS_TAKEOFF_ALT=2)",
    )
    p.add_argument(
        "--signing-key-file",
        type=Path,
        help="sign MAVLink 2 to ground stations and accept only signed packets; the file "
        "holds 64 hex digits or a passphrase",
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
    p.set_defaults(func=commands.cmd_sim)

    p = sub.add_parser("bench", help="benchmarks that print figures")
    bench_sub = p.add_subparsers(dest="target", required=True, metavar="TARGET")
    b = bench_sub.add_parser("sim", help="physics and lockstep real-time factors")
    b.add_argument("--world", default="default")
    b.add_argument(
        "--seconds", type=float, default=20.0, help="simulated seconds per figure (default: 20)"
    )
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.add_argument("--out", type=Path, help="also write the JSON to this file")
    b.set_defaults(func=commands.cmd_bench)

    b = bench_sub.add_parser("model", help="the ground-effect network's inference time")
    b.add_argument("--network", default="rho2", help="model file or packaged name")
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.set_defaults(func=commands.cmd_bench)
    b = bench_sub.add_parser("online", help="controller latency and rtf, learner off and on")
    b.add_argument(
        "--method", default="naive", choices=METHODS, help="online method (default: naive)"
    )
    b.add_argument("--repeat", type=int, default=3, help="off/on pairs (default: 3)")
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.set_defaults(func=commands.cmd_bench)
    b = bench_sub.add_parser("sitl", help="simulator and autopilot processes in lockstep")
    b.add_argument("--world", default="default")
    b.add_argument(
        "--repeat", type=int, default=3, help="flights with recording off and on each (default: 3)"
    )
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.set_defaults(func=commands.cmd_bench)

    p = sub.add_parser(
        "autopilot",
        help="run the autopilot: PX4 simulator protocol to the sim, MAVLink to ground stations",
    )
    p.add_argument(
        "--sim", default="tcp:127.0.0.1:4560", help="simulator URL (default: tcp:127.0.0.1:4560)"
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
    _model_options(p, rho_default=None, model_default=None)
    _gcs_options(p)
    p.add_argument("--vehicle", default="nano", help="vehicle YAML or packaged name")
    p.add_argument("--origin", metavar="LAT,LON,ALT", help="geodetic origin of the local frame")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.add_argument("--trajectory", type=Path, help="save the flown trajectory (.npz)")
    p.add_argument("--flight-log", type=Path, help="save airborne steps as a gap-diagnosis log")
    p.add_argument(
        "--max-flight-s", type=_max_flight_s, default=900.0,
        help="end the flight (exit code 3) after this many simulated seconds (default 900)",
    )  # fmt: skip
    add_online_options(p)
    add_record_options(p, world=True)
    p.set_defaults(func=commands.cmd_autopilot)

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
    p.add_argument(
        "--no-gcs",
        action="store_true",
        help="no ground station: the autopilot arms and starts by itself (reproducible)",
    )
    p.add_argument("--identity", choices=["px4", "ardupilot"], default="px4")
    p.add_argument("-v", "--verbose", action="store_true", help="print the vehicle's messages")
    p.add_argument(
        "--param",
        action="append",
        metavar="NAME=VALUE",
        default=[],
        help="a vehicle parameter for this flight, repeatable (e.g. GFX_OL_LR=0.01)",
    )
    add_online_options(p)
    add_record_options(p)
    p.set_defaults(func=commands.cmd_fly)

    add_review_parser(sub)

    p = sub.add_parser(
        "sitl",
        help="simulator and autopilot waiting for ground stations (like make px4_sitl)",
    )
    p.add_argument("--world", default="default", help="world YAML or packaged world name")
    p.add_argument(
        "--speedup", type=_speedup, default=1.0, help="N times real time or 'max' (default: 1)"
    )
    p.add_argument(
        "-L",
        "--location",
        metavar="LAT,LON,ALT,YAW",
        help="geodetic origin and start heading (degrees from north), as sim_vehicle.py -L",
    )
    _model_options(p, rho_default=None, model_default=None)
    _gcs_options(p)
    p.add_argument("--vehicle", default="nano", help="vehicle YAML or packaged name")
    add_record_options(p)
    p.set_defaults(func=commands.cmd_sitl)

    add_mission_parser(sub)
    add_experiment_parser(sub)

    p = sub.add_parser("learn", help="gather data, train the ground-effect network, plot it")
    learn = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    g = learn.add_parser("gather", help="the expert flies the thesis's random waypoints")
    g.add_argument("--rho", type=float, required=True, help="rho_sim of the world and the expert")
    g.add_argument("--samples", type=int, default=10000, help="100 Hz samples (default: 10000)")
    g.add_argument("--seed", type=int, default=0)
    g.add_argument("--world", default="default", help="world whose ground effect rho replaces")
    g.add_argument("--out", type=Path, required=True, help="dataset file (.npz)")
    g.set_defaults(func=commands.cmd_learn)
    t = learn.add_parser("train", help="offline training")
    t.add_argument("data", type=Path, nargs="+", help="dataset files")
    t.add_argument("--out", type=Path, required=True, help="model file (.npz)")
    t.add_argument("--max-epochs", type=int, default=1000)
    t.add_argument(
        "--layer-bound",
        type=float,
        default=DEFAULT_LAYER_BOUND,
        help=f"spectral norm bound per layer (default: {DEFAULT_LAYER_BOUND:g})",
    )
    t.add_argument(
        "--control-gain-bound",
        type=float,
        default=DEFAULT_CONTROL_GAIN_BOUND,
        help="bound on |d f_ge / d thrust| near hover, N/N, through the rotor-speed inputs "
        f"(Neural Lander's stability condition; 0: none; default: {DEFAULT_CONTROL_GAIN_BOUND:g})",
    )
    t.add_argument("--seed", type=int, default=0)
    t.set_defaults(func=commands.cmd_learn)
    e = learn.add_parser("evaluate", help="none, analytic and neural over seeded landing trials")
    e.add_argument("--world", default="rho2")
    e.add_argument(
        "--network", help="model file or packaged name (default: nearest the world's rho)"
    )
    e.add_argument("--trials", type=int, default=10)
    e.add_argument("--seed", type=int, default=0, help="first trial seed")
    e.add_argument("--json", action="store_true")
    e.set_defaults(func=commands.cmd_learn)
    add_online_learn_parsers(learn, commands.cmd_learn)
    pl = learn.add_parser("plot", help="true against predicted f_ge,z over altitude")
    pl.add_argument("--network", default="rho1", help="model file or packaged name")
    pl.add_argument("--rho-list", default="1,2", help="rho values to draw (default: 1,2)")
    pl.add_argument("--out", type=Path, default=DEFAULT_LOGS / "prediction.png")
    pl.set_defaults(func=commands.cmd_learn)

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
    g.set_defaults(func=commands.cmd_plot)

    gap_cli.add_parser(sub)

    p = sub.add_parser("demo", help="the demo flight (analytic, neural and no model)")
    p.add_argument("--world", help="world YAML or packaged name (default: rho2; --lift: default)")
    p.add_argument("--logs", type=Path, default=DEFAULT_LOGS)
    p.add_argument(
        "--lift",
        action="store_true",
        help="the simulator alone: the ground effect lifts a drone at hover speed",
    )
    p.set_defaults(func=commands.cmd_demo)
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
