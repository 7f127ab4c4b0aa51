"""`groundfx sim`: the simulated vehicle behind the PX4 simulator protocol."""

from __future__ import annotations

import argparse
import dataclasses
import faulthandler
import signal
import sys
from typing import Any

from mission.cli.options import port, speedup
from simbridge.transport import PEER_SILENCE_S


def terminate(_signum: int, _frame: object) -> None:
    raise KeyboardInterrupt


def add_parser(sub: Any) -> None:
    p = sub.add_parser("sim", help="run the PyBullet drone behind the PX4 simulator protocol (TCP)")
    p.add_argument(
        "--world", default="default", help="world YAML or packaged world name (default: default)"
    )
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default: 127.0.0.1)")
    p.add_argument(
        "--port", type=port, default=4560, help="TCP port, 0 for any free one (default: 4560)"
    )
    p.add_argument(
        "--unix",
        metavar="PATH",
        help="listen on a Unix-domain socket at PATH instead of TCP (an autopilot of ours "
        "connects with --sim unix:PATH; the same messages, a shorter way through the kernel)",
    )
    p.add_argument(
        "--start", metavar="X,Y,Z", help="start position in metres, overriding the world's"
    )
    p.add_argument(
        "--ideal-sensors",
        action="store_true",
        help="sensors without noise, bias or latency (the world's sensor_noise turned off)",
    )
    p.add_argument(
        "--sensor-seed",
        type=int,
        metavar="N",
        help="seed of the sensor errors, overriding the world's sensor_noise.seed",
    )
    p.add_argument(
        "--speedup",
        type=speedup,
        default=1.0,
        help="simulated seconds per wall second, or 'max' (default: 1)",
    )
    p.add_argument(
        "--timeout",
        type=float,
        default=PEER_SILENCE_S,
        help="seconds to wait for an autopilot's reply in lockstep; a slow autopilot is "
        "waited for, one that closed its connection ends the run at once "
        f"(default: {PEER_SILENCE_S:g})",
    )
    p.add_argument(
        "--wait",
        action="store_true",
        help="after an autopilot leaves, wait for the next one in a fresh world",
    )
    p.add_argument(
        "--lockstep-start",
        action="store_true",
        help="wait for the autopilot's reply to the first state before the clock runs "
        "(reproducible flights; not for PX4, which needs a running clock to boot)",
    )
    p.add_argument(
        "--low-latency-idle",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="as fast as possible (--speedup max), hold the kernel's CPU wake-up latency "
        "request (/dev/cpu_dma_latency at 0 us) while an autopilot is served, so that "
        "lockstep pays no halted-CPU wake-ups; idle CPUs then spin in the kernel's idle "
        "loop meanwhile (power). Needs root; without it the flight runs unchanged "
        "(default: on)",
    )
    p.set_defaults(func=cmd_sim)


def cmd_sim(args: argparse.Namespace) -> int:
    from simbridge.server import LinkEnded, ServerOptions, SimServer
    from simbridge.vehicle import load_vehicle
    from simbridge.world import load_world, parse_start, with_ideal_sensors, with_start

    world = load_world(args.world)
    if args.ideal_sensors:
        world = with_ideal_sensors(world)
    elif args.sensor_seed is not None:
        if not 0 <= args.sensor_seed < 2**31:
            print(f"groundfx sim: --sensor-seed: expected 0 to {2**31 - 1}", file=sys.stderr)
            return 2
        noise = dataclasses.replace(world.sensor_noise, seed=args.sensor_seed)
        world = dataclasses.replace(world, sensor_noise=noise)
    if args.start:
        world = with_start(world, parse_start(args.start))
    vehicle = load_vehicle(world.vehicle)
    server = SimServer(
        world,
        vehicle,
        ServerOptions(
            host=args.host,
            port=args.port,
            unix_path=args.unix,
            speedup=args.speedup,
            timeout_s=args.timeout,
            wait=args.wait,
            lockstep_start=args.lockstep_start,
            low_latency_idle=args.low_latency_idle,
        ),
    )
    # before it says it listens: a launcher may stop it as soon as it has read that line
    signal.signal(signal.SIGTERM, terminate)
    # Ctrl-C even where SIGINT came in ignored (a script's background job, nohup): Python then
    # leaves it ignored, and a simulator told to stop would run on
    signal.signal(signal.SIGINT, signal.default_int_handler)
    faulthandler.register(signal.SIGUSR1)  # `kill -USR1 PID`: where each thread is, on stderr
    try:
        url = server.listen()
    except OSError as err:
        where = f"unix:{args.unix}" if args.unix else f"tcp:{args.host}:{args.port}"
        print(f"groundfx sim: cannot listen on {where}: {err.strerror}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 0
    try:
        print(f"groundfx sim: listening on {url}", flush=True)
        end = server.serve(lambda e: print(f"groundfx sim: {server.summary(str(e))}", flush=True))
    except KeyboardInterrupt:
        end = LinkEnded("stopped by signal")
    print(f"groundfx sim: {server.summary(str(end))}", flush=True)
    return 0 if end.clean else 1
