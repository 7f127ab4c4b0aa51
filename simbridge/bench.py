"""`groundfx bench sim`: how fast the physics and the lockstep link run, each beside a
reference measured in the same run on the same machine (machines are shared and noisy: the
ratio holds where the absolute figure does not).

- physics: `Simulation.step` (ground effect on, a hover at 0.1 m) against a bare quadrotor
  loop in PyBullet: the same body, and per physics step only what any PyBullet quadrotor
  does (read pose and velocity, apply the four rotor thrusts at their hubs and the yaw
  moment, step), as gym-pybullet-drones' `_physics` does;
- lockstep: `groundfx sim` in its own process against a minimal pymavlink client, against
  `simbridge.pingpong` (the same messages packed and parsed by pymavlink, no physics) with
  the same client. The lockstep runs over both of the simulator's transports: the
  Unix-domain socket our flights use (`groundfx fly`, the campaigns: both ends ours) and
  TCP, as any PX4-protocol autopilot connects; the ping-pong over TCP, as pymavlink's
  `mavutil` connects (it has no Unix-domain sockets). The client holds the vehicle hovering
  in ground effect at 0.1 m, as in the physics figure. Each loop also reports the CPU time
  each end spent a step (`*_cpu_us_per_step`): a loop of two alternating processes runs at
  the pace of its busier end, which these say;
- lockstep against a pymavlink simulator with physics: the same ping-pong stepping the
  physics reference (the bare loop, `simbridge/bare_loop.py`) for a control period after
  each reply, as our simulator steps its physics between a reply and its next tick
  (`lockstep_physics_ratio`): what our link and sensors cost beside pymavlink's, with the
  physics in both loops.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from simbridge import transport
from simbridge.bare_loop import BareQuadrotor
from simbridge.client import connect, constant, end_lockstep, hover_fraction, run_lockstep
from simbridge.effects.ground import hover_rotor_speed_in_ground_effect_rad_s
from simbridge.launch import SimProcessError, finish, spawn_local_sim, start_sim
from simbridge.physics import Simulation
from simbridge.pingpong import LISTENING
from simbridge.vehicle import Vehicle, load_vehicle
from simbridge.world import World, load_world, resolve_world_path, with_start

BENCH_ALTITUDE_M = 0.1  # deep enough in ground effect that every step evaluates it


def _hover_rad_s(world: World, vehicle: Vehicle) -> float:
    ge = world.effects.ground_effect
    if ge is None:
        return vehicle.hover_rotor_speed_rad_s
    return hover_rotor_speed_in_ground_effect_rad_s(
        vehicle.weight_n,
        vehicle.thrust_coefficient_n_s2,
        BENCH_ALTITUDE_M,
        ge.rho,
        vehicle.rotor_radius_m,
        ge.cutoff_for(vehicle.rotor_radius_m),
    )


def physics_rtf(world: World, vehicle: Vehicle, seconds: float) -> dict[str, float]:
    """Physics alone: the vehicle hovering in ground effect, stepped as fast as possible."""
    n = _hover_rad_s(world, vehicle)
    steps = max(1, round(seconds / world.control_period_s))
    with Simulation(with_start(world, (0.0, 0.0, BENCH_ALTITUDE_M)), vehicle) as sim:
        t0 = time.perf_counter()
        for _ in range(steps):
            sim.step((n, n, n, n))
        wall = time.perf_counter() - t0
        drift = abs(sim.state().position_m[2] - BENCH_ALTITUDE_M)
    sim_s = steps * world.control_period_s
    return {
        "physics_rtf": sim_s / wall,
        "physics_us_per_step": wall / (steps * world.substeps) * 1e6,
        "physics_altitude_drift_m": drift,
    }


def bare_loop_rtf(world: World, vehicle: Vehicle, seconds: float) -> dict[str, float]:
    """The reference: the same body in the same world, stepped by a bare quadrotor loop."""
    steps = max(1, round(seconds * world.physics_rate_hz))
    with Simulation(with_start(world, (0.0, 0.0, BENCH_ALTITUDE_M)), vehicle) as sim:
        bare = BareQuadrotor(sim, vehicle)
        t0 = time.perf_counter()
        bare.run(steps)
        wall = time.perf_counter() - t0
    return {"bare_loop_rtf": seconds / wall, "bare_loop_us_per_step": wall / steps * 1e6}


def process_cpu_s(pid: int) -> float | None:
    """CPU time (user + system) another process has used so far, from /proc (Linux); None
    where that cannot be read. Its resolution is a clock tick (10 ms): a run of a few tenths
    of a second a figure reads to a few per cent."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _lockstep(sock: Any, steps: int, command: Any, server_pid: int) -> dict[str, float]:
    """Run the loop; its wall time and the CPU time each end spent in it (per step, us):
    the loop runs at the pace of the busier end. Timed from the first tick answered: our
    simulator listens before it builds its world (a flight's two processes start side by
    side), and the ping-pong after; the loop's figure is the loop's, not a set-up's."""
    try:
        view = run_lockstep(sock, 1, command)
        server0, client0 = process_cpu_s(server_pid), time.process_time()
        t0 = time.perf_counter()
        run_lockstep(sock, steps, command, view)
        wall = time.perf_counter() - t0
        client1, server1 = time.process_time(), process_cpu_s(server_pid)
        end_lockstep(sock)
    finally:
        sock.close()
    cpu = {"client_cpu_us": (client1 - client0) / steps * 1e6}
    if server0 is not None and server1 is not None:
        cpu["server_cpu_us"] = (server1 - server0) / steps * 1e6
    return {"wall": wall, **cpu}


def _hover_command(world: World, vehicle: Vehicle) -> Any:
    """Constant actuators holding the vehicle at BENCH_ALTITUDE_M in ground effect: each of
    the loop's physics steps evaluates the effect, as in the physics figure."""
    return constant(hover_fraction(_hover_rad_s(world, vehicle), vehicle.max_rotor_speed_rad_s))


def _loop_figures(
    prefix: str, server: str, run: dict[str, float], steps: int, period_s: float
) -> dict[str, float]:
    """`{prefix}_rtf`, `_us_per_step`, and the CPU each end spent a step in the loop
    (`{prefix}_{server}_cpu_us_per_step`, `{prefix}_client_cpu_us_per_step`)."""
    figures = {
        f"{prefix}_rtf": steps * period_s / run["wall"],
        f"{prefix}_us_per_step": run["wall"] / steps * 1e6,
        f"{prefix}_client_cpu_us_per_step": run["client_cpu_us"],
    }
    if "server_cpu_us" in run:
        figures[f"{prefix}_{server}_cpu_us_per_step"] = run["server_cpu_us"]
    return figures


def lockstep_rtf(
    world_path: str, world: World, vehicle: Vehicle, seconds: float, kind: str
) -> dict[str, Any]:
    """`groundfx sim` in its own process against a minimal pymavlink client, constant
    actuators, over a Unix-domain socket (`kind` "unix": keys `lockstep_*`) or TCP ("tcp":
    `lockstep_tcp_*`)."""
    period_s = world.control_period_s
    steps = max(1, round(seconds / period_s))
    command = _hover_command(world, vehicle)
    start = f"0,0,{BENCH_ALTITUDE_M}"
    if kind == transport.UNIX:
        with tempfile.TemporaryDirectory(prefix="groundfx-bench-") as folder:
            path = Path(folder) / "sim.sock"
            proc = spawn_local_sim(world_path, path, start=start)
            try:
                sock = transport.connect(f"unix:{path}", timeout_s=30.0)
            except ConnectionError:
                proc.kill()
                _, err = proc.communicate(timeout=10)
                raise SimProcessError(f"groundfx sim did not start: {err.strip()}") from None
            run = _lockstep(sock, steps, command, proc.pid)
            last_line = finish(proc)
        prefix = "lockstep"
    else:
        proc, port = start_sim(world_path, speedup="max", start=start)
        run = _lockstep(connect("127.0.0.1", port), steps, command, proc.pid)
        last_line = finish(proc)
        prefix = "lockstep_tcp"
    return {
        **_loop_figures(prefix, "sim", run, steps, period_s),
        f"{prefix.replace('lockstep', 'sim')}_report": last_line,
    }


def pingpong_rtf(
    world_path: str, world: World, vehicle: Vehicle, seconds: float, physics: bool = False
) -> dict[str, Any]:
    """The reference: `simbridge.pingpong` with the same client, as many steps (keys
    `pingpong_*`); with `physics`, the ping-pong stepping the bare quadrotor loop after each
    reply (`pingpong_physics_*`)."""
    period_s = world.control_period_s
    steps = max(1, round(seconds / period_s))
    cmd = [sys.executable, "-m", "simbridge.pingpong", "--world", world_path]
    # one step more than timed: the first is answered before the clocks start (`_lockstep`)
    cmd += ["--altitude", str(BENCH_ALTITUDE_M), "--steps", str(steps + 1)]
    cmd += ["--physics"] if physics else []
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    line = proc.stdout.readline()
    if not line.startswith(LISTENING):
        proc.kill()
        raise SimProcessError(f"the ping-pong reference did not start: {line.strip()}")
    sock = connect("127.0.0.1", int(line.rsplit(":", 1)[1]))
    run = _lockstep(sock, steps, _hover_command(world, vehicle), proc.pid)
    report = finish(proc)
    prefix = "pingpong_physics" if physics else "pingpong"
    return {**_loop_figures(prefix, "server", run, steps, period_s), f"{prefix}_report": report}


def wake_latency(report: str) -> str:
    """What a simulator's or the reference's last line says of the CPU wake-up latency."""
    return next((part.strip() for part in report.split(";") if "wake-up latency" in part), "")


def bench_sim(
    world_name: str = "default", seconds: float = 20.0, repeat: int = 5
) -> dict[str, Any]:
    """Each figure and its reference `repeat` times, interleaved (the load of a shared machine
    drifts); medians, the ratio of the medians, and the load average over the run."""
    world = load_world(world_name)
    vehicle = load_vehicle(world.vehicle)
    path = str(resolve_world_path(world_name))
    load_before = os.getloadavg()[0]
    runs: dict[str, list[float]] = {}
    last: dict[str, Any] = {}
    for _ in range(repeat):
        for figure in (
            physics_rtf(world, vehicle, seconds),
            bare_loop_rtf(world, vehicle, seconds),
            lockstep_rtf(path, world, vehicle, seconds, transport.UNIX),
            pingpong_rtf(path, world, vehicle, seconds),
            lockstep_rtf(path, world, vehicle, seconds, transport.TCP),
            pingpong_rtf(path, world, vehicle, seconds, physics=True),
        ):
            last.update(figure)
            for key, value in figure.items():
                if isinstance(value, float):
                    runs.setdefault(key, []).append(value)
    result: dict[str, Any] = {
        "world": path,
        "effects": world.effects.names(),
        "physics_hz": world.physics_rate_hz,
        "control_hz": round(1.0 / world.control_period_s),
        "sim_s": seconds,
        "repeat": repeat,
        **{key: statistics.median(values) for key, values in runs.items()},
        "sim_report": last["sim_report"],
        "sim_tcp_report": last["sim_tcp_report"],
        "pingpong_report": last["pingpong_report"],
        "pingpong_physics_report": last["pingpong_physics_report"],
        # both lockstep loops ran with the same CPU wake-up latency (simbridge/cpu_latency.py)
        "cpu_wake_latency": wake_latency(last["sim_report"]),
        "physics_runs": runs["physics_rtf"],
        "lockstep_runs": runs["lockstep_rtf"],
        "lockstep_tcp_runs": runs["lockstep_tcp_rtf"],
        "pingpong_runs": runs["pingpong_rtf"],
        "pingpong_physics_runs": runs["pingpong_physics_rtf"],
    }
    result["physics_ratio"] = result["physics_rtf"] / result["bare_loop_rtf"]
    result["lockstep_ratio"] = result["lockstep_rtf"] / result["pingpong_rtf"]
    result["lockstep_tcp_ratio"] = result["lockstep_tcp_rtf"] / result["pingpong_rtf"]
    result["lockstep_physics_ratio"] = result["lockstep_rtf"] / result["pingpong_physics_rtf"]
    result["load_average"] = (load_before, os.getloadavg()[0])
    return result
