"""`groundfx bench sim`: how fast the physics and the lockstep link run, in real-time factors."""

from __future__ import annotations

import time
from typing import Any

from simbridge.client import connect, constant, hover_fraction, run_lockstep
from simbridge.effects.ground import hover_rotor_speed_in_ground_effect_rad_s
from simbridge.launch import finish, start_sim
from simbridge.physics import Simulation
from simbridge.vehicle import Vehicle, load_vehicle
from simbridge.world import World, load_world, resolve_world_path, with_start

BENCH_ALTITUDE_M = 0.1  # deep enough in ground effect that every step evaluates it


def physics_rtf(world: World, vehicle: Vehicle, seconds: float) -> dict[str, float]:
    """Physics alone: the vehicle hovering in ground effect, stepped as fast as possible."""
    ge = world.effects.ground_effect
    n = vehicle.hover_rotor_speed_rad_s
    if ge is not None:
        n = hover_rotor_speed_in_ground_effect_rad_s(
            vehicle.weight_n,
            vehicle.thrust_coefficient_n_s2,
            BENCH_ALTITUDE_M,
            ge.rho,
            vehicle.rotor_radius_m,
            ge.cutoff_for(vehicle.rotor_radius_m),
        )
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


def lockstep_rtf(
    world_name: str, vehicle: Vehicle, control_period_s: float, seconds: float
) -> dict[str, Any]:
    """`groundfx sim` in its own process against a minimal pymavlink client, constant actuators."""
    proc, port = start_sim(world_name, speedup="max", start=f"0,0,{BENCH_ALTITUDE_M}")
    steps = max(1, round(seconds / control_period_s))
    command = constant(
        hover_fraction(vehicle.hover_rotor_speed_rad_s, vehicle.max_rotor_speed_rad_s)
    )
    sock = connect("127.0.0.1", port)
    try:
        t0 = time.perf_counter()
        run_lockstep(sock, steps, command)
        wall = time.perf_counter() - t0
    finally:
        sock.close()
    last_line = finish(proc)
    return {
        "lockstep_rtf": steps * control_period_s / wall,
        "lockstep_us_per_step": wall / steps * 1e6,
        "sim_report": last_line,
    }


def bench_sim(world_name: str = "default", seconds: float = 20.0) -> dict[str, Any]:
    world = load_world(world_name)
    vehicle = load_vehicle(world.vehicle)
    result: dict[str, Any] = {
        "world": str(resolve_world_path(world_name)),
        "effects": world.effects.names(),
        "physics_hz": world.physics_rate_hz,
        "control_hz": round(1.0 / world.control_period_s),
        "sim_s": seconds,
    }
    result.update(physics_rtf(world, vehicle, seconds))
    result.update(lockstep_rtf(world_name, vehicle, world.control_period_s, seconds))
    return result
