"""One log prepared for the force model: mid-period attitude and velocity, acceleration,
rotor commands and the distances to the nominal world's surfaces, as arrays; rows in contact
with a surface and airborne stretches too short to smooth left out, and counted."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.signal import savgol_filter

from learner.flightlogs.flightlog import FlightLog
from learner.gap.geometry import distance_above_m, height_below_m, wall_distances_m
from simbridge import frames
from simbridge.effects.proximity import WallEffectParams
from simbridge.vehicle import GRAVITY_M_S2, Vehicle
from simbridge.world import World

# Rows further apart than this many control periods start a new segment (airborne spells).
GAP_PERIODS = 1.5
SMOOTH_S = 0.1  # Savitzky-Golay window for acceleration from velocity


@dataclass(frozen=True)
class FlightData:
    name: str
    time_s: np.ndarray  # (N,)
    dt_s: float  # control period (median row spacing)
    segment: np.ndarray  # (N,) index of the airborne spell each row belongs to
    position_m: np.ndarray  # (N, 3) at the row's time
    velocity_m_s: np.ndarray  # (N, 3) mean over the period
    velocity_at_m_s: np.ndarray  # (N, 3) at the row's time
    rotation: np.ndarray  # (N, 3, 3) body to world, mid-period
    rates_rad_s: np.ndarray  # (N, 3)
    commands_rad_s: np.ndarray  # (N, 4) over the period
    acceleration_m_s2: np.ndarray  # (N, 3) kinematic, world
    measured_acceleration: bool  # False: differentiated from velocity
    rotor_heights_m: np.ndarray  # (N, 4) down from each hub
    rotor_ceilings_m: np.ndarray  # (N, 4) up from each hub
    wall_distances_m: np.ndarray  # (N, 4) along +x, -x, +y, -y
    height_m: np.ndarray  # (N,) centre of mass above the surface below (inf: none)
    substeps: int  # physics steps per control period (motor lag)
    meta: dict
    left_out: dict = dataclasses.field(default_factory=dict)  # rows left out, counted


def every_nth(d: FlightData, step: int) -> FlightData:
    """Every `step`-th row of `d` (each still one control period): the rows a fit scores, for
    the effects whose force at a row depends on that row alone."""
    n = len(d.time_s)
    rows = {
        f.name: getattr(d, f.name)[::step]
        for f in dataclasses.fields(d)
        if isinstance(getattr(d, f.name), np.ndarray) and len(getattr(d, f.name)) == n
    }
    return dataclasses.replace(d, **rows)


def quat_to_matrices(q: np.ndarray) -> np.ndarray:
    """(N, 4) w, x, y, z -> (N, 3, 3) rotation matrices, the quaternions normalised first."""
    return frames.quat_to_matrices(q / np.linalg.norm(q, axis=1, keepdims=True))


def _previous(a: np.ndarray, new_segment: np.ndarray) -> np.ndarray:
    """Each row's predecessor within its segment (itself at a segment's start)."""
    prev = np.concatenate([a[:1], a[:-1]])
    prev[new_segment] = a[new_segment]
    return prev


def differentiate(t: np.ndarray, v: np.ndarray, segment: np.ndarray, dt_s: float) -> np.ndarray:
    """Acceleration from velocity: a Savitzky-Golay derivative per segment."""
    out = np.zeros_like(v)
    window = max(5, round(SMOOTH_S / dt_s) | 1)
    for s in np.unique(segment):
        idx = np.flatnonzero(segment == s)
        if len(idx) >= window:
            out[idx] = savgol_filter(v[idx], window, 2, deriv=1, delta=dt_s, axis=0)
        elif len(idx) > 1:
            out[idx] = np.gradient(v[idx], t[idx], axis=0)
    return out


def as_differentiated(force: np.ndarray, d: FlightData) -> np.ndarray:
    """A row-wise force (each row's over the period ending at its time) as an acceleration
    differentiated from the log's velocity sees it: summed over the periods into a velocity,
    then the same Savitzky-Golay derivative (`differentiate`). Compared unfiltered, the
    derivative's smoothing stays in the residual, and a motor lag (8.5 ms) and a flatter
    thrust curve (gamma 0.95) were fitted where the world had none."""
    dt = np.diff(d.time_s, prepend=d.time_s[0])
    dt[np.concatenate([[True], d.segment[1:] != d.segment[:-1]])] = 0.0
    velocity = np.empty_like(force)
    for s in np.unique(d.segment):
        idx = np.flatnonzero(d.segment == s)
        velocity[idx] = np.cumsum(force[idx] * dt[idx, None], axis=0)
    return differentiate(d.time_s, velocity, d.segment, d.dt_s)


def smooth_positions(p: np.ndarray, segment: np.ndarray, dt_s: float) -> np.ndarray:
    """Positions through a quadratic Savitzky-Golay filter of SMOOTH_S per segment."""
    out = p.copy()
    window = max(5, round(SMOOTH_S / dt_s) | 1)
    for s in np.unique(segment):
        idx = np.flatnonzero(segment == s)
        if len(idx) >= window:
            out[idx] = savgol_filter(p[idx], window, 2, axis=0)
    return out


CONTACT_MARGIN_M = 0.005  # closer than this to a wall or the ceiling: touching it
# Closer than this to the surface below (smoothed position): touching it. Tighter than the
# sideways margin: a landing over a strong ground effect sinks slowly through the last few
# millimetres while airborne (the bench's lowest airborne row is 2.3 mm off), and those rows
# carry the effect's strongest signal; resting rows sit at 0 (+- a smoothed 1 mm noise).
CONTACT_BELOW_M = 0.002
# An airborne stretch must be at least this long: twice the smoothing windows (acceleration
# and force gap, 0.1 s), so that its middle is averaged over airborne rows only. Shorter ones
# are a touchdown bounce or a few rows between contacts, whose forces are contact forces.
MIN_STRETCH_S = 0.2


def _body_corners_m(log: FlightLog, vehicle: Vehicle) -> np.ndarray:
    """(N, 4, 3) the four bottom corners of the body box in the world, from positions
    smoothed as for the surface distances (white position noise would flicker in and out
    of contact)."""
    hx, hy, hz = np.asarray(vehicle.body_size_m) / 2.0
    corners = np.array([[sx * hx, sy * hy, -hz] for sx in (1, -1) for sy in (1, -1)])
    rotation = quat_to_matrices(log.quaternion)
    t = log.time_s
    p = log.position_m
    if len(t) > 1:
        dt = float(np.median(np.diff(t)))
        segment = np.cumsum(np.concatenate([[True], np.diff(t) > GAP_PERIODS * dt])) - 1
        p = smooth_positions(p, segment, dt)
    return p[:, None, :] + np.einsum("nij,kj->nki", rotation, corners)


def touching(log: FlightLog, world: World, vehicle: Vehicle) -> np.ndarray:
    """Rows where the body touches a surface: the ground, a box top or step under any corner
    of the body, a wall, the ceiling. Contact forces no aerodynamic effect explains (and a
    strong wall or ceiling effect pulls the vehicle into contact)."""
    half = np.asarray(vehicle.body_size_m) / 2.0
    walls = wall_distances_m(log.position_m, world.obstacles, 1.0)
    out = np.min(walls, axis=1) < max(half[0], half[1]) + CONTACT_MARGIN_M
    if world.ceiling_height_m is not None:
        out |= log.position_m[:, 2] + half[2] + CONTACT_MARGIN_M > world.ceiling_height_m
    # the surface below each corner, looked for from a little above it: a corner that noise
    # (or rounding) puts just inside a box top or the ground still finds that surface
    lift = np.array([0.0, 0.0, CONTACT_MARGIN_M])
    corners = _body_corners_m(log, vehicle).reshape(-1, 3) + lift
    below = height_below_m(corners, world.obstacles, 1.0).reshape(-1, 4) - CONTACT_MARGIN_M
    sunk = corners[:, 2].reshape(-1, 4) - CONTACT_MARGIN_M < CONTACT_BELOW_M  # into the ground
    out |= np.any((below < CONTACT_BELOW_M) | sunk, axis=1)
    return out


# A specific force beyond this many times the rotors' full thrust per mass is an impact (a
# crash, a hard landing): no force of the air reaches it (the nano's rotors give 3.4
# weights; the gap bench's strongest ground effect takes a flight to 1.3 times that).
IMPACT_THRUSTS = 3.0
IMPACT_GUARD_ROWS = 2  # either side of an impact: differentiation and smoothing spread it


def _kinematic_acceleration(log: FlightLog) -> np.ndarray:
    """The logged acceleration, else the velocity's raw derivative (enough for the coarse
    thresholds of a crash or a standstill; the fits use `differentiate`)."""
    a = log.acceleration_m_s2
    return np.gradient(log.velocity_m_s, log.time_s, axis=0) if a is None else a


def crashing(log: FlightLog, vehicle: Vehicle) -> np.ndarray:
    """Rows of a crash: the body upside down (its z axis below the horizon: no multirotor
    flies so), or an impact (a specific force beyond IMPACT_THRUSTS times the rotors' full
    thrust per mass, with IMPACT_GUARD_ROWS either side). A flight that ends in a crash is
    diagnosed on its flight: one impact's rows (53 N on a 56 g vehicle) would outweigh the
    rest in every fit and leave each candidate explaining nothing."""
    rows = len(log.time_s)
    x, y = log.quaternion[:, 1], log.quaternion[:, 2]
    out = 1.0 - 2.0 * (x * x + y * y) < 0.0  # R[2, 2]: body z against world z
    if rows < 2:
        return out
    a = _kinematic_acceleration(log)
    full_thrust = 4.0 * vehicle.thrust_coefficient_n_s2 * vehicle.max_rotor_speed_rad_s**2
    limit = IMPACT_THRUSTS * full_thrust / vehicle.mass_kg
    impact = np.flatnonzero(np.linalg.norm(a + np.array([0.0, 0.0, GRAVITY_M_S2]), axis=1) > limit)
    for k in range(-IMPACT_GUARD_ROWS, IMPACT_GUARD_ROWS + 1):
        out[np.clip(impact + k, 0, rows - 1)] = True
    return out


# Rotors stopped (their nominal thrust below this share of the weight) and the body not
# accelerating (its kinematic acceleration below a quarter of g: the accelerometer reads the
# weight held up) for at least HELD_S: something holds it up (the ground under a log whose
# heights are off, a stand, a hand). In the air such a body falls: only drag could hold it,
# and below half its terminal speed drag carries at most a quarter of the weight, so the
# speed need only be below that (`held_speed_limit_m_s`), not at rest: an outdoor estimator's
# velocity wanders by a metre per second on the ground. That holds where the log's rotors
# carry the weight somewhere (its thrust is in the right units); in a log whose thrust never
# comes near the weight, only rest (below HELD_REST_SPEED_M_S) counts as standing, and a
# moving body is left to the plausibility check, which names the likely wrong units.
HELD_THRUST_SHARE = 0.05
HELD_REST_SPEED_M_S = 0.1
LIFTING_THRUST_SHARE = 0.5
HELD_ACCELERATION_M_S2 = 0.25 * GRAVITY_M_S2
HELD_S = 0.5
SEA_LEVEL_AIR_DENSITY_KG_M3 = 1.225
DISC_DRAG_COEFFICIENT = 1.4  # the rotor discs broadside to the flow: the most drag they give


def held_speed_limit_m_s(vehicle: Vehicle) -> float:
    """Half the lowest terminal speed the vehicle could fall at with its rotors stopped (its
    four rotor discs as the drag area)."""
    area_m2 = 4 * np.pi * vehicle.rotor_radius_m**2  # a quadrotor
    terminal = np.sqrt(
        2.0 * vehicle.weight_n / (SEA_LEVEL_AIR_DENSITY_KG_M3 * DISC_DRAG_COEFFICIENT * area_m2)
    )
    return 0.5 * float(terminal)


def held_up(log: FlightLog, vehicle: Vehicle) -> np.ndarray:
    """Rows standing with the rotors stopped: no aerodynamic effect acts there, and their
    full-weight residual would swamp every fit (a disarmed stretch of a PX4 log whose local
    frame does not put the ground at zero)."""
    rows = len(log.time_s)
    if rows < 2:
        return np.zeros(rows, bool)
    thrust_n = vehicle.thrust_coefficient_n_s2 * np.sum(log.rotor_speeds_rad_s**2, axis=1)
    a = _kinematic_acceleration(log)
    lifts = bool(np.any(thrust_n >= LIFTING_THRUST_SHARE * vehicle.weight_n))
    speed_limit = held_speed_limit_m_s(vehicle) if lifts else HELD_REST_SPEED_M_S
    candidate = (
        (thrust_n < HELD_THRUST_SHARE * vehicle.mass_kg * GRAVITY_M_S2)
        & (np.linalg.norm(log.velocity_m_s, axis=1) < speed_limit)
        & (np.linalg.norm(a, axis=1) < HELD_ACCELERATION_M_S2)
    )
    # runs of candidate rows lasting HELD_S
    edges = np.flatnonzero(np.diff(np.concatenate([[0], candidate.astype(int), [0]])))
    out = np.zeros(rows, bool)
    for start, end in zip(edges[::2], edges[1::2], strict=True):
        if log.time_s[end - 1] - log.time_s[start] >= HELD_S:
            out[start:end] = True
    return out


def short_stretches(t: np.ndarray, dt_s: float) -> np.ndarray:
    """Rows of airborne stretches shorter than MIN_STRETCH_S (or than the acceleration's
    smoothing window, at low rates): left out."""
    if len(t) == 0:
        return np.zeros(0, bool)
    new = np.concatenate([[True], np.diff(t) > GAP_PERIODS * dt_s])
    segment = np.cumsum(new) - 1
    sizes = np.bincount(segment)
    min_rows = max(int(np.ceil(MIN_STRETCH_S / dt_s - 1e-9)), max(5, round(SMOOTH_S / dt_s) | 1))
    return sizes[segment] < min_rows


def without_rows(log: FlightLog, drop: np.ndarray) -> FlightLog:
    keep = ~drop

    def k(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else a[keep]

    return dataclasses.replace(
        log, time_s=log.time_s[keep], position_m=log.position_m[keep],
        velocity_m_s=log.velocity_m_s[keep], quaternion=log.quaternion[keep],
        body_rates_rad_s=log.body_rates_rad_s[keep],
        rotor_speeds_rad_s=log.rotor_speeds_rad_s[keep],
        acceleration_m_s2=k(log.acceleration_m_s2), battery_v=k(log.battery_v),
    )  # fmt: skip


def leave_out(log: FlightLog, world: World, vehicle: Vehicle) -> tuple[FlightLog, dict]:
    """The log without rows in contact with a surface and without airborne stretches too
    short to smooth; what was left out, counted."""
    rows = len(log.time_s)
    dt = float(np.median(np.diff(log.time_s))) if rows > 1 else 0.0
    contact = touching(log, world, vehicle)
    held = held_up(log, vehicle) & ~contact
    crash = crashing(log, vehicle) & ~contact & ~held
    if contact.any() or crash.any() or held.any():  # the rows around them start new segments
        log = without_rows(log, contact | crash | held)
    short = short_stretches(log.time_s, dt) if dt > 0 else np.zeros(len(log.time_s), bool)
    if short.any():
        starts = np.concatenate([[True], np.diff(log.time_s) > GAP_PERIODS * dt])
        stretches = int(np.sum(starts & short))
        log = without_rows(log, short)
    else:
        stretches = 0
    counts = {
        "rows": rows,
        "contact_rows": int(contact.sum()),
        "crash_rows": int(crash.sum()),
        "held_rows": int(held.sum()),
        "short_stretches": stretches,
        "short_rows": int(short.sum()),
        "min_stretch_s": MIN_STRETCH_S,
    }
    return log, counts


def describe_left_out(counts: dict) -> str:
    """'left out: 3 stretches shorter than 0.2 s (41 rows), 120 rows in contact with a
    surface (...)'."""
    parts = []
    if counts.get("short_stretches"):
        parts.append(
            f"{counts['short_stretches']} stretches shorter than {counts['min_stretch_s']:g} s "
            f"({counts['short_rows']} rows)"
        )
    if counts.get("contact_rows"):
        parts.append(
            f"{counts['contact_rows']} rows in contact with a surface (the body within "
            f"{CONTACT_BELOW_M * 1000:g} mm of the surface below it or "
            f"{CONTACT_MARGIN_M * 1000:g} mm of a wall or the ceiling)"
        )
    if counts.get("held_rows"):
        parts.append(
            f"{counts['held_rows']} rows standing with the rotors stopped (their thrust below "
            f"{HELD_THRUST_SHARE:.0%} of the weight, not falling for {HELD_S:g} s or more: on "
            f"the ground, or held)"
        )
    if counts.get("crash_rows"):
        parts.append(
            f"{counts['crash_rows']} rows of a crash (the body upside down, or an impact: a "
            f"specific force beyond {IMPACT_THRUSTS:g} times the rotors' full thrust)"
        )
    return "left out: " + (", ".join(parts) if parts else "nothing")


def prepare(log: FlightLog, world: World, vehicle: Vehicle) -> FlightData:
    raw_rows = len(log.time_s)
    log, left_out = leave_out(log, world, vehicle)
    t = log.time_s
    if len(t) < 10:
        raise ValueError(
            f"{log.name}: only {len(t)} of {raw_rows} rows are airborne and usable "
            f"({describe_left_out(left_out)}); a flight log needs at least 10"
        )
    dt = float(np.median(np.diff(t)))
    new_segment = np.concatenate([[True], np.diff(t) > GAP_PERIODS * dt])
    segment = np.cumsum(new_segment) - 1
    q_prev = _previous(log.quaternion, new_segment)
    # q and -q are one attitude: align before averaging
    sign = np.sign(np.sum(q_prev * log.quaternion, axis=1))[:, None]
    rotation = quat_to_matrices(q_prev * np.where(sign == 0, 1, sign) + log.quaternion)
    v_mid = 0.5 * (_previous(log.velocity_m_s, new_segment) + log.velocity_m_s)
    # distances to surfaces from a smoothed position: the ground effect is steep in height
    # (1 / z^2), so white position noise near the ground biases it (errors in variables)
    smooth_p = smooth_positions(log.position_m, segment, dt)
    p_mid = 0.5 * (_previous(smooth_p, new_segment) + smooth_p)
    measured = log.acceleration_m_s2 is not None
    acc = log.acceleration_m_s2 if measured else differentiate(t, log.velocity_m_s, segment, dt)
    hubs = p_mid[:, None, :] + np.einsum("nij,kj->nki", rotation, vehicle.rotor_positions_body_m())
    flat = hubs.reshape(-1, 3)
    # the simulator clamps a command to the vehicle's [0, n_max]: so does its model here (a
    # Crazyflie's logged motor.f asks up to 1.7 times what its rotors give)
    n_max = vehicle.max_rotor_speed_rad_s
    commands = log.rotor_speeds_rad_s
    beyond = np.any(commands > n_max, axis=1)
    if beyond.any():
        commands = np.minimum(commands, n_max)
    left_out = {**left_out, "clamped_rows": int(beyond.sum())}
    fx = world.effects
    down = fx.ground_effect.ray_length_m if fx.ground_effect else 3.0
    up = fx.ceiling_effect.ray_length_m if fx.ceiling_effect else 3.0
    wall = fx.wall_effect or WallEffectParams()
    return FlightData(
        name=log.name,
        time_s=t,
        dt_s=dt,
        segment=segment,
        position_m=log.position_m,
        velocity_m_s=v_mid,
        velocity_at_m_s=log.velocity_m_s,
        rotation=rotation,
        rates_rad_s=log.body_rates_rad_s,
        commands_rad_s=commands,
        acceleration_m_s2=acc,
        measured_acceleration=measured,
        rotor_heights_m=height_below_m(flat, world.obstacles, down).reshape(-1, 4),
        rotor_ceilings_m=distance_above_m(flat, world.ceiling_height_m, up).reshape(-1, 4),
        wall_distances_m=wall_distances_m(p_mid, world.obstacles, wall.range_m),
        height_m=height_below_m(p_mid, world.obstacles, down),
        substeps=max(1, round(dt * world.physics_rate_hz)),
        meta=log.meta,
        left_out=left_out,
    )
