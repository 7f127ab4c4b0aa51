"""Offboard and guided setpoints: SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT read into one
target, and the setpoint the position loop flies towards it, as pure functions.

A target says, per axis, a position, a velocity or an acceleration (NaN: not controlled), as
the type mask allows: position where given (the velocity and acceleration given with it are
its feed-forward), else the velocity, integrated into a moving position, else the
acceleration, integrated twice; an axis with none holds where it was. Yaw, else yaw rate
(integrated), else the heading kept. What cannot be flown is refused with the reason:
accelerations as forces, a mask that leaves nothing to control, a frame the vehicle does not
know, values that are not finite or absurd.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from autopilot.types import Setpoint
from simbridge.frames import Vec3, geodetic_to_local
from simbridge.hil import mavlink as mav

NAN3 = (math.nan, math.nan, math.nan)
IGNORE_POSITION = (
    mav.POSITION_TARGET_TYPEMASK_X_IGNORE,
    mav.POSITION_TARGET_TYPEMASK_Y_IGNORE,
    mav.POSITION_TARGET_TYPEMASK_Z_IGNORE,
)
IGNORE_VELOCITY = (
    mav.POSITION_TARGET_TYPEMASK_VX_IGNORE,
    mav.POSITION_TARGET_TYPEMASK_VY_IGNORE,
    mav.POSITION_TARGET_TYPEMASK_VZ_IGNORE,
)
IGNORE_ACCELERATION = (
    mav.POSITION_TARGET_TYPEMASK_AX_IGNORE,
    mav.POSITION_TARGET_TYPEMASK_AY_IGNORE,
    mav.POSITION_TARGET_TYPEMASK_AZ_IGNORE,
)
FORCE = mav.POSITION_TARGET_TYPEMASK_FORCE_SET
IGNORE_YAW = mav.POSITION_TARGET_TYPEMASK_YAW_IGNORE
IGNORE_YAW_RATE = mav.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
LOCAL_FRAMES = {
    mav.MAV_FRAME_LOCAL_NED: "LOCAL_NED",
    mav.MAV_FRAME_LOCAL_OFFSET_NED: "LOCAL_OFFSET_NED",
    mav.MAV_FRAME_BODY_NED: "BODY_NED",
    mav.MAV_FRAME_BODY_OFFSET_NED: "BODY_OFFSET_NED",
}
GLOBAL_FRAMES = {
    mav.MAV_FRAME_GLOBAL_INT: "GLOBAL_INT",
    mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: "GLOBAL_RELATIVE_ALT_INT",
    mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT: "GLOBAL_TERRAIN_ALT_INT",
}
MSL_FRAMES = (mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_INT)
MAX_OFFSET_M, MAX_SPEED_M_S, MAX_ACCEL_M_S2 = 1e4, 20.0, 20.0
LEAD_M = 1.0  # an integrated position never runs further than this ahead of the vehicle
MAX_DT_S = 0.1


class Refused(ValueError):
    """A setpoint the vehicle will not fly; the message says why."""


@dataclass(frozen=True)
class Target:
    """Local frame, x east, y north, z up; NaN where not controlled."""

    position_m: Vec3 = NAN3
    velocity_m_s: Vec3 = NAN3
    acceleration_m_s2: Vec3 = NAN3
    yaw_rad: float = math.nan  # from east, counter-clockwise
    yaw_rate_rad_s: float = math.nan

    @property
    def position_only(self) -> bool:
        """Every axis by position and nothing else moving: a place to go to."""
        return all(math.isfinite(v) for v in self.position_m) and not any(
            math.isfinite(v) and v != 0.0 for v in (*self.velocity_m_s, *self.acceleration_m_s2)
        )


@dataclass(frozen=True)
class Track:
    """Where the integrated setpoint is: position, velocity, heading, at `time_s`."""

    position_m: Vec3
    velocity_m_s: Vec3
    yaw_rad: float
    time_s: float


def _given(values: Vec3, mask: int, bits: tuple[int, int, int]) -> list[float]:
    return [math.nan if mask & bit else float(v) for v, bit in zip(values, bits, strict=True)]


def _check(name: str, values: list[float], limit: float) -> None:
    for axis, v in zip("xyz", values, strict=True):
        if not math.isnan(v) and (not math.isfinite(v) or abs(v) > limit):
            raise Refused(f"setpoint refused: {name} {axis} {v:g} (at most {limit:g})")


def _ned_to_enu(v: list[float]) -> Vec3:
    return (v[1], v[0], -v[2])


def _rotate(v: Vec3, yaw_rad: float) -> Vec3:
    """A vector in the heading frame (x forward, y left) into the local frame."""
    if math.isnan(v[0]) != math.isnan(v[1]):
        raise Refused("setpoint refused: a body frame needs x and y together")
    if math.isnan(v[0]):
        return v
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return (c * v[0] - s * v[1], s * v[0] + c * v[1], v[2])


def _body(v: list[float]) -> Vec3:
    """Body x forward, y right, z down -> x forward, y left, z up."""
    return (v[0], -v[1], -v[2])


def _mask_checks(mask: int) -> None:
    if mask & FORCE and not all(mask & bit for bit in IGNORE_ACCELERATION):
        raise Refused("setpoint refused: force setpoints (type mask bit 512) are not supported")
    ignored = (*IGNORE_POSITION, *IGNORE_VELOCITY, *IGNORE_ACCELERATION)
    if all(mask & bit for bit in ignored):
        raise Refused("setpoint refused: the type mask ignores position, velocity and acceleration")


def _frame_and_mask_checks(frame: int, frames: dict[int, str], kind: str, mask: int) -> None:
    """A frame this kind of target takes, and a mask that controls something."""
    if frame not in frames:
        taken = ", ".join(f"{k} {n}" for k, n in frames.items())
        raise Refused(f"setpoint refused: frame {frame} ({kind} targets take {taken})")
    _mask_checks(mask)


def _yaws(mask: int, yaw: float, yaw_rate: float) -> tuple[float, float]:
    """NED heading (clockwise from north) and its rate -> ours (counter-clockwise from east)."""
    heading = math.nan if mask & IGNORE_YAW or not math.isfinite(yaw) else math.pi / 2 - yaw
    rate = math.nan if mask & IGNORE_YAW_RATE or not math.isfinite(yaw_rate) else -yaw_rate
    return heading, rate


def local_target(
    frame: int,
    mask: int,
    fields: tuple[float, ...],  # x, y, z, vx, vy, vz, afx, afy, afz, yaw, yaw_rate
    position_m: Vec3,
    heading_rad: float,
) -> Target:
    """SET_POSITION_TARGET_LOCAL_NED as a target; `position_m` and `heading_rad` (ours) are the
    vehicle's, which the offset and body frames count from."""
    _frame_and_mask_checks(frame, LOCAL_FRAMES, "local", mask)
    p = _given(fields[0:3], mask, IGNORE_POSITION)
    v = _given(fields[3:6], mask, IGNORE_VELOCITY)
    a = _given(fields[6:9], mask, IGNORE_ACCELERATION)
    _check("position", p, MAX_OFFSET_M)
    _check("velocity", v, MAX_SPEED_M_S)
    _check("acceleration", a, MAX_ACCEL_M_S2)
    yaw, rate = _yaws(mask, fields[9], fields[10])
    if frame in (mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_OFFSET_NED):
        pos, vel, acc = (_rotate(_body(x), heading_rad) for x in (p, v, a))
    else:
        pos, vel, acc = _ned_to_enu(p), _ned_to_enu(v), _ned_to_enu(a)
    if frame != mav.MAV_FRAME_LOCAL_NED:  # offsets from where the vehicle is
        pos = tuple(here + d for here, d in zip(position_m, pos, strict=True))  # type: ignore[assignment]
    return Target(pos, vel, acc, yaw, rate)


def global_position(
    frame: int,
    lat_deg: float,
    lon_deg: float,
    alt_m: float,
    origin: tuple[float, float, float],
    home_up_m: float,
    position_m: Vec3,
) -> Vec3:
    """A global position as local (east, north, up); NaN latitude, longitude or altitude:
    the vehicle's own (latitude and longitude both, or neither); infinity is refused. MSL
    altitudes in frames 0 and 5, relative to home otherwise."""
    for name, value in (("latitude", lat_deg), ("longitude", lon_deg), ("altitude", alt_m)):
        if math.isinf(value):
            raise Refused(f"target refused: {name} {value:g} is not a number a place has")
    if math.isnan(lat_deg) != math.isnan(lon_deg):
        raise Refused("target refused: latitude and longitude both, or both NaN (here)")
    if math.isfinite(lat_deg) and math.isfinite(lon_deg):
        if not (-90.0 <= lat_deg <= 90.0 and -180.0 <= lon_deg <= 180.0):
            raise Refused(f"target refused: latitude {lat_deg:g}, longitude {lon_deg:g}")
        east, north = geodetic_to_local(origin[0], origin[1], lat_deg, lon_deg)
    else:
        east, north = position_m[0], position_m[1]
    if not math.isfinite(alt_m):
        up = position_m[2]
    else:
        up = alt_m - origin[2] if frame in MSL_FRAMES else home_up_m + alt_m
    if max(abs(east - position_m[0]), abs(north - position_m[1])) > MAX_OFFSET_M:
        raise Refused(f"target refused: {math.hypot(east, north):.0f} m away")
    return (east, north, up)


def global_target(
    frame: int,
    mask: int,
    lat_int: int,
    lon_int: int,
    fields: tuple[float, ...],  # alt, vx, vy, vz, afx, afy, afz, yaw, yaw_rate
    origin: tuple[float, float, float],
    home_up_m: float,
    position_m: Vec3,
) -> Target:
    """SET_POSITION_TARGET_GLOBAL_INT as a target (velocities and accelerations NED)."""
    _frame_and_mask_checks(frame, GLOBAL_FRAMES, "global", mask)
    v = _given(fields[1:4], mask, IGNORE_VELOCITY)
    a = _given(fields[4:7], mask, IGNORE_ACCELERATION)
    _check("velocity", v, MAX_SPEED_M_S)
    _check("acceleration", a, MAX_ACCEL_M_S2)
    here = global_position(
        frame, lat_int * 1e-7, lon_int * 1e-7, fields[0], origin, home_up_m, position_m
    )
    p = _given(here, mask, IGNORE_POSITION)
    if math.isnan(p[0]) != math.isnan(p[1]):
        raise Refused("setpoint refused: latitude and longitude go together")
    yaw, rate = _yaws(mask, fields[7], fields[8])
    return Target((p[0], p[1], p[2]), _ned_to_enu(v), _ned_to_enu(a), yaw, rate)


def follow(
    target: Target, track: Track | None, position_m: Vec3, yaw_rad: float, time_s: float
) -> tuple[Setpoint, Track]:
    """The setpoint towards `target` at `time_s`, from the track so far (None: starting at the
    vehicle's `position_m` and heading `yaw_rad`)."""
    if track is None:
        track = Track(position_m, (0.0, 0.0, 0.0), yaw_rad, time_s)
    dt = min(max(time_s - track.time_s, 0.0), MAX_DT_S)
    p_out, v_out, a_out = [], [], []
    for i in range(3):
        p, v, a = target.position_m[i], target.velocity_m_s[i], target.acceleration_m_s2[i]
        ff_a = a if math.isfinite(a) else 0.0
        if math.isfinite(p):
            sp_p, sp_v = p, v if math.isfinite(v) else 0.0
        else:
            if math.isfinite(v):
                sp_v = v
            elif math.isfinite(a):
                sp_v = min(max(track.velocity_m_s[i] + a * dt, -MAX_SPEED_M_S), MAX_SPEED_M_S)
            else:
                sp_v, ff_a = 0.0, 0.0
            sp_p = track.position_m[i] + sp_v * dt
            sp_p = min(max(sp_p, position_m[i] - LEAD_M), position_m[i] + LEAD_M)
        p_out.append(sp_p)
        v_out.append(sp_v)
        a_out.append(ff_a)
    if math.isfinite(target.yaw_rad):
        yaw = target.yaw_rad
    elif math.isfinite(target.yaw_rate_rad_s):
        yaw = track.yaw_rad + target.yaw_rate_rad_s * dt
    else:
        yaw = track.yaw_rad
    yaw = (yaw + math.pi) % (2.0 * math.pi) - math.pi
    position, velocity = (p_out[0], p_out[1], p_out[2]), (v_out[0], v_out[1], v_out[2])
    setpoint = Setpoint(position, velocity, (a_out[0], a_out[1], a_out[2]), yaw)
    return setpoint, Track(position, velocity, yaw, time_s)
