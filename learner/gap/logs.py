"""Flight logs for the gap diagnosis: one `FlightLog` of arrays, read from our CSV/Parquet
format or from another vehicle's columns through a `ColumnMapping`.

The format (one row per control period; world x east, y north, z up; body x forward, y left,
z up). A row's acceleration and rotor commands describe the control period that ends at its
`time_s`; its state is the state at `time_s`.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from simbridge.config import ConfigError, load_yaml
from simbridge.frames import frd_to_flu, ned_to_enu, quat_ned_frd_to_enu_flu

COLUMNS: dict[str, str] = {
    "time_s": "s",
    "x_m": "m, world east",
    "y_m": "m, world north",
    "z_m": "m, world up (above the ground plane z = 0)",
    "vx_m_s": "m/s, world",
    "vy_m_s": "m/s, world",
    "vz_m_s": "m/s, world",
    "qw": "1, attitude body to world (w, x, y, z)",
    "qx": "1",
    "qy": "1",
    "qz": "1",
    "p_rad_s": "rad/s, body rate about x forward",
    "q_rad_s": "rad/s, body rate about y left",
    "r_rad_s": "rad/s, body rate about z up",
    "n0_rad_s": "rad/s, rotor 0 (front-left) speed command",
    "n1_rad_s": "rad/s, rotor 1 (back-left)",
    "n2_rad_s": "rad/s, rotor 2 (back-right)",
    "n3_rad_s": "rad/s, rotor 3 (front-right)",
}
OPTIONAL: dict[str, str] = {
    "ax_m_s2": "m/s^2, world, kinematic (gravity removed); else differentiated from velocity",
    "ay_m_s2": "m/s^2",
    "az_m_s2": "m/s^2",
    "battery_v": "V",
}
# Unit names a mapping may give, as factors into the format's units.
UNIT_FACTORS: dict[str, float] = {
    "s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9,
    "m": 1.0, "cm": 1e-2, "mm": 1e-3,
    "m/s": 1.0, "cm/s": 1e-2, "mm/s": 1e-3,
    "rad/s": 1.0, "deg/s": math.pi / 180.0, "rpm": 2.0 * math.pi / 60.0,
    "m/s^2": 1.0, "g": 9.81, "mg": 9.81e-3,
    "V": 1.0, "mV": 1e-3, "1": 1.0,
}  # fmt: skip
VECTORS = (("x_m", "y_m", "z_m"), ("vx_m_s", "vy_m_s", "vz_m_s"), ("ax_m_s2", "ay_m_s2", "az_m_s2"))
RATES = ("p_rad_s", "q_rad_s", "r_rad_s")
QUAT = ("qw", "qx", "qy", "qz")
ROTORS = ("n0_rad_s", "n1_rad_s", "n2_rad_s", "n3_rad_s")


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


@dataclass(frozen=True)
class FlightLog:
    """One flight as arrays (N rows), in the format's frames and units."""

    name: str
    time_s: np.ndarray
    position_m: np.ndarray  # (N, 3)
    velocity_m_s: np.ndarray  # (N, 3)
    quaternion: np.ndarray  # (N, 4) w, x, y, z
    body_rates_rad_s: np.ndarray  # (N, 3)
    rotor_speeds_rad_s: np.ndarray  # (N, 4) commands
    acceleration_m_s2: np.ndarray | None = None  # (N, 3) world, kinematic
    battery_v: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.time_s)

    def table(self) -> dict[str, np.ndarray]:
        """The log as format columns."""
        cols = {"time_s": self.time_s}
        for names, arr in zip(
            VECTORS, (self.position_m, self.velocity_m_s, self.acceleration_m_s2), strict=True
        ):
            if arr is not None:
                cols.update({n: arr[:, i] for i, n in enumerate(names)})
        cols.update({n: self.quaternion[:, i] for i, n in enumerate(QUAT)})
        cols.update({n: self.body_rates_rad_s[:, i] for i, n in enumerate(RATES)})
        cols.update({n: self.rotor_speeds_rad_s[:, i] for i, n in enumerate(ROTORS)})
        if self.battery_v is not None:
            cols["battery_v"] = self.battery_v
        return cols


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


def read_log(path: Path, mapping: ColumnMapping | None = None) -> FlightLog:
    """A CSV or Parquet flight log through `mapping` (default: our own column names), or one
    of our rerun recordings (.rrd)."""
    path = Path(path)
    if path.suffix == ".rrd":  # our own recordings: their layout is fixed, no mapping
        from learner.gap.recording_log import read_recording_log

        return read_recording_log(path)
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


def write_log(log: FlightLog, path: Path) -> Path:
    """Write `log` as our CSV (with a JSON sidecar of its meta) or Parquet."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    cols = log.table()
    if path.suffix == ".parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        pq.write_table(pa.table(cols), path)
    else:
        names = list(cols)
        data = np.column_stack([cols[n] for n in names])
        with path.open("w", newline="") as f:
            f.write("# groundfx flight log; columns and units: learner/gap/logs.py\n")
            w = csv.writer(f)
            w.writerow(names)
            w.writerows([f"{v:.9g}" for v in row] for row in data)
    if log.meta:
        path.with_suffix(".json").write_text(json.dumps(log.meta, indent=1))
    return path


def add_noise(log: FlightLog, noise: dict[str, float], seed: int) -> FlightLog:
    """The log with white Gaussian sensor noise (standard deviations in format units):
    position_m, velocity_m_s, attitude_rad (small rotation), rates_rad_s, rotor_rad_s,
    accel_m_s2."""
    rng = np.random.default_rng(seed)

    def noisy(a: np.ndarray | None, key: str) -> np.ndarray | None:
        return None if a is None else a + rng.normal(0.0, noise.get(key, 0.0), a.shape)

    half = rng.normal(0.0, noise.get("attitude_rad", 0.0) / 2.0, (len(log), 3))
    dq = np.column_stack([np.ones(len(log)), half])
    q = _quat_mul(log.quaternion, dq)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return FlightLog(
        log.name,
        log.time_s,
        noisy(log.position_m, "position_m"),
        noisy(log.velocity_m_s, "velocity_m_s"),
        q,
        noisy(log.body_rates_rad_s, "rates_rad_s"),
        noisy(log.rotor_speeds_rad_s, "rotor_rad_s"),
        noisy(log.acceleration_m_s2, "accel_m_s2"),
        log.battery_v,
        {**log.meta, "noise": noise, "noise_seed": seed},
    )


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    aw, ax, ay, az = a.T
    bw, bx, by, bz = b.T
    return np.column_stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ]
    )
