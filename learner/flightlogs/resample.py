"""Autopilot logs (PX4 ULog, ArduPilot DataFlash, MAVLink telemetry) into a `FlightLog`: what
their readers decoded, as time series in the autopilot's own frames (world NED, body FRD), put
on one timeline and into our frames and units.

The timeline is uniform at the rate of the faster of the position and attitude streams, from
where every essential stream has started to where the first one ends; the diagnosis starts a
new segment wherever rows are further apart than 1.5 periods, so a jittery timeline of logged
stamps would cut a flight into pieces. Position, velocity, rates and battery are interpolated
linearly; quaternions made sign-continuous, interpolated and normalised; acceleration and
actuators averaged over each row's period (a row's commands cover the period ending at it)
where the source is faster than the timeline, else interpolated. No stream is interpolated
across a logging gap (its samples more than GAP_PERIODS of its own periods apart): those rows
are dropped and counted, so segments on either side stay apart.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from learner.flightlogs.actuators import ActuatorModel, kinematic_acceleration, rotor_speeds_rad_s
from learner.flightlogs.flightlog import FlightLog
from simbridge.config import ConfigError
from simbridge.frames import (
    frd_to_flu,
    ned_to_enu,
    quat_conjugate,
    quat_multiply,
    quat_ned_frd_to_enu_flu,
)
from simbridge.vehicle import Vehicle, load_vehicle

# A stream's samples further apart than this many of its median periods: a logging gap.
GAP_PERIODS = 5.0
# PX4 and ArduCopter quad X number motors 1 front-right, 2 back-left, 3 front-left,
# 4 back-right; our rotor i is their motor QUAD_X_TO_OURS[i] (zero-based), as in nano.yaml.
QUAD_X_TO_OURS = [2, 1, 3, 0]
ACCEL_FRAMES = ("ned_kinematic", "frd_specific_force")


@dataclass(frozen=True)
class Stream:
    """One decoded time series: times (s, increasing, distinct) and values (N, k)."""

    t_s: np.ndarray
    values: np.ndarray
    source: str  # where in the log it came from, for the log's meta

    @property
    def period_s(self) -> float:
        return float(np.median(np.diff(self.t_s)))


def stream(t_s: Any, values: Any, source: str) -> Stream | None:
    """A Stream from raw arrays: non-finite rows dropped, sorted, repeated stamps kept once;
    None if fewer than two rows remain."""
    t = np.asarray(t_s, dtype=float)
    v = np.asarray(values, dtype=float)
    v = v[:, None] if v.ndim == 1 else v
    ok = np.isfinite(t) & np.all(np.isfinite(v), axis=1)
    t, v = t[ok], v[ok]
    order = np.argsort(t, kind="stable")
    t, v = t[order], v[order]
    keep = np.r_[True, np.diff(t) > 0] if len(t) else np.zeros(0, bool)
    t, v = t[keep], v[keep]
    return Stream(t, v, source) if len(t) >= 2 else None


@dataclass
class AutopilotLog:
    """What a reader decoded, before resampling. Frames as autopilots log them: world NED,
    body FRD; the quaternion (w, x, y, z) turns body FRD into world NED."""

    path: Path
    fmt: str  # "PX4 ULog", "ArduPilot DataFlash log", "MAVLink telemetry log"
    found: list[str]  # the topics or message types in the file, for error messages
    looked_for: dict[str, str]  # essential -> where it was looked for
    position_ned_m: Stream | None = None
    velocity_ned_m_s: Stream | None = None
    attitude_ned_frd: Stream | None = None
    rates_frd_rad_s: Stream | None = None
    acceleration: Stream | None = None
    acceleration_frame: str = "ned_kinematic"  # or frd_specific_force (gravity included)
    actuators: Stream | None = None  # 4 columns in our rotor order
    actuator_model: ActuatorModel | None = None
    actuator_note: str = ""  # how the logged values become thrust, for the log's meta
    battery_v: Stream | None = None
    range_m: Stream | None = None  # downward distance sensor
    notes: list[str] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)

    def missing(self, what: str) -> ConfigError:
        """The error for an essential the log lacks."""
        shown = ", ".join(self.found[:40]) + (", ..." if len(self.found) > 40 else "")
        return ConfigError(
            f"{self.path}: this {self.fmt} has no {what} (looked for "
            f"{self.looked_for.get(what, what)}); the log has: {shown or 'nothing we could read'}"
        )


def to_flightlog(log: AutopilotLog, vehicle: Vehicle | str | None = None) -> FlightLog:
    """The decoded log on one timeline in our frames; what was used and assumed in its meta."""
    for what, s in (
        ("position", log.position_ned_m),
        ("attitude", log.attitude_ned_frd),
        ("actuator outputs", log.actuators),
    ):
        if s is None:
            raise log.missing(what)
    assert log.position_ned_m and log.attitude_ned_frd and log.actuators and log.actuator_model
    notes = list(log.notes)
    pos, att = log.position_ned_m, _continuous(log.attitude_ned_frd)
    vel = log.velocity_ned_m_s
    if vel is None:
        vel = Stream(pos.t_s, np.gradient(pos.values, pos.t_s, axis=0), f"d/dt {pos.source}")
        notes.append("velocity: not logged; differentiated from the position")
    rates = log.rates_frd_rad_s
    if rates is None:
        rates = _rates_from_attitude(att)
        notes.append("body rates: not logged; from the attitude's change")
    essential = [pos, vel, att, rates, log.actuators]
    period = min(pos.period_s, att.period_s)
    t0, t1 = max(s.t_s[0] for s in essential), min(s.t_s[-1] for s in essential)
    if not t1 - t0 > period:
        spans = ", ".join(f"{s.source} {s.t_s[0]:.2f}-{s.t_s[-1]:.2f} s" for s in essential)
        raise ConfigError(f"{log.path}: the essential streams do not overlap in time: {spans}")
    t = t0 + period * np.arange(int(np.floor((t1 - t0) / period)) + 1)
    valid = np.ones(len(t), bool)
    p, ok = _interp(pos, t)
    valid &= ok
    v, ok = _interp(vel, t)
    valid &= ok
    q, ok = _interp(att, t)
    valid &= ok
    w, ok = _interp(rates, t)
    valid &= ok
    u, ok = _period_mean(log.actuators, t, period)
    valid &= ok
    acc = None
    if log.acceleration is not None:
        acc, ok = _period_mean(log.acceleration, t, period)
        if np.mean(ok[valid]) < 0.5:  # mostly gaps: better differentiated than half dropped
            notes.append(f"acceleration: {log.acceleration.source} mostly gaps; not used")
            acc = None
        else:
            valid &= ok
    dropped = int(np.count_nonzero(~valid))
    if not valid.any():
        raise ConfigError(f"{log.path}: no row without a logging gap in an essential stream")
    t, p, v, q, w, u = t[valid], p[valid], v[valid], q[valid], w[valid], u[valid]
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    q_enu = _rows(quat_ned_frd_to_enu_flu, q)
    if acc is not None:
        acc = _acceleration(log, acc[valid], q_enu, notes)
    else:
        notes.append("acceleration: not logged; the diagnosis differentiates the velocity")
    v_model = vehicle if isinstance(vehicle, Vehicle) else load_vehicle(vehicle or "nano")
    rotors = rotor_speeds_rad_s(u, log.actuator_model, v_model)
    notes.append(
        f"actuators: {log.actuator_note} -> rad/s through {v_model.name}'s C_T "
        f"{v_model.thrust_coefficient_n_s2:.3g} N/(rad/s)^2"
    )
    notes.append("frame: world NED, body FRD -> world ENU, body FLU")
    notes.append(
        f"timeline: uniform {1.0 / period:.1f} Hz ({len(t)} rows); {dropped} rows dropped at "
        f"logging gaps (a stream's samples more than {GAP_PERIODS:g} of its periods apart)"
    )
    battery = None if log.battery_v is None else _hold_interp(log.battery_v, t)
    meta = {
        **log.meta,
        "format": log.fmt,
        "source": str(log.path),
        "sources": {
            name: s.source
            for name, s in (
                ("position", pos),
                ("velocity", vel),
                ("attitude", att),
                ("rates", rates),
                ("acceleration", log.acceleration if acc is not None else None),
                ("actuators", log.actuators),
                ("battery", log.battery_v),
                ("range", log.range_m),
            )
            if s is not None
        },
        "rows_dropped_at_gaps": dropped,
        "conversions": notes,
    }
    if log.range_m is not None:
        # not a FlightLog column: the diagnosis takes heights from the world's geometry
        meta["range_m_median"] = float(np.median(log.range_m.values[:, 0]))
    return FlightLog(
        log.path.stem, t, _rows(ned_to_enu, p), _rows(ned_to_enu, v), q_enu,
        _rows(frd_to_flu, w), rotors, acceleration_m_s2=acc, battery_v=battery, meta=meta,
    )  # fmt: skip


def _acceleration(log: AutopilotLog, acc: np.ndarray, q_enu: np.ndarray, notes: list) -> Any:
    assert log.acceleration is not None
    if log.acceleration_frame == "ned_kinematic":
        notes.append(f"acceleration: {log.acceleration.source}, world NED kinematic")
        return _rows(ned_to_enu, acc)
    if log.acceleration_frame != "frd_specific_force":
        raise ValueError(f"acceleration_frame {log.acceleration_frame!r} not in {ACCEL_FRAMES}")
    notes.append(
        f"acceleration: {log.acceleration.source}, body FRD specific force (gravity included) "
        f"-> world, kinematic"
    )
    return kinematic_acceleration(_rows(frd_to_flu, acc), q_enu, "included", "body")


def _gap_free(s: Stream, t: np.ndarray) -> np.ndarray:
    """Rows of `t` inside the stream's span whose bracketing samples are not across a gap."""
    j = np.clip(np.searchsorted(s.t_s, t), 1, len(s.t_s) - 1)
    span = s.t_s[j] - s.t_s[j - 1]
    inside = (t >= s.t_s[0]) & (t <= s.t_s[-1])
    return inside & (span <= GAP_PERIODS * s.period_s)


def _interp(s: Stream, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    out = np.column_stack([np.interp(t, s.t_s, s.values[:, k]) for k in range(s.values.shape[1])])
    return out, _gap_free(s, t)


def _period_mean(s: Stream, t: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean of the samples in each row's period (t - period, t]; interpolated where the
    stream is slower than the timeline and a period holds none."""
    out, ok = _interp(s, t)
    if s.period_s >= period:
        return out, ok
    lo = np.searchsorted(s.t_s, t - period, side="right")
    hi = np.searchsorted(s.t_s, t, side="right")
    sums = np.vstack([np.zeros(s.values.shape[1]), np.cumsum(s.values, axis=0)])
    count = hi - lo
    some = count > 0
    out[some] = (sums[hi[some]] - sums[lo[some]]) / count[some, None]
    return out, ok


def _hold_interp(s: Stream, t: np.ndarray) -> np.ndarray:
    # a battery reading changes slowly: interpolated across gaps and held at the ends
    return np.interp(t, s.t_s, s.values[:, 0])


def _continuous(s: Stream) -> Stream:
    """Quaternions with the sign that keeps each next to the previous (q and -q are one
    attitude; interpolating between opposite signs passes through zero)."""
    q = s.values / np.linalg.norm(s.values, axis=1, keepdims=True)
    dots = np.sum(q[1:] * q[:-1], axis=1)
    flips = np.cumprod(np.r_[1.0, np.where(dots < 0.0, -1.0, 1.0)])
    return Stream(s.t_s, q * flips[:, None], s.source)


def _rates_from_attitude(att: Stream) -> Stream:
    """Body rates from consecutive attitudes: w = 2 vec(conj(q) dq/dt), at the midpoints."""
    q = att.values
    dt = np.diff(att.t_s)
    dq = (q[1:] - q[:-1]) / dt[:, None]
    mid = (q[1:] + q[:-1]) / 2.0
    w = np.array(
        [
            quat_multiply(quat_conjugate(tuple(m)), tuple(d))[1:]
            for m, d in zip(mid, dq, strict=True)
        ]
    )
    return Stream((att.t_s[1:] + att.t_s[:-1]) / 2.0, 2.0 * w, f"d/dt {att.source}")


def _rows(fn: Callable[[tuple], tuple], a: np.ndarray) -> np.ndarray:
    """A frames.py conversion applied row by row (the one place for frame conventions)."""
    return np.array([fn(tuple(r)) for r in a], dtype=float).reshape(len(a), -1)
