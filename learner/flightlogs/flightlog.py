"""The flight-log format of the gap diagnosis: one `FlightLog` of arrays, its columns and
units, and our CSV/Parquet writer.

One row per control period; world x east, y north, z up; body x forward, y left, z up. A
row's acceleration and rotor commands describe the control period that ends at its `time_s`;
its state is the state at `time_s`.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from simbridge.config import ConfigError

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
VECTORS = (("x_m", "y_m", "z_m"), ("vx_m_s", "vy_m_s", "vz_m_s"), ("ax_m_s2", "ay_m_s2", "az_m_s2"))
RATES = ("p_rad_s", "q_rad_s", "r_rad_s")
QUAT = ("qw", "qx", "qy", "qz")
ROTORS = ("n0_rad_s", "n1_rad_s", "n2_rad_s", "n3_rad_s")


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


def write_log(log: FlightLog, path: Path) -> Path:
    """Write `log` as our CSV (with a JSON sidecar of its meta) or Parquet."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    cols = log.table()
    if path.suffix == ".parquet":
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError:
            raise ConfigError(
                f"{path}: writing Parquet needs pyarrow (pip install groundfx[parquet])"
            ) from None

        pq.write_table(pa.table(cols), path)
    else:
        names = list(cols)
        data = np.column_stack([cols[n] for n in names])
        with path.open("w", newline="") as f:
            f.write("# groundfx flight log; columns and units: learner/flightlogs/flightlog.py\n")
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
