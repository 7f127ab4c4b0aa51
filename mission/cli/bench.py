"""`groundfx bench sim|model|online|sitl|soak|campaign`: benchmarks that print figures."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from autopilot.request import alternation_seconds
from learner.online.names import METHODS
from simbridge.config import ConfigError


def add_parser(sub: Any) -> None:
    p = sub.add_parser("bench", help="benchmarks that print figures")
    bench_sub = p.add_subparsers(dest="target", required=True, metavar="TARGET")
    b = bench_sub.add_parser("sim", help="physics and lockstep real-time factors")
    b.add_argument("--world", default="default")
    b.add_argument(
        "--seconds", type=float, default=20.0, help="simulated seconds per figure (default: 20)"
    )
    b.add_argument(
        "--repeat", type=int, default=5, help="runs of each figure and reference (default: 5)"
    )
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.add_argument("--out", type=Path, help="also write the JSON to this file")
    b.set_defaults(func=cmd_bench)

    b = bench_sub.add_parser("model", help="the ground-effect network's inference time")
    b.add_argument("--network", default="rho2", help="model file or packaged name")
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.set_defaults(func=cmd_bench)
    b = bench_sub.add_parser(
        "online", help="controller latency and rtf, the learner working against resting"
    )
    b.add_argument(
        "--method",
        default="naive",
        choices=(*METHODS, "all"),
        help="online method, or all of them in turn (default: naive)",
    )
    b.add_argument("--repeat", type=int, help="flights per method (default: 16)")
    b.add_argument("--hold-s", type=float, help="the 3 cm hold of each flight, s (default: 120)")
    b.add_argument(
        "--alternate-s",
        type=alternation_seconds,
        help="the learner's turns, working then resting, simulated s (default: 1)",
    )
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.set_defaults(func=cmd_bench)
    b = bench_sub.add_parser("sitl", help="simulator and autopilot processes in lockstep")
    b.add_argument("--world", default="default")
    b.add_argument(
        "--repeat", type=int, default=5, help="flights with recording off and on each (default: 5)"
    )
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.set_defaults(func=cmd_bench)
    b = bench_sub.add_parser(
        "campaign", help="the campaign runner's throughput with 1 and K local workers"
    )
    b.add_argument("--flights", type=int, default=8, help="short flights per setting (default: 8)")
    b.add_argument(
        "--workers", type=int, default=2, help="the second setting's workers (default: 2)"
    )
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.set_defaults(func=cmd_bench)
    b = bench_sub.add_parser(
        "soak", help="MAVSDK missions back to back against one sitl: failures, memory growth"
    )
    b.add_argument("--missions", type=int, default=50, help="missions to fly (default: 50)")
    b.add_argument("--identity", default="px4", choices=("px4", "ardupilot"))
    b.add_argument("--speedup", default="max", help="the simulator's pace (default: max)")
    b.add_argument(
        "--record",
        type=Path,
        metavar="FILE",
        help="record the whole soak to this rerun file (default: no recording)",
    )
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.add_argument("--out", type=Path, help="also write the JSON to this file")
    b.set_defaults(func=cmd_bench)


def _wrote_json(args: argparse.Namespace, result: dict[str, Any]) -> bool:
    """The result to `--out` (if given) and, with `--json`, to stdout: True if printed."""
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=2) + "\n")
    if args.json:
        print(json.dumps(result))
    return bool(args.json)


def _soak(args: argparse.Namespace) -> int:
    from mission.campaigns.soak import soak

    result = soak(
        args.missions,
        args.identity,
        args.speedup,
        args.record,
        say=lambda text: None if args.json else print(text, flush=True),
    )
    if not _wrote_json(args, result):
        print(
            f"{result['flown']} of {result['missions']} missions flown, "
            f"{len(result['failures'])} failures in {result['wall_s']:.0f} s "
            f"(load {result['load_average']:.2f})"
        )
        for failure in result["failures"]:
            print(f"  {failure}")
        for name, m in result["memory_after_mission_1_to_last"].items():
            print(
                f"{name}: resident {m['first_mib']} MiB after mission 1, {m['last_mib']} MiB "
                f"after the last ({m['growth_percent']:+.1f} %), at most {m['max_mib']} MiB"
            )
    return 0 if not result["failures"] else 3


def cmd_bench(args: argparse.Namespace) -> int:
    if args.target == "soak":
        return _soak(args)
    if args.target == "campaign":
        from mission.campaigns.campaign_bench import bench_campaign

        if args.flights < 1 or args.workers < 2:
            raise ConfigError("--flights must be at least 1 and --workers at least 2")
        result = bench_campaign(args.flights, args.workers)
        print(
            json.dumps(result) if args.json else "\n".join(f"{k}: {v}" for k, v in result.items())
        )
        return 0
    if args.target == "model":
        from learner.bench import bench_model

        r = bench_model(args.network)
        if args.json:
            print(json.dumps(r))
            return 0
        print(
            f"network {r['network']}: {r['predict_us_p50']:.1f} us p50 per sample "
            f"({r['predict_us_p99']:.1f} p99); the same network in torch "
            f"{r['torch_us_p50']:.1f} us ({r['torch_us_p99']:.1f}): "
            f"{r['speedup_over_torch']:.1f} times as fast"
        )
        print(
            f"the two agree to {r['max_force_difference_n']:.1e} N; {r['samples']} samples each, "
            f"interleaved; load average {r['load_average'][0]:.2f} before, "
            f"{r['load_average'][1]:.2f} after"
        )
        return 0
    if args.target == "online":
        return _bench_online(args)
    if args.target == "sitl":
        from mission.campaigns.bench import bench_sitl

        result = bench_sitl(args.world, args.repeat)
        print(
            json.dumps(result) if args.json else "\n".join(f"{k}: {v}" for k, v in result.items())
        )
        return 0
    from simbridge.bench import bench_sim

    if args.repeat < 1:
        raise ConfigError(f"--repeat: {args.repeat} must be at least 1")
    result = bench_sim(args.world, args.seconds, args.repeat)
    if not _wrote_json(args, result):
        r = result
        print(
            f"physics:  {r['physics_rtf']:.1f}x real time "
            f"({r['physics_us_per_step']:.1f} us per {r['physics_hz']} Hz step, "
            f"effects: {', '.join(r['effects']) or 'none'}); bare quadrotor loop "
            f"{r['bare_loop_rtf']:.1f}x ({r['bare_loop_us_per_step']:.1f} us): "
            f"{r['physics_ratio']:.2f} of it"
        )
        print(
            f"lockstep: {r['lockstep_rtf']:.1f}x real time over a Unix-domain socket "
            f"({r['lockstep_us_per_step']:.0f} us per {r['control_hz']} Hz round trip), "
            f"{r['lockstep_tcp_rtf']:.1f}x over TCP ({r['lockstep_tcp_us_per_step']:.0f} us); "
            f"pymavlink ping-pong over TCP {r['pingpong_rtf']:.1f}x "
            f"({r['pingpong_us_per_step']:.0f} us): {r['lockstep_ratio']:.2f} and "
            f"{r['lockstep_tcp_ratio']:.2f} of it"
        )
        print(
            f"          the ping-pong stepping the bare quadrotor loop after each reply (a "
            f"pymavlink simulator with physics) {r['pingpong_physics_rtf']:.1f}x "
            f"({r['pingpong_physics_us_per_step']:.0f} us): {r['lockstep_physics_ratio']:.2f} "
            "of it"
        )
        if "lockstep_sim_cpu_us_per_step" in r and "pingpong_server_cpu_us_per_step" in r:
            print(
                f"CPU a step in the loop: simulator {r['lockstep_sim_cpu_us_per_step']:.0f} us, "
                f"its client {r['lockstep_client_cpu_us_per_step']:.0f} us; ping-pong server "
                f"{r['pingpong_server_cpu_us_per_step']:.0f} us, its client "
                f"{r['pingpong_client_cpu_us_per_step']:.0f} us; with physics "
                f"{r['pingpong_physics_server_cpu_us_per_step']:.0f} and "
                f"{r['pingpong_physics_client_cpu_us_per_step']:.0f} us (each loop runs at the "
                "pace of its busier end)"
            )
        print(f"both lockstep loops: {r['cpu_wake_latency'] or 'CPU wake-up latency unknown'}")
        print(
            f"medians of {r['repeat']} interleaved runs; load average "
            f"{r['load_average'][0]:.2f} before, {r['load_average'][1]:.2f} after"
        )
    return 0


def _bench_online(args: argparse.Namespace) -> int:
    from mission.campaigns.online_bench import bench_online

    chosen: dict[str, Any] = {}
    if args.repeat is not None:
        if args.repeat < 1:
            raise ConfigError(f"--repeat: {args.repeat} must be at least 1")
        chosen["repeat"] = args.repeat
    if args.hold_s is not None:
        if not 0.0 < args.hold_s <= 3600.0:
            raise ConfigError(f"--hold-s: {args.hold_s:g} is outside the allowed range (0, 3600]")
        chosen["hold_s"] = args.hold_s
    if args.alternate_s is not None:
        chosen["alternate_s"] = args.alternate_s
    methods = METHODS if args.method == "all" else (args.method,)
    results = {}
    for method in methods:
        results[method] = r = bench_online(method, **chosen)
        if not args.json:
            print(_online_line(r), flush=True)
    if args.json:
        print(json.dumps(results if args.method == "all" else results[args.method]))
    return 0 if all(_meets(r) for r in results.values()) else 3


def _meets(r: dict[str, Any]) -> bool:
    return bool(r["meets_p99_target"] and r["meets_rtf_target"] and r["no_sample_dropped"])


def _online_line(r: dict[str, Any]) -> str:
    """One method's figures in a few lines."""

    from mission.campaigns.online_bench import P99_TARGET, RTF_TARGET

    def ci(key: str) -> str:
        low_high = r.get(f"{key}_ci95")
        return f" [{low_high[0]:.2f}, {low_high[1]:.2f}]" if low_high else ""

    verdict = "meets" if _meets(r) else "misses"
    return (
        f"{r['method']} ({r['network']}, {r['flights']} flights, {r['steps_working']} steps "
        f"working, {r['steps_resting']} resting):\n"
        f"  controller p99 {r['controller_us_p99_working']:.0f} us working, "
        f"{r['controller_us_p99_resting']:.0f} resting: {r['p99_ratio']:.2f}x{ci('p99_ratio')}"
        f" (p50 {r['p50_ratio']:.2f}x; resting against resting "
        f"{r['resting_halves_p99_ratio']:.2f}x)\n"
        f"  real-time factor {r['rtf_working']:.2f} working, {r['rtf_resting']:.2f} resting: "
        f"{r['rtf_ratio']:.2f}x{ci('rtf_ratio')}\n"
        f"  updates {r['online_updates']}, samples dropped {r['online_dropped']}; {verdict} the "
        f"targets (p99 at most {P99_TARGET:g}x, real-time factor at least {RTF_TARGET:g}x, no "
        f"sample dropped); load "
        f"average {r['load_average'][0]:.2f} before, {r['load_average'][1]:.2f} after"
    )
