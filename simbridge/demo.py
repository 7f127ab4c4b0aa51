"""`groundfx demo` (until the autopilot lands): the simulator shows the ground effect.

A drone at 3 cm is released with its free-air hover rotor speed. `groundfx sim` runs as its
own process; a minimal lockstep client holds the rotor speeds and reads the sensors back
over MAVLink. Equation 3.4 predicts the upward acceleration; the accelerometer measures it.
"""

from __future__ import annotations

from pathlib import Path

from simbridge.client import ClientView, connect, constant, hover_fraction, run_lockstep
from simbridge.effects.ground import ground_effect_force_n
from simbridge.launch import finish, start_sim
from simbridge.plots import plot_ground_effect
from simbridge.vehicle import GRAVITY_M_S2, load_vehicle
from simbridge.world import load_world

START_ALTITUDE_M = 0.03


def run_demo(world_name: str, logs: Path, say=print) -> None:
    world = load_world(world_name)
    vehicle = load_vehicle(world.vehicle)
    ge = world.effects.ground_effect
    rho = ge.rho if ge else 0.0
    n = vehicle.hover_rotor_speed_rad_s
    thrust = vehicle.thrust_coefficient_n_s2 * n * n
    predicted = 0.0
    if ge:
        predicted = (
            4
            * ground_effect_force_n(
                thrust,
                START_ALTITUDE_M,
                rho,
                vehicle.rotor_radius_m,
                ge.cutoff_for(vehicle.rotor_radius_m),
            )
            / vehicle.mass_kg
        )
    say(
        f"groundfx demo: a {vehicle.mass_kg * 1000:.0f} g drone at "
        f"{START_ALTITUDE_M * 100:.0f} cm, "
        f"rotors at the free-air hover speed {n:.1f} rad/s, rho_sim = {rho:g}"
    )
    # the clock waits for the first command: on a busy machine the first steps would
    # otherwise run on the stand before it arrives, and the first row measure nothing
    proc, port = start_sim(
        world_name,
        speedup="max",
        start=f"0,0,{START_ALTITUDE_M}",
        lockstep_start=True,
        extra=["--ideal-sensors"],  # the physics shown as it is, not through a noisy IMU
    )
    sock = connect("127.0.0.1", port)
    command = constant(hover_fraction(n, vehicle.max_rotor_speed_rad_s))
    rows = []
    view = ClientView()
    try:
        # Two answers: the sensors of the first step (t = 4 ms) then arrive, holding the
        # acceleration over a step that began at 3 cm; then one row every 0.1 s.
        for answers in (2, 24, 25, 25, 25, 25, 25):
            run_lockstep(sock, answers, command, view)
            state, sensor = view.latest["HIL_STATE_QUATERNION"], view.latest["HIL_SENSOR"]
            rows.append(
                (
                    state.time_usec * 1e-6,
                    state.alt / 1000.0 - world.origin.alt_m,
                    -state.vz / 100.0,
                    -sensor.zacc - GRAVITY_M_S2,
                )
            )
    finally:
        sock.close()
    say(
        f"  equation 3.4 predicts {predicted:.3f} m/s^2 upward at {START_ALTITUDE_M} m; "
        f"the first row measures it"
    )
    say("  t [s]   altitude [m]   climb [m/s]   measured vertical accel [m/s^2]")
    for t, z, vz, az in rows:
        say(f"  {t:5.3f}   {z:12.4f}   {vz:11.2f}   {az:10.3f}")
    say(f"  simulator: {finish(proc)}")
    png = plot_ground_effect(vehicle, [0.5, 1.0, 2.0, 4.0], logs / "ground_effect.png")
    say(f"  ground effect against altitude for rho 0.5, 1, 2, 4: {png}")
