"""The lockstep benchmark's reference: a plain pymavlink ping-pong of the same messages.

`python -m simbridge.pingpong --world W --steps N` serves N steps the way a simulator
written with pymavlink would: its own connection (`mavutil`, `tcpin:`), and each step the
very messages our simulator sends for such a step (taken from a short flight of the real
encoder beforehand, then cycled) sent with `mav.send`, then the client's
HIL_ACTUATOR_CONTROLS awaited with `recv_match`. No physics, no sensors: what the wire and
pymavlink cost. With `--physics`, a pymavlink simulator with physics: after each reply it
steps the simulator's body by the bare quadrotor loop (simbridge/bare_loop.py, the physics
figure's reference) for a control period, as our simulator steps its own physics between a
reply and the next tick. `groundfx bench sim` runs the same minimal client against all. It
holds the same CPU wake-up latency request as the simulator does at full speed
(simbridge/cpu_latency.py), so that the reference and the measured loop wake up alike.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from typing import Any

from pymavlink import mavutil

from simbridge.bare_loop import BareQuadrotor
from simbridge.cpu_latency import CpuLatencyRequest
from simbridge.hil import HilEncoder, mavlink
from simbridge.physics import Simulation
from simbridge.vehicle import Vehicle, load_vehicle
from simbridge.world import World, load_world, with_start

SAMPLE_STEPS = 250  # one simulated second: every message rate's pattern repeats within it
LISTENING = "groundfx pingpong: listening on tcp:"


def sample_steps(world: World, vehicle: Vehicle) -> list[list[Any]]:
    """Each step's messages (pymavlink objects) of the real encoder, the vehicle hovering
    where `world` starts it, on its hover rotor speed."""
    encoder = HilEncoder(world, vehicle)
    parser = mavlink.MAVLink(None)
    n = vehicle.hover_rotor_speed_rad_s
    steps = []
    with Simulation(world, vehicle) as sim:
        for _ in range(SAMPLE_STEPS):
            sim.step((n, n, n, n))
            data = encoder.encode(sim.state(), sim.time_us, sim.ground_effect_n)
            steps.append(list(parser.parse_buffer(data) or ()))
    return steps


def serve(
    conn: Any,
    steps: list[list[Any]],
    count: int,
    timeout_s: float,
    physics: Callable[[], None] | None = None,
) -> int:
    """`count` steps (fewer if the client stops answering), `physics` (if any) run after each
    reply; returns the steps served."""
    for served in range(count):
        for m in steps[served % len(steps)]:
            conn.mav.send(m)
        if conn.recv_match(type="HIL_ACTUATOR_CONTROLS", blocking=True, timeout=timeout_s) is None:
            return served
        if physics is not None:
            physics()
    return count


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m simbridge.pingpong", description=__doc__)
    p.add_argument("--world", default="default")
    p.add_argument("--steps", type=int, required=True, help="steps to serve")
    p.add_argument("--altitude", type=float, default=0.1, help="hover height of the sample, m")
    p.add_argument(
        "--physics",
        action="store_true",
        help="step the bare quadrotor loop for a control period after each reply",
    )
    p.add_argument(
        "--low-latency-idle",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="hold the CPU wake-up latency request while serving, as `groundfx sim` does",
    )
    args = p.parse_args(argv)
    world = with_start(load_world(args.world), (0.0, 0.0, args.altitude))
    vehicle = load_vehicle(world.vehicle)
    steps = sample_steps(world, vehicle)
    if not args.physics:
        return _serve_client(args, steps, None)
    with Simulation(world, vehicle) as sim:
        bare, substeps = BareQuadrotor(sim, vehicle), world.substeps
        return _serve_client(args, steps, lambda: bare.run(substeps))


def _serve_client(
    args: argparse.Namespace, steps: list[list[Any]], physics: Callable[[], None] | None
) -> int:
    conn = mavutil.mavlink_connection("tcpin:127.0.0.1:0", source_system=1, source_component=200)
    print(f"{LISTENING}127.0.0.1:{conn.listen.getsockname()[1]}", flush=True)
    while conn.port is None:  # mavutil accepts in recv, and drops what is sent before
        conn.select(0.05)
        conn.recv()
    with CpuLatencyRequest(0, not_asked="" if args.low_latency_idle else "declined") as request:
        t0 = time.perf_counter()
        served = serve(conn, steps, args.steps, timeout_s=10.0, physics=physics)
        wall = time.perf_counter() - t0
    conn.close()
    print(f"groundfx pingpong: {served} steps in {wall:.2f} s; {request.describe()}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
