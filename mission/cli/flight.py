"""`groundfx fly`, `sitl` and `demo`: flights of simulator and autopilot processes."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from autopilot.request import DEFAULT_GCS_URLS, FlightRequest, add_options
from mission.cli.options import DEFAULT_LOGS, add_sensor_options, sensor_arguments, speedup
from simbridge.config import ConfigError

# what `groundfx fly` asks of its autopilot process, as `groundfx autopilot` takes it
FLY_REQUEST = ("rho", "network", "trajectory", "flight_log", "max_flight_s", "identity", "param")
FLY_ONLINE = ("online", "online_deterministic", "save_model")
# what `groundfx sitl` passes to its autopilot process besides the model
SITL_GCS = ("out", "no_gcs", "identity", "params_file", "param", "signing_key_file")


def add_fly_parser(sub: Any) -> None:
    p = sub.add_parser("fly", help="fly a mission: simulator and autopilot processes in lockstep")
    p.add_argument("mission", type=Path, help="mission YAML (see mission/examples)")
    p.add_argument("--world", default="default", help="world YAML or packaged world name")
    add_options(p, ["model", "rho", "network"], defaults={"model": "analytic"})
    p.add_argument(
        "--speedup", type=speedup, default=None, help="N times real time or 'max' (default)"
    )
    p.add_argument("--start", metavar="X,Y,Z", help="start position, overriding the world's")
    add_options(p, ["json", "trajectory", "flight_log", "max_flight_s"])
    p.add_argument(
        "--no-gcs",
        action="store_true",
        help="no ground station: the autopilot arms and starts by itself (reproducible)",
    )
    add_options(p, ["identity"])
    p.add_argument("-v", "--verbose", action="store_true", help="print the vehicle's messages")
    add_options(p, ["param"])
    add_sensor_options(p)
    add_options(p, [*FLY_ONLINE, "record", "no_record"])
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
    add_options(p, ["model", "rho", "network", *SITL_GCS])
    add_options(
        p,
        ["vehicle"],
        defaults={"vehicle": None},
        helps={
            "vehicle": "the autopilot's vehicle YAML or packaged name (default: the world's, "
            "as the sim's)"
        },
    )
    add_sensor_options(p)
    add_options(p, ["record", "no_record"])
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
    from mission.cli.online import online_overrides
    from mission.fly import describe, fly

    online_overrides(args)  # refuse --online without --model neural before starting anything
    sim_options, sensor_params = sensor_arguments(args)
    asked = {name: getattr(args, name) for name in (*FLY_REQUEST, *FLY_ONLINE)}
    # the user's --param last: it overrides a sensor set's
    asked["param"] = (*FlightRequest.parse(sensor_params).param, *args.param)
    summary = fly(
        args.mission,
        args.world,
        args.model,
        via_gcs=not args.no_gcs,
        speedup="max" if args.speedup is None else f"{args.speedup:g}",
        start=args.start,
        record=False if args.no_record else (args.record or True),
        say=print if args.verbose else (lambda text: None),
        sim_options=sim_options,
        **asked,
    )
    recording = summary.get("recording")
    if recording and Path(recording).is_file():  # a flight on one page, beside its recording
        from mission.cli.review import write_flight_report

        started = time.perf_counter()
        try:
            summary["report"] = str(write_flight_report(Path(recording))[0])
            summary["report_wall_s"] = time.perf_counter() - started
        except ConfigError as err:  # the flight stands; the page could not be drawn
            summary["report_error"] = str(err)
    print(json.dumps(summary) if args.json else describe(summary))
    return 0 if summary["landed"] else 1


def cmd_sitl(args: argparse.Namespace) -> int:
    from mission.sitl import parse_location, run_sitl

    location = parse_location(args.location) if args.location else None
    sim_options, sensor_params = sensor_arguments(args)
    asked = {name: getattr(args, name) for name in ("model", "rho", "network", *SITL_GCS)}
    asked["param"] = (*FlightRequest.parse(sensor_params).param, *args.param)
    asked["out"] = () if args.no_gcs else tuple(args.out or DEFAULT_GCS_URLS)
    request = FlightRequest(**asked, record=args.record, no_record=args.no_record)
    speedup = "max" if args.speedup is None else f"{args.speedup:g}"
    return run_sitl(args.world, speedup, request, args.vehicle, location, sim_options=sim_options)


def cmd_demo(args: argparse.Namespace) -> int:
    if args.lift:
        from simbridge.demo import run_demo

        run_demo(args.world or "default", args.logs)
        return 0
    from mission.campaigns.demo import run_flight_demo

    return 0 if run_flight_demo(args.world or "rho2", args.logs) else 1
