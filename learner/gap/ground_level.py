"""Where a log's frame puts the ground: found from the vehicle resting on it.

A motion-capture frame's z = 0 is wherever its calibration put it, and a marker set's origin
sits wherever the markers are: the neural-swarm Crazyflies rest at a logged z of 49-61 mm,
where the simulator's box rests at half its height (14.5 mm). Heights above the ground drive
the ground effect (1 / z^2 near the ground), so a log read as if its z = 0 were the world's
floor puts every row 3-4 cm too high, and its rows on the ground (rotors off, at rest) as a
hover 5 cm up that no aerodynamic effect explains. A flight that rests on a surface (before
take-off, after landing) says where that surface is in its frame: the offset is the median
height of its resting rows less the simulator's resting height over the world's surface
below them, and every row's z is shifted by it.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from learner.flightlogs.flightlog import FlightLog
from learner.flightlogs.resting import resting_rows
from learner.gap.geometry import height_below_m
from simbridge.vehicle import Vehicle
from simbridge.world import World

# An offset within this of zero is the log's own noise and smoothing: nothing is shifted.
OFFSET_TOLERANCE_M = 0.003
WORLD_FRAME = "world"  # a log's meta `frame`: its z is the simulator world's


def resting_offset_m(log: FlightLog, world: World, vehicle: Vehicle) -> float | None:
    """How far above the simulator's resting height over the world's surface the log's
    resting rows sit (m); None when the flight never rests."""
    rest = resting_rows(log, vehicle)
    if not rest.any():
        return None
    p = log.position_m[rest]
    # the surface below each resting row, looked for from well above it
    probe = p + np.array([0.0, 0.0, 1.0])
    surface_z = probe[:, 2] - height_below_m(probe, world.obstacles, 10.0)
    resting_height_m = vehicle.body_size_m[2] / 2.0  # the simulator's box rests so
    return float(np.median(p[:, 2] - surface_z - resting_height_m))


def shifted(log: FlightLog, offset_m: float) -> FlightLog:
    position = log.position_m.copy()
    position[:, 2] -= offset_m
    return dataclasses.replace(log, position_m=position)


def level_logs(
    logs: list[FlightLog], world: World, vehicle: Vehicle, z_offset_m: float | None = None
) -> tuple[list[FlightLog], list[str], dict[str, float]]:
    """The logs with their z shifted to the world's ground, the notes saying so, and the
    offset applied to each (m). `z_offset_m` given: that offset for every log. Otherwise
    each log that rests is shifted by its own offset (when beyond OFFSET_TOLERANCE_M), and a
    log that never rests by the median of those that do: the logs of one diagnosis are one
    vehicle in one world, so in one frame."""
    if z_offset_m is not None:
        notes = [f"every log's z is shifted by {0.0 - z_offset_m * 1000:+.1f} mm (--z-offset)"]
        applied = {log.name: z_offset_m for log in logs}
        return [shifted(log, z_offset_m) for log in logs], notes, applied
    # a log that says its frame is the world's (groundfx's recordings and flight logs) is not
    # moved: a landing onto a strong ground effect floats millimetres above the ground and
    # reads as a rest there
    own_frame = {log.name for log in logs if log.meta.get("frame") == WORLD_FRAME}
    found = {
        log.name: resting_offset_m(log, world, vehicle) for log in logs if log.name not in own_frame
    }
    known = [v for v in found.values() if v is not None]
    if not known or all(abs(v) <= OFFSET_TOLERANCE_M for v in known):
        return logs, [], {}
    common = float(np.median(known))
    out, applied, said = [], {}, []
    for log in logs:
        if log.name in own_frame:
            out.append(log)
            continue
        own = found[log.name]
        offset = own if own is not None else common
        if abs(offset) <= OFFSET_TOLERANCE_M:
            out.append(log)
            continue
        out.append(shifted(log, offset))
        applied[log.name] = offset
        how = "where it rests" if own is not None else "the median of the flights that rest"
        said.append(f"{log.name} {-offset * 1000:+.1f} mm ({how})")
    notes = [
        "the logs' frame does not put the ground where the world has it: a vehicle resting "
        f"on it sits {vehicle.body_size_m[2] / 2 * 1000:.1f} mm above it in the simulator; "
        "z shifted: " + ", ".join(said) + " (--z-offset sets it)"
    ]
    return out, notes, applied
