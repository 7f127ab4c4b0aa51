"""Flights for the gap diagnosis: seeded missions, "real" flights flown through `fly` in a
world holding effects the diagnosis is not told (written as noisy logs, cached), and the
closed-loop replays of held-out missions in the nominal and corrected worlds."""

from __future__ import annotations

import dataclasses
import math
import random
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from learner.flightlogs.flightlog import FlightLog, add_noise, write_log
from learner.flightlogs.readers import read_log
from mission.fly import fly
from simbridge.vehicle import Vehicle, load_vehicle

# The documented sensor noise of bench logs (standard deviations, white): a motion-capture
# pose, an IMU and ESC speed readings of a nano quadrotor.
BENCH_NOISE: dict[str, float] = {
    "position_m": 0.001,
    "velocity_m_s": 0.01,
    "attitude_rad": 0.003,
    "rates_rad_s": 0.02,
    "rotor_rad_s": 0.0,  # commands: the autopilot knows what it sent
    "accel_m_s2": 0.1,
}
# A bench mission lasts 15-30 simulated seconds; one still flying after this failed (it is a
# figure of the bench, not a hang) unless it was landing: in a ground effect much stronger
# than the autopilot's model, the vehicle sinks ever slower onto a cushion a few mm above its
# touchdown height (rho 2.5 against the model's 1: 21 mm after 75 s of landing).
MAX_FLIGHT_S = 60.0
KINDS = ("mixed", "hover", "aggressive", "wall", "ceiling", "passes", "pad")
# `passes`: low passes along x (fitting seeds, under 100) or along y (held-out seeds), at
# these speeds and this height; `pad`: low holds and the landing over the pad (seeds 0 and
# 100) or away from it (other seeds)
PASS_SPEEDS_M_S = (0.3, 0.8, 1.5)
PASS_HEIGHT_M = 0.06
PASS_REACH_M = 1.5
PAD_XY_M = (0.8, 0.0)
PAD_SEEDS = (0, 100)
# Identification flights climb and descend faster than a cautious default: the rotor drag's
# vertical coefficient is seen only through vertical speed, which legs cruising at nearly
# one height hardly have (0.09 m/s RMS). The limits clip the position loop's error at speed
# x lead (1 s), so moves shorter than that are the loop's plain step.
VERTICAL_SPEED_M_S = 1.0
AUTOPILOT_PARAMS: tuple[str, ...] = (
    f"MPC_Z_V_AUTO_UP={VERTICAL_SPEED_M_S}",
    f"MPC_Z_V_AUTO_DN={VERTICAL_SPEED_M_S}",
)
# Vertical legs of `mixed` and `aggressive` flights: from the last cruising waypoint down to
# the low height, up to the high one, twice (1 m steps peak near 0.8 m/s), then on to the
# low pass. Both heights well clear of the ground's and a 3 m ceiling's reach.
VERTICAL_LEG_HEIGHTS_M = (0.25, 1.25, 0.25, 1.25)
# Where a flight lingers by a surface whose effect it should measure, in rotor radii of the
# reference vehicle (0.047 m): close enough for a force of a few mN at the catalogue's
# typical strength, far enough that the effect's pull (the ceiling's rising as the gap
# closes, a wall's towards it) stays well below the position loop's stiffness.
WALL_HOLD_RADII = 2.1
CEILING_HOLD_RADII = 3.0
REFERENCE_ROTOR_RADIUS_M = 0.047
SURFACE_HOLD_S = 3.0


# Heights a vehicle's body must keep clear of the ground: a slow, level hold its resting
# height and HOLD_CLEARANCE_M more; a leg flown tilted up to LEG_TILT_DEG its lowest corner
# LEG_CLEARANCE_M above the ground. Below the reference vehicles' heights (nano, Crazyflies:
# their missions unchanged); a 600 mm frame's raised.
HOLD_CLEARANCE_M = 0.02
LEG_TILT_DEG = 30.0
LEG_CLEARANCE_M = 0.05


def height_floors_m(vehicle: Vehicle) -> tuple[float, float]:
    """(a level hold's, a tilted leg's) lowest height of the centre of mass for `vehicle`."""
    half_height = vehicle.body_size_m[2] / 2.0
    half_diagonal = math.hypot(vehicle.body_size_m[0], vehicle.body_size_m[1]) / 2.0
    tilt = math.radians(LEG_TILT_DEG)
    leg = half_height * math.cos(tilt) + half_diagonal * math.sin(tilt) + LEG_CLEARANCE_M
    return half_height + HOLD_CLEARANCE_M, leg


def bench_mission(
    kind: str, seed: int, ceiling_m: float | None = None, vehicle: Vehicle | None = None
) -> dict[str, Any]:
    """A short seeded mission. `mixed`: cruising at 1 m/s at several heights, vertical legs
    and a low pass at 4 cm; `hover`: holds at 0.5 m and 6 cm; `aggressive`: long legs at
    2.5 m/s, then the same vertical legs; `wall`: like mixed without the vertical legs,
    holding close to a wall at y = 0.6 m; `ceiling`: like `wall`, holding under the ceiling
    at `ceiling_m` (required) instead. `vehicle` (default the nano): heights raised where
    its body would meet the ground (`height_floors_m`)."""
    mission = _bench_mission(kind, seed, ceiling_m)
    hold_floor, leg_floor = height_floors_m(vehicle or load_vehicle("nano"))
    for wp in mission["waypoints"]:
        slow = wp.get("acceptance_radius_m", 1.0) <= 0.03 or wp.get("hold_s", 0.0) > 0.0
        floor = hold_floor if slow else leg_floor
        wp["position_m"][2] = max(wp["position_m"][2], floor)
    return mission


def _bench_mission(kind: str, seed: int, ceiling_m: float | None) -> dict[str, Any]:
    if kind not in KINDS:
        raise ValueError(f"mission kind {kind!r}: expected one of {', '.join(KINDS)}")
    if kind == "ceiling" and ceiling_m is None:
        raise ValueError("mission kind 'ceiling': ceiling_m (the ceiling's height) is required")
    rng = random.Random(f"{kind}-{seed}")
    if kind in ("passes", "pad"):
        return _low_mission(kind, seed, rng)
    if kind == "hover":
        x, y = rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3)
        wps = [
            {"position_m": [x, y, 0.5], "hold_s": 3.0},
            {"position_m": [x, y, 0.06], "hold_s": 2.0, "acceptance_radius_m": 0.02,
             "timeout_s": 4.0},
        ]  # fmt: skip
        return {"name": f"hover {seed}", "takeoff_altitude_m": 0.5, "waypoints": wps, "land": True}
    # the position loop's speed is about half the distance to go: far waypoints, passed
    # through with a wide acceptance radius, keep it cruising
    reach, speed, accept = (2.5, 3.0, 0.6) if kind == "aggressive" else (1.5, 1.5, 0.4)
    wps = []
    for i in range(3):
        sign = 1.0 if i % 2 == 0 else -1.0
        wps.append(
            {
                "position_m": [
                    sign * rng.uniform(0.5 * reach, reach),
                    rng.uniform(-reach, reach),
                    rng.uniform(0.25, 0.8),
                ],
                "hold_s": 0.0,
                "acceptance_radius_m": accept,
                "speed_m_s": speed,
            }
        )
    if kind == "wall":  # the wall stands at y = 0.6 m: every other waypoint on this side
        for wp in wps:
            wp["position_m"][1] = min(wp["position_m"][1], 0.3)
        wall_y = 0.6 - WALL_HOLD_RADII * REFERENCE_ROTOR_RADIUS_M
        wps[1] = _surface_hold([rng.uniform(-0.5, 0.5), wall_y, 0.5])
    if kind == "ceiling" and ceiling_m is not None:
        ceiling_z = ceiling_m - CEILING_HOLD_RADII * REFERENCE_ROTOR_RADIUS_M
        for wp in wps:  # cruising legs stay below the hold
            wp["position_m"][2] = min(wp["position_m"][2], ceiling_z)
        wps.insert(2, _surface_hold([*wps[1]["position_m"][:2], ceiling_z]))
    if kind in ("mixed", "aggressive"):
        x, y = wps[-1]["position_m"][:2]
        wps += [
            {"position_m": [x, y, z], "hold_s": 0.0, "acceptance_radius_m": 0.15}
            for z in VERTICAL_LEG_HEIGHTS_M
        ]
    x, y = rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3)
    wps.append(
        {"position_m": [x, y, 0.04], "hold_s": 1.0, "acceptance_radius_m": 0.02, "timeout_s": 3.0}
    )
    return {"name": f"{kind} {seed}", "takeoff_altitude_m": 0.3, "waypoints": wps, "land": True}


def _low_mission(kind: str, seed: int, rng: random.Random) -> dict[str, Any]:
    """`passes`: back and forth at PASS_HEIGHT_M along one axis at each of PASS_SPEEDS_M_S,
    a hold at each end; `pad`: holds low at four points about a place, on the pad for
    PAD_SEEDS, then the landing there."""
    low = PASS_HEIGHT_M
    if kind == "passes":
        axis = 0 if seed < 100 else 1
        wps = []
        for i, speed in enumerate(PASS_SPEEDS_M_S):
            end = [0.0, 0.0, low]
            end[axis] = PASS_REACH_M if i % 2 == 0 else -PASS_REACH_M
            end[1 - axis] = rng.uniform(-0.2, 0.2)
            wps.append({"position_m": end, "hold_s": 1.0, "acceptance_radius_m": 0.05,
                        "timeout_s": 8.0, "speed_m_s": speed})  # fmt: skip
    else:
        cx, cy = PAD_XY_M if seed in PAD_SEEDS else (-PAD_XY_M[0], PAD_XY_M[1])
        wps = []
        for _ in range(4):
            x, y = cx + rng.uniform(-0.15, 0.15), cy + rng.uniform(-0.15, 0.15)
            wps.append({"position_m": [x, y, 0.4], "hold_s": 0.0, "acceptance_radius_m": 0.1})
            wps.append({"position_m": [x, y, low], "hold_s": 1.5, "acceptance_radius_m": 0.02,
                        "timeout_s": 4.0, "speed_m_s": 0.5})  # fmt: skip
        wps.append({"position_m": [cx, cy, low], "hold_s": 0.5, "acceptance_radius_m": 0.02,
                    "timeout_s": 4.0})  # fmt: skip
    return {"name": f"{kind} {seed}", "takeoff_altitude_m": 0.3, "waypoints": wps, "land": True}


def _surface_hold(position_m: list[float]) -> dict[str, Any]:
    """A slow approach to `position_m` and a hold there (timed out if an effect holds the
    vehicle off it)."""
    return {"position_m": position_m, "hold_s": SURFACE_HOLD_S, "acceptance_radius_m": 0.03,
            "timeout_s": 4.0, "speed_m_s": 0.5}  # fmt: skip


def fly_log(
    mission: dict[str, Any] | Path,
    world: Path,
    out: Path,
    model: str = "analytic",
    max_flight_s: float = MAX_FLIGHT_S,
    record: bool = False,
    params: tuple[str, ...] = AUTOPILOT_PARAMS,
) -> Path:
    """Fly `mission` in `world` through `fly` (simulator and autopilot processes in lockstep,
    the autopilot arming by itself) and keep its flight log at `out` (reused if present);
    `record`: its rerun recording too, beside it (.rrd). The sensors are ideal: the bench
    scores how the diagnosis names a withheld physical effect, and a noisy, biased IMU
    would be one more effect in every flight (the catalogue's sensor_bias and
    sensor_latency are withheld as effects of their own). `params`: the autopilot's
    parameters (NAME=VALUE), the bench's by default."""
    if out.exists():
        return out
    out.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(mission, Path):
        path = mission
    else:
        path = out.with_suffix(".mission.yaml")
        path.write_text(yaml.safe_dump(mission))
    raw, track = out.with_suffix(".clean.csv"), out.with_suffix(".track.npz")
    summary = fly(path, str(world), model, rho=1.0, via_gcs=False, flight_log=raw,
                  record=out.with_suffix(".rrd") if record else False,
                  max_flight_s=max_flight_s, trajectory=track,
                  autopilot_options=[a for p in params for a in ("--param", p)],
                  sim_options=["--ideal-sensors"])  # fmt: skip
    if not summary.get("landed") and not _ended_landing(track):
        raise RuntimeError(f"{out.name}: the flight did not land ({summary.get('ended')})")
    if not raw.exists():
        raise RuntimeError(f"{out.name}: the flight wrote no log ({summary.get('ended')})")
    raw.replace(out)
    out.with_suffix(".clean.json").replace(out.with_suffix(".json"))
    return out


def _ended_landing(track: Path) -> bool:
    """The flight's last step was in the landing phase (its trajectory file)."""
    import numpy as np

    from autopilot.summary import MODES

    if not track.exists():
        return False
    with np.load(track) as data:
        columns, log = list(data["columns"]), data["log"]
    return len(log) > 0 and log[-1, columns.index("mode")] == MODES.index("landing")


def real_log(
    mission: dict[str, Any],
    world: Path,
    out: Path,
    noise: dict[str, float],
    seed: int,
    record: bool = False,
) -> Path:
    """A "real" flight: flown in the withheld world, written with sensor noise; cached. The
    clean flight is kept beside it (.truth.csv; `record`: also .truth.rrd)."""
    if out.exists():
        return out
    clean = fly_log(mission, world, out.with_suffix(".truth.csv"), record=record)
    log = read_log(clean)
    noisy: FlightLog = add_noise(log, noise, seed)
    return write_log(noisy, out)


def cut_log(path: Path, seconds: float, out: Path) -> Path:
    """The log at `path` cut to `seconds` about its middle (where the vehicle is in the air),
    as a user would bring a log that stopped early."""
    log = read_log(path)
    middle = 0.5 * (log.time_s[0] + log.time_s[-1])
    keep = np.abs(log.time_s - middle) <= 0.5 * seconds
    rows = {
        f.name: getattr(log, f.name)[keep]
        for f in dataclasses.fields(log)
        if isinstance(getattr(log, f.name), np.ndarray)
    }
    return write_log(dataclasses.replace(log, **rows), out)


def replay_params(meta: dict[str, Any]) -> tuple[str, ...]:
    """The autopilot parameters a replay of a log flies: those its flight set apart from the
    defaults, where the log carries them (groundfx's recordings), but the ground model and
    online learning (the replay's own: the analytic model at rho 1); else the bench's."""
    from autopilot.params import BEFORE_ADDED, SPECS, float32

    logged = meta.get("parameters")
    if not isinstance(logged, dict):
        return AUTOPILOT_PARAMS
    # a recording from before a parameter existed flew as its old value does
    logged = {**BEFORE_ADDED, **logged}
    own = ("model", "online", "online_settings")
    return tuple(
        f"{name}={float(value):g}"  # recorded as REAL32: compared as the link carries them
        for name, value in sorted(logged.items())
        if name in SPECS
        and SPECS[name].group not in own
        and float32(float(value)) != float32(SPECS[name].default)
    )


def replay_flight(
    mission: str,
    world: str,
    path: str,
    max_flight_s: float,
    params: tuple[str, ...] = AUTOPILOT_PARAMS,
) -> dict[str, Any]:
    """One replay of a diagnosis (a task of the campaign runner): the flight's log at `path`.
    Here, not beside the diagnosis: a worker that only flies imports no fitting or network."""
    fly_log(Path(mission), Path(world), Path(path), max_flight_s=max_flight_s, params=params)
    return {"path": path}
