"""Flight logs as tables (CSV, Parquet, or the columns another reader decoded) in our columns,
or in another vehicle's through a `ColumnMapping`: names, units, quaternion order, frame,
the time unit, what the actuator columns hold and what the accelerometer measures."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from learner.flightlogs.actuators import (
    ACCEL_FRAMES,
    GRAVITY,
    ActuatorModel,
    actuator_model,
    kinematic_acceleration,
    rotor_speeds_rad_s,
)
from learner.flightlogs.csvtable import read_csv_columns
from learner.flightlogs.flightlog import COLUMNS, OPTIONAL, QUAT, RATES, ROTORS, VECTORS, FlightLog
from learner.flightlogs.packaged import MAPPINGS_DIR
from simbridge.config import ConfigError, load_yaml, resolve_packaged
from simbridge.frames import frd_to_flu, ned_to_enu, quat_ned_frd_to_enu_flu
from simbridge.vehicle import Vehicle, load_vehicle

# Unit names a mapping may give, as factors into the format's units.
UNIT_FACTORS: dict[str, float] = {
    "s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9,
    "m": 1.0, "cm": 1e-2, "mm": 1e-3,
    "m/s": 1.0, "cm/s": 1e-2, "mm/s": 1e-3,
    "rad/s": 1.0, "mrad/s": 1e-3, "deg/s": math.pi / 180.0, "rpm": 2.0 * math.pi / 60.0,
    "m/s^2": 1.0, "cm/s^2": 1e-2, "mm/s^2": 1e-3, "g": 9.81, "mg": 9.81e-3,
    "V": 1.0, "mV": 1e-3, "1": 1.0,
}  # fmt: skip
TIME_UNITS = ("s", "ms", "us", "ns")
# What a time column's unit may be detected from: a flight log's rate and length.
AUTO_RATE_HZ = (2.0, 5000.0)
AUTO_DURATION_S = (0.5, 86400.0)
MAPPING_KEYS = (
    "names", "units", "quaternion_order", "frame", "time_unit", "actuators", "accelerometer",
)  # fmt: skip


@dataclass(frozen=True)
class ColumnMapping:
    """How another log's columns become ours: names (ours -> theirs), units, quaternion order,
    frame (`enu_flu`: ours; `ned_frd`: PX4/MAVLink world NED, body FRD), the time unit
    (s, ms, us, ns or auto; None: `units.time_s`, else s for our own `time_s`, else auto), the
    actuator columns (their columns for our rotors 0 front-left, 1 back-left, 2 back-right,
    3 front-right; one for a collective kind) and the accelerometer's (gravity, frame)."""

    names: dict[str, str] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    quaternion_order: str = "wxyz"
    frame: str = "enu_flu"
    time_unit: str | None = None
    actuators: ActuatorModel | None = None
    actuator_columns: tuple[str, ...] = ()
    accelerometer: tuple[str, str] | None = None  # (gravity, frame); None: removed, world

    def __post_init__(self) -> None:
        known = set(COLUMNS) | set(OPTIONAL)
        for where, keys in (("names", self.names), ("units", self.units)):
            bad = sorted(set(keys) - known)
            if bad:
                raise ConfigError(
                    f"column mapping {where}: unknown column {bad[0]!r}; ours are "
                    f"{', '.join([*COLUMNS, *OPTIONAL])}"
                )
        for ours, theirs in self.names.items():
            if not isinstance(theirs, str):
                raise ConfigError(
                    f"column mapping names.{ours}: expected a column name (text), got {theirs!r}"
                )
        for col, unit in self.units.items():
            if unit not in UNIT_FACTORS:
                raise ConfigError(
                    f"column mapping units.{col}: {unit!r} is not one of {', '.join(UNIT_FACTORS)}"
                )
        if self.quaternion_order not in ("wxyz", "xyzw"):
            raise ConfigError("column mapping quaternion_order: expected wxyz or xyzw")
        named = [q for q in QUAT if q in self.names]
        if self.quaternion_order != "wxyz" and named:
            # names already put each component in its place; reordering too would flip it twice
            raise ConfigError(
                f"column mapping: quaternion_order {self.quaternion_order} beside names for "
                f"{', '.join(named)}: give one of them (names say which column is each "
                "component; quaternion_order is for the columns qw, qx, qy, qz holding x, y, "
                "z, w)"
            )
        if self.frame not in ("enu_flu", "ned_frd"):
            raise ConfigError("column mapping frame: expected enu_flu or ned_frd")
        self._check_time()
        self._check_actuators()
        if self.accelerometer is not None:
            gravity, frame = self.accelerometer
            if gravity not in GRAVITY:
                raise ConfigError(
                    f"column mapping accelerometer.gravity: {gravity!r} is not one of "
                    f"{', '.join(GRAVITY)}"
                )
            if frame not in ACCEL_FRAMES:
                raise ConfigError(
                    f"column mapping accelerometer.frame: {frame!r} is not one of "
                    f"{', '.join(ACCEL_FRAMES)}"
                )

    def _check_time(self) -> None:
        if self.time_unit is None:
            return
        if self.time_unit not in (*TIME_UNITS, "auto"):
            raise ConfigError(
                f"column mapping time_unit: {self.time_unit!r} is not one of "
                f"{', '.join(TIME_UNITS)}, auto"
            )
        given = self.units.get("time_s")
        if given is not None and given != self.time_unit:
            raise ConfigError(
                f"column mapping time_unit: {self.time_unit} contradicts units.time_s: {given}; "
                f"give one of them"
            )

    def _check_actuators(self) -> None:
        if self.actuators is None:
            return
        given = sorted(set(self.names) & set(ROTORS)) + sorted(set(self.units) & set(ROTORS))
        if given:
            raise ConfigError(
                f"column mapping: {given[0]} is mapped in names/units and by actuators.columns; "
                f"give the rotor columns in actuators.columns only"
            )
        kind, count = self.actuators.kind, len(self.actuator_columns)
        allowed = {"collective_thrust": (1,), "rotor_speed": (4,), "rotor_thrust": (4,)}.get(
            kind, (1, 4)
        )
        if count not in allowed or not all(isinstance(c, str) for c in self.actuator_columns):
            need = " or ".join(str(a) for a in allowed)
            raise ConfigError(
                f"column mapping actuators.columns: kind {kind} needs {need} column name(s) "
                f"(rotors 0 front-left, 1 back-left, 2 back-right, 3 front-right), "
                f"got {list(self.actuator_columns)!r}"
            )

    @property
    def is_default(self) -> bool:
        """Whether this maps nothing (our own columns): a reader may use its format's own."""
        return self == ColumnMapping()


def load_mapping(path: Path | str | None) -> ColumnMapping:
    """A mapping YAML (or a packaged one by name: crazyflie_z, crazyflie, neural_swarm, neural_fly):
    {names, units, quaternion_order, frame, time_unit, actuators, accelerometer}."""
    if path is None:
        return ColumnMapping()
    path = resolve_packaged(path, MAPPINGS_DIR, ".yaml", "column mapping")
    data = load_yaml(path)
    try:
        return mapping_from_dict(data)
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}") from None


def mapping_from_dict(data: dict[str, Any]) -> ColumnMapping:
    """A mapping from its YAML content."""
    unknown = sorted(set(data) - set(MAPPING_KEYS))
    if unknown:
        raise ConfigError(f"unknown key {unknown[0]!r}; known keys: {', '.join(MAPPING_KEYS)}")
    for key in ("names", "units", "actuators", "accelerometer"):
        if not isinstance(data.get(key) or {}, dict):
            raise ConfigError(f"{key}: expected a mapping, got {data[key]!r}")
    acts = data.get("actuators")
    columns = (acts or {}).get("columns", [])
    if not isinstance(columns, list):
        raise ConfigError(f"actuators.columns: expected a list of column names, got {columns!r}")
    acc = data.get("accelerometer")
    if acc is not None:
        extra = sorted(set(acc) - {"gravity", "frame"})
        if extra:
            raise ConfigError(f"accelerometer: unknown key {extra[0]!r}; known: gravity, frame")
        acc = (str(acc.get("gravity", "removed")), str(acc.get("frame", "world")))
    time_unit = data.get("time_unit")
    return ColumnMapping(
        names=dict(data.get("names") or {}),
        units=dict(data.get("units") or {}),
        quaternion_order=str(data.get("quaternion_order", "wxyz")),
        frame=str(data.get("frame", "enu_flu")),
        time_unit=None if time_unit is None else str(time_unit),
        actuators=None if acts is None else actuator_model(acts),
        actuator_columns=tuple(columns),
        accelerometer=acc,
    )


def read_table_log(
    path: Path, mapping: ColumnMapping | None = None, vehicle: Vehicle | str | None = None
) -> FlightLog:
    """A CSV or Parquet flight log through `mapping` (default: our own column names);
    `vehicle` (default nano) turns logged thrust into rotor speeds through its C_T."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: no such flight log")
    if path.suffix == ".parquet":
        try:
            import pyarrow.parquet as pq
        except ImportError:
            raise ConfigError(
                f"{path}: reading Parquet needs pyarrow (pip install groundfx[parquet])"
            ) from None
        table = pq.read_table(path)
        raw = {n: np.asarray(table[n].to_numpy(), dtype=float) for n in table.column_names}
        lists: dict[str, str] = {}
    else:
        raw, lists = read_csv_columns(path)
    return table_log(raw, path, mapping, vehicle, lists=lists, meta=_sidecar(path))


def table_log(
    raw: dict[str, np.ndarray],
    path: Path,
    mapping: ColumnMapping | None = None,
    vehicle: Vehicle | str | None = None,
    lists: dict[str, str] | None = None,
    meta: dict[str, Any] | None = None,
) -> FlightLog:
    """Decoded columns (`raw`, by their names in the log at `path`) into a FlightLog through
    `mapping`. What was converted is listed in the log's meta["conversions"]."""
    m = mapping or ColumnMapping()
    lists = lists or {}
    notes: list[str] = list((meta or {}).get("conversions", []))

    def source(theirs: str, ours: str, what: str) -> np.ndarray:
        if theirs in raw:
            return np.asarray(raw[theirs], dtype=float)
        if theirs in lists:
            raise ConfigError(
                f"{path}: column {theirs!r} ({ours}) holds lists; address its elements as "
                f"{lists[theirs]}"
            )
        shown = ", ".join(list(raw)[:12]) + (", ..." if len(raw) > 12 else "")
        raise ConfigError(
            f"{path}: missing column {theirs!r} ({ours}, {what}); map it with a column mapping "
            f"(names: {{{ours}: THEIRS}}); the log has: {shown}"
        )

    def column(name: str, required: bool) -> np.ndarray | None:
        theirs = m.names.get(name, name)
        if not required and theirs not in raw:
            return None
        values = source(theirs, name, (COLUMNS | OPTIONAL)[name])
        return values * UNIT_FACTORS[m.units.get(name, _unit(name))]

    def stack(names: tuple[str, ...], required: bool) -> np.ndarray | None:
        cols = [column(n, required) for n in names]
        return None if any(c is None for c in cols) else np.column_stack(cols)

    t = _time_s(m, raw, path, source, notes)
    pos, vel = stack(VECTORS[0], True), stack(VECTORS[1], True)
    q, rates = stack(QUAT, True), stack(RATES, True)
    acc = stack(VECTORS[2], m.accelerometer is not None)
    notes += _unit_notes(m)
    if m.quaternion_order == "xyzw":
        q = q[:, [3, 0, 1, 2]]
    if m.frame == "ned_frd":
        pos, vel = _rows(ned_to_enu, pos), _rows(ned_to_enu, vel)
        rates = _rows(frd_to_flu, rates)
        q = _rows(quat_ned_frd_to_enu_flu, q)
        if acc is not None:
            body = m.accelerometer is not None and m.accelerometer[1] == "body"
            acc = _rows(frd_to_flu if body else ned_to_enu, acc)
        notes.append("frame: world NED, body FRD -> world ENU, body FLU")
    norm = np.linalg.norm(q, axis=1, keepdims=True)
    # a zero quaternion is no attitude: NaN, dropped with the row below
    q = q / np.where(norm > 0.0, norm, np.nan)
    if acc is not None and m.accelerometer is not None:
        gravity, frame = m.accelerometer
        acc = kinematic_acceleration(acc, q, gravity, frame)
        notes.append(f"acceleration: {frame} frame, gravity {gravity} -> world, kinematic")
    elif acc is None:
        notes.append("acceleration: not logged; the diagnosis differentiates the velocity")
    rotors = _rotor_speeds(m, raw, path, source, vehicle, notes, stack)
    battery = column("battery_v", False)
    order = _clean_order(t, (pos, vel, q, rates, rotors, acc), notes)
    arrays = [a[order] if a is not None else None for a in (t, pos, vel, q, rates, rotors, acc)]
    return FlightLog(
        path.stem, *arrays[:6], acceleration_m_s2=arrays[6],
        battery_v=None if battery is None else battery[order],
        meta={**(meta or {}), "conversions": notes},
    )  # fmt: skip


def _clean_order(
    t: np.ndarray, columns: tuple[np.ndarray | None, ...], notes: list[str]
) -> np.ndarray:
    """The rows to keep, in time order: rows with a value missing (NaN, inf) in a column the
    diagnosis reads are dropped, and of rows with the same time stamp the first is kept (a
    logger that writes a row twice; a zero time step would divide by zero downstream). Each
    is counted in the notes."""
    finite = np.isfinite(t)
    for a in columns:
        if a is not None:
            finite &= np.all(np.isfinite(a.reshape(len(t), -1)), axis=1)
    if not finite.all():
        notes.append(
            f"rows: {_rows_text(int((~finite).sum()))} with a missing or non-finite value dropped"
        )
    order = np.flatnonzero(finite)
    order = order[np.argsort(t[order], kind="stable")]
    if len(order) > 1:
        repeated = np.concatenate([[False], np.diff(t[order]) <= 0.0])
        if repeated.any():
            notes.append(
                f"rows: {_rows_text(int(repeated.sum()))} repeating an earlier time stamp dropped"
            )
            order = order[~repeated]
    return order


def _rows_text(n: int) -> str:
    return f"{n} row" if n == 1 else f"{n} rows"


def _time_s(m: ColumnMapping, raw: dict, path: Path, source: Any, notes: list[str]) -> np.ndarray:
    theirs = m.names.get("time_s", "time_s")
    t = source(theirs, "time_s", COLUMNS["time_s"])
    unit = m.time_unit or m.units.get("time_s") or ("s" if theirs == "time_s" else "auto")
    if unit == "auto":
        unit, why = detect_time_unit(t, f"{path}: time column {theirs!r}")
        notes.append(f"time: {unit} -> s (detected: {why})")
    elif unit != "s":
        notes.append(f"time: {unit} -> s")
    return t * UNIT_FACTORS[unit]


def detect_time_unit(t: np.ndarray, where: str) -> tuple[str, str]:
    """The one unit (s, ms, us, ns) in which the time column's median step and span are a
    flight log's (a rate of 2 Hz to 5 kHz, 0.5 s to a day), else a ConfigError."""
    t = np.asarray(t, dtype=float)
    t = t[np.isfinite(t)]
    steps = np.diff(np.sort(t))
    steps = steps[steps > 0]
    ask = "set time_unit: s, ms, us or ns in the column mapping"
    if len(steps) < 2:
        raise ConfigError(f"{where}: too few distinct times to detect their unit; {ask}")
    step, span = float(np.median(steps)), float(t.max() - t.min())
    fits = [
        u
        for u in TIME_UNITS
        if AUTO_RATE_HZ[0] <= 1.0 / (step * UNIT_FACTORS[u]) <= AUTO_RATE_HZ[1]
        and AUTO_DURATION_S[0] <= span * UNIT_FACTORS[u] <= AUTO_DURATION_S[1]
    ]
    if len(fits) != 1:
        could = f"it could be {' or '.join(fits)}" if fits else "no unit gives 2 Hz-5 kHz"
        raise ConfigError(
            f"{where}: cannot tell the time unit from the median step {step:g} and the span "
            f"{span:g} ({could}); {ask}"
        )
    u = fits[0]
    rate = 1.0 / (step * UNIT_FACTORS[u])
    return u, f"median step {step:g} {u}, {rate:.1f} Hz over {span * UNIT_FACTORS[u]:.1f} s"


def _rotor_speeds(
    m: ColumnMapping, raw: dict, path: Path, source: Any, vehicle: Any, notes: list, stack: Any
) -> np.ndarray:
    if m.actuators is None:
        units = {m.units.get(n, "rad/s") for n in ROTORS}
        if units != {"rad/s"}:
            notes.append(f"rotor speed: {', '.join(sorted(units))} -> rad/s")
        return stack(ROTORS, True)
    model = m.actuators
    values = np.column_stack([source(c, "actuators", model.kind) for c in m.actuator_columns])
    hover = None
    if model.hover_throttle_column is not None:
        hover = source(model.hover_throttle_column, "actuators.hover_throttle", "throttle")
    v = vehicle if isinstance(vehicle, Vehicle) else load_vehicle(vehicle or "nano")
    notes.append(_actuator_note(model, len(m.actuator_columns), v))
    return rotor_speeds_rad_s(values, model, v, hover)


def _actuator_note(model: ActuatorModel, count: int, v: Vehicle) -> str:
    through = f"rad/s through {v.name}'s C_T {v.thrust_coefficient_n_s2:.3g} N/(rad/s)^2"
    if model.kind == "rotor_speed":
        return f"rotor speed: {model.unit} -> rad/s"
    if model.kind == "rotor_thrust":
        return f"thrust: per-rotor {model.unit} -> {through}"
    if model.kind == "collective_thrust":
        return f"thrust: collective {model.unit}, a quarter per rotor -> {through}"
    which = "collective" if count == 1 else "per-rotor"
    if model.thrust_curve_n is not None:
        a, b, c = model.thrust_curve_n
        return f"thrust: {which} {model.kind} u, N = {a:g} u^2 + {b:g} u + {c:g} -> {through}"
    hover = model.hover_throttle_column or f"{model.hover_throttle:g}"
    return (
        f"thrust: {which} throttle x {v.name}'s weight {v.weight_n:.3g} N / hover throttle "
        f"({hover}) -> {through}"
    )


def _unit_notes(m: ColumnMapping) -> list[str]:
    groups = {"position": VECTORS[0], "velocity": VECTORS[1], "acceleration": VECTORS[2],
              "body rates": RATES, "battery": ("battery_v",)}  # fmt: skip
    notes = []
    for what, names in groups.items():
        units = sorted({m.units[n] for n in names if n in m.units and m.units[n] != _unit(n)})
        if units:
            notes.append(f"{what}: {', '.join(units)} -> {_unit(names[0])}")
    return notes


def _unit(name: str) -> str:
    unit = (COLUMNS | OPTIONAL)[name].split(",")[0]
    return unit if unit in UNIT_FACTORS else "1"


def _rows(fn: Any, a: np.ndarray) -> np.ndarray:
    return np.array([fn(tuple(r)) for r in a], dtype=float)


def _sidecar(path: Path) -> dict[str, Any]:
    side = path.with_suffix(".json")
    if not side.exists() or side == path:
        return {}
    try:
        return json.loads(side.read_text())
    except (OSError, json.JSONDecodeError):
        raise ConfigError(f"{side}: the log's JSON sidecar cannot be read") from None
