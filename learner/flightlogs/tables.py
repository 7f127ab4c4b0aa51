"""Flight logs as tables (CSV, Parquet) in our columns, or in another vehicle's through a
`ColumnMapping` (names, units, quaternion order, frame)."""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from learner.flightlogs.flightlog import COLUMNS, OPTIONAL, QUAT, RATES, ROTORS, VECTORS, FlightLog
from simbridge.config import ConfigError, load_yaml
from simbridge.frames import frd_to_flu, ned_to_enu, quat_ned_frd_to_enu_flu

# Unit names a mapping may give, as factors into the format's units.
UNIT_FACTORS: dict[str, float] = {
    "s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9,
    "m": 1.0, "cm": 1e-2, "mm": 1e-3,
    "m/s": 1.0, "cm/s": 1e-2, "mm/s": 1e-3,
    "rad/s": 1.0, "deg/s": math.pi / 180.0, "rpm": 2.0 * math.pi / 60.0,
    "m/s^2": 1.0, "g": 9.81, "mg": 9.81e-3,
    "V": 1.0, "mV": 1e-3, "1": 1.0,
}  # fmt: skip


@dataclass(frozen=True)
class ColumnMapping:
    """How another log's columns become ours: names (ours -> theirs), units, quaternion order,
    frame (`enu_flu`: ours; `ned_frd`: PX4/MAVLink world NED, body FRD)."""

    names: dict[str, str] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    quaternion_order: str = "wxyz"
    frame: str = "enu_flu"

    def __post_init__(self) -> None:
        known = set(COLUMNS) | set(OPTIONAL)
        for where, keys in (("names", self.names), ("units", self.units)):
            bad = sorted(set(keys) - known)
            if bad:
                raise ConfigError(f"column mapping {where}: unknown column {bad[0]!r}")
        for col, unit in self.units.items():
            if unit not in UNIT_FACTORS:
                raise ConfigError(
                    f"column mapping units.{col}: {unit!r} is not one of {', '.join(UNIT_FACTORS)}"
                )
        if self.quaternion_order not in ("wxyz", "xyzw"):
            raise ConfigError("column mapping quaternion_order: expected wxyz or xyzw")
        if self.frame not in ("enu_flu", "ned_frd"):
            raise ConfigError("column mapping frame: expected enu_flu or ned_frd")


def load_mapping(path: Path | None) -> ColumnMapping:
    """A mapping YAML: {names: {ours: theirs}, units: {ours: unit}, quaternion_order, frame}."""
    if path is None:
        return ColumnMapping()
    data = load_yaml(path)
    unknown = sorted(set(data) - {"names", "units", "quaternion_order", "frame"})
    if unknown:
        raise ConfigError(f"{path}: unknown key {unknown[0]!r}")
    return ColumnMapping(
        names=dict(data.get("names") or {}),
        units=dict(data.get("units") or {}),
        quaternion_order=str(data.get("quaternion_order", "wxyz")),
        frame=str(data.get("frame", "enu_flu")),
    )


def _read_table(path: Path) -> dict[str, np.ndarray]:
    if not path.is_file():
        raise ConfigError(f"{path}: no such flight log")
    if path.suffix == ".parquet":
        try:
            import pyarrow.parquet as pq
        except ImportError:
            raise ConfigError(f"{path}: reading Parquet needs pyarrow") from None
        table = pq.read_table(path)
        return {n: np.asarray(table[n].to_numpy(), dtype=float) for n in table.column_names}
    if path.suffix != ".csv":
        raise ConfigError(f"{path}: expected a .csv, .parquet or .rrd flight log")
    try:
        with path.open(newline="") as f:
            rows = list(csv.reader(line for line in f if not line.startswith("#")))
    except OSError as err:
        raise ConfigError(f"{path}: cannot read ({err.strerror})") from None
    if len(rows) < 2:
        raise ConfigError(f"{path}: no rows")
    header, body = rows[0], rows[1:]
    try:
        data = np.array([[float(v) if v != "" else math.nan for v in r] for r in body])
    except ValueError as err:
        raise ConfigError(f"{path}: a value is not a number ({err})") from None
    return {name: data[:, i] for i, name in enumerate(header)}


def read_table_log(path: Path, mapping: ColumnMapping | None = None) -> FlightLog:
    """A CSV or Parquet flight log through `mapping` (default: our own column names)."""
    path = Path(path)
    mapping = mapping or ColumnMapping()
    raw = _read_table(path)

    def column(name: str, required: bool) -> np.ndarray | None:
        source = mapping.names.get(name, name)
        if source not in raw:
            if required:
                raise ConfigError(
                    f"{path}: missing column {source!r} ({name}, {COLUMNS[name]}); "
                    f"map it with a column mapping (names: {{{name}: THEIRS}})"
                )
            return None
        unit = mapping.units.get(name, "1" if name in QUAT else _unit(name))
        return raw[source] * UNIT_FACTORS[unit]

    def stack(names: tuple[str, ...], required: bool) -> np.ndarray | None:
        cols = [column(n, required) for n in names]
        return None if any(c is None for c in cols) else np.column_stack(cols)

    t = column("time_s", True)
    pos, vel = stack(VECTORS[0], True), stack(VECTORS[1], True)
    acc = stack(VECTORS[2], False)
    q = stack(QUAT, True)
    rates, rotors = stack(RATES, True), stack(ROTORS, True)
    if mapping.quaternion_order == "xyzw":
        q = q[:, [3, 0, 1, 2]]
    if mapping.frame == "ned_frd":
        pos, vel = _rows(ned_to_enu, pos), _rows(ned_to_enu, vel)
        acc = None if acc is None else _rows(ned_to_enu, acc)
        rates = _rows(frd_to_flu, rates)
        q = _rows(quat_ned_frd_to_enu_flu, q)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    order = np.argsort(t, kind="stable")
    arrays = [a[order] if a is not None else None for a in (t, pos, vel, q, rates, rotors, acc)]
    battery = column("battery_v", False)
    meta = _sidecar(path)
    return FlightLog(
        path.stem, *arrays[:6], acceleration_m_s2=arrays[6],
        battery_v=None if battery is None else battery[order], meta=meta,
    )  # fmt: skip


def _unit(name: str) -> str:
    unit = (COLUMNS | OPTIONAL)[name].split(",")[0]
    return unit if unit in UNIT_FACTORS else "1"


def _rows(fn: Any, a: np.ndarray) -> np.ndarray:
    return np.array([fn(tuple(r)) for r in a], dtype=float)


def _sidecar(path: Path) -> dict[str, Any]:
    side = path.with_suffix(".json")
    return json.loads(side.read_text()) if side.exists() else {}
