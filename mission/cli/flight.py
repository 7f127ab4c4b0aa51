"""`groundfx fly`, `sitl` and `demo`: flights of simulator and autopilot processes."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from mission.cli.online import add_online_options
from mission.cli.options import (
    DEFAULT_GCS_URLS,
    DEFAULT_LOGS,
    add_sensor_options,
    gcs_options,
    max_flight_s,
    model_options,
    sensor_arguments,
    speedup,
)
from mission.recordings import add_record_options


def add_fly_parser(sub: Any) -> None:
    p = sub.add_parser("fly", help="fly a mission: simulator and autopilot processes in lockstep")
    p.add_argument("mission", type=Path, help="mission YAML (see mission/examples)")
    p.add_argument("--world", default="default", help="world YAML or packaged world name")
    model_options(p, rho_default=None)
    p.add_argument(
        "--speedup", type=speedup, default=None, help="N times real time or 'max' (default)"
    )
    p.add_argument("--start", metavar="X,Y,Z", help="start position, overriding the world's")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.add_argument("--trajectory", type=Path, help="save the flown trajectory (.npz)")
    p.add_argument("--flight-log", type=Path, help="save airborne steps as a gap-diagnosis log")
    p.add_argument(
        "--max-flight-s",
        type=max_flight_s,
        help="end the flight after this many simulated seconds (default: the autopilot's 900)",
    )
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
    add_sensor_options(p)
    add_online_options(p)
    add_record_options(p)
    p.set_defaults(func=cmd_fly)


def add_sitl_parser(sub: Any) -> None:
    p = sub.add_parser(
        "sitl",
        help="simulator and autopilot waiting for ground stations (like make px4_sitl)",
    )
    p.add_argument("--world", default="default", help="world YAML or packaged world name")
    p.add_argument(
        "--speedup", type=speedup, default=1.0, help="N times real time or 'max' (default: 1)"
    )
    p.add_argument(
        "-L",
        "--location",
        metavar="LAT,LON,ALT,YAW",
        help="geodetic origin and start heading (degrees from north), as sim_vehicle.py -L",
    )
    model_options(p, rho_default=None, model_default=None)
    gcs_options(p)
    p.add_argument(
        "--vehicle",
        help="the autopilot's vehicle YAML or packaged name (default: the world's, as the sim's)",
    )
    add_sensor_options(p)
    add_record_options(p)
    p.set_defaults(func=cmd_sitl)


def add_demo_parser(sub: Any) -> None:
    p = sub.add_parser("demo", help="the demo flight (analytic, neural and no model)")
    p.add_argument("--world", help="world YAML or packaged name (default: rho2; --lift: default)")
    p.add_argument("--logs", type=Path, default=DEFAULT_LOGS)
    p.add_argument(
        "--lift",
        action="store_true",
        help="the simulator alone: the ground effect lifts a drone at hover speed",
    )
    p.set_defaults(func=cmd_demo)


def cmd_fly(args: argparse.Namespace) -> int:
    from mission.cli.online import online_overrides, pass_through
    from mission.fly import describe, fly

    online_overrides(args)  # refuse --online without --model neural before starting anything
    sim_options, sensor_params = sensor_arguments(args)
    # the user's --param last: it overrides a sensor set's
    extra = pass_through(args) + sensor_params + [a for p in args.param for a in ("--param", p)]
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
        sim_options=sim_options,
        flight_log=args.flight_log,
        max_flight_s=args.max_flight_s,
    )
    print(json.dumps(summary) if args.json else describe(summary))
    return 0 if summary["landed"] else 1


def cmd_sitl(args: argparse.Namespace) -> int:
    from mission.sitl import parse_location, run_sitl

    location = parse_location(args.location) if args.location else None
    options = ["--identity", args.identity, "--params-file", str(args.params_file)]
    if args.vehicle is not None:
        options += ["--vehicle", args.vehicle]
    sim_options, sensor_params = sensor_arguments(args)
    options += sensor_params + [a for p in args.param for a in ("--param", p)]
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
    return run_sitl(args.world, speedup, options, gcs_urls, location, sim_options=sim_options)


def cmd_demo(args: argparse.Namespace) -> int:
    if args.lift:
        from simbridge.demo import run_demo

        run_demo(args.world or "default", args.logs)
        return 0
    from mission.campaigns.demo import run_flight_demo

    return 0 if run_flight_demo(args.world or "rho2", args.logs) else 1
