"""The lockstep benchmark's reference: a plain pymavlink ping-pong of the same messages.

`python -m simbridge.pingpong --world W` listens like `groundfx sim` and, for every step,
packs with pymavlink the very messages the simulator sends for such a step (taken from a
short flight of the real encoder beforehand, then cycled), sends them, and waits in a
blocking read for the client's HIL_ACTUATOR_CONTROLS, parsed with pymavlink. No physics,
no sensors: what the wire and pymavlink cost, the ceiling a lockstep simulator written
with pymavlink could reach. `groundfx bench sim` runs the same minimal client against both.
"""

from __future__ import annotations

import argparse
import socket
import sys
import time
from typing import Any

from simbridge.hil import HilEncoder, mavlink
from simbridge.physics import Simulation
from simbridge.vehicle import load_vehicle
from simbridge.world import load_world, with_start

SAMPLE_STEPS = 250  # one simulated second: every message rate's pattern repeats within it
LISTENING = "groundfx pingpong: listening on tcp:"


def sample_steps(world_name: str, altitude_m: float) -> list[list[Any]]:
    """Each step's messages (pymavlink objects) of the real encoder, the vehicle hovering at
    `altitude_m` on its hover rotor speed."""
    world = with_start(load_world(world_name), (0.0, 0.0, altitude_m))
    vehicle = load_vehicle(world.vehicle)
    encoder = HilEncoder(world, vehicle)
    parser = mavlink.MAVLink(None)
    n = vehicle.hover_rotor_speed_rad_s
    steps = []
    with Simulation(world, vehicle) as sim:
        for _ in range(SAMPLE_STEPS):
            sim.step((n, n, n, n))
            data = encoder.encode(sim.state(), sim.time_us, sim.effect_forces())
            steps.append(list(parser.parse_buffer(data) or ()))
    return steps


def serve(sock: socket.socket, steps: list[list[Any]]) -> int:
    """Until the client leaves: send a step's messages packed by pymavlink, wait for one
    HIL_ACTUATOR_CONTROLS. Returns the steps served."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=200)
    parser = mavlink.MAVLink(None)
    served = 0
    while True:
        buffer = b"".join(m.pack(mav) for m in steps[served % len(steps)])
        try:
            sock.sendall(buffer)
            answered = False
            while not answered:
                data = sock.recv(65536)
                if not data:
                    return served
                for m in parser.parse_buffer(data) or ():
                    answered |= m.get_type() == "HIL_ACTUATOR_CONTROLS"
        except OSError:
            return served
        served += 1


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m simbridge.pingpong", description=__doc__)
    p.add_argument("--world", default="default")
    p.add_argument("--altitude", type=float, default=0.1, help="hover height of the sample, m")
    args = p.parse_args(argv)
    steps = sample_steps(args.world, args.altitude)
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    listener.bind(("127.0.0.1", 0))
    listener.listen(1)
    print(f"{LISTENING}127.0.0.1:{listener.getsockname()[1]}", flush=True)
    conn, _ = listener.accept()
    conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    t0 = time.perf_counter()
    served = serve(conn, steps)
    wall = time.perf_counter() - t0
    conn.close()
    listener.close()
    print(f"groundfx pingpong: {served} steps in {wall:.2f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
