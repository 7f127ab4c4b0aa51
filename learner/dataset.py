"""Ground-effect datasets: self-describing columnar files (`.npz`: one array per column, and
a JSON header with column names and units, rho, vehicle, world, seed and version).

A row is one 100 Hz sample of a flight: the 12 features of thesis section 3.5, the measured
acceleration, commanded and actual rotor speeds, the target f_ge = m a - m g - R f_rotors of
equation 3.16, and the simulator's true ground effect (for evaluation only, never a target).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from learner.npzfile import read_npz
from simbridge.config import ConfigError

# Thesis 3.5.2 drops samples with f_ge,z outside [-1e-3, 1] N. Its targets were noise-free;
# ours come from a real accelerometer's readings (1.5 mN of white noise per sample, more in
# flight), and cutting at -1 mN would drop the lower tail of that noise far from the ground
# and bias the network upwards there. The lower bound is therefore at -20 mN (13 standard
# deviations of the noise): it still drops what no ground effect can be.
OUTLIER_RANGE_N = (-0.02, 1.0)


def inliers(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The rows kept for learning (offline and online alike): f_ge,z within OUTLIER_RANGE_N,
    every feature and target finite."""
    lo, hi = OUTLIER_RANGE_N
    return (
        (y[:, 2] >= lo)
        & (y[:, 2] <= hi)
        & np.all(np.isfinite(x), axis=1)
        & np.all(np.isfinite(y), axis=1)
    )


FORMAT = "groundfx-dataset"
VERSION = 1
FEATURES = ("z", "vx", "vy", "vz", "qw", "qx", "qy", "qz", "n0", "n1", "n2", "n3")
TARGETS = ("fge_x", "fge_y", "fge_z")
COLUMNS: dict[str, str] = {
    "time_s": "s",
    "z": "m (height of the centre of mass above the surface below)",
    "vx": "m/s",
    "vy": "m/s",
    "vz": "m/s",
    "qw": "1",
    "qx": "1",
    "qy": "1",
    "qz": "1",
    "n0": "rad/s",
    "n1": "rad/s",
    "n2": "rad/s",
    "n3": "rad/s",
    "ax": "m/s^2",
    "ay": "m/s^2",
    "az": "m/s^2",
    "n0_actual": "rad/s",
    "n1_actual": "rad/s",
    "n2_actual": "rad/s",
    "n3_actual": "rad/s",
    "fge_x": "N",
    "fge_y": "N",
    "fge_z": "N",
    "true_fge_x": "N",
    "true_fge_y": "N",
    "true_fge_z": "N",
}


@dataclass(frozen=True)
class Dataset:
    columns: dict[str, np.ndarray]
    meta: dict[str, Any]

    def __len__(self) -> int:
        return len(self.columns["time_s"])

    def matrix(self, names: tuple[str, ...]) -> np.ndarray:
        return np.stack([self.columns[n] for n in names], axis=1)


def save_dataset(path: Path, rows: np.ndarray, meta: dict[str, Any]) -> Path:
    """`rows` has one column per COLUMNS entry, in that order."""
    if rows.ndim != 2 or rows.shape[1] != len(COLUMNS):
        raise ValueError(f"expected rows with {len(COLUMNS)} columns, got {rows.shape}")
    header = {"format": FORMAT, "version": VERSION, "columns": COLUMNS, **meta}
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {name: rows[:, i] for i, name in enumerate(COLUMNS)}
    with path.open("wb") as f:
        np.savez_compressed(f, header=np.array(json.dumps(header)), **arrays)
    return path


def load_dataset(path: Path) -> Dataset:
    """A dataset file; anything else stops with a message naming the file."""

    def read(header: dict[str, Any], data: Any) -> Dataset:
        missing = [c for c in COLUMNS if c not in data.files]
        if missing:
            raise ConfigError(f"{path}: missing columns {', '.join(missing)}")
        columns = {c: np.asarray(data[c], dtype=float) for c in COLUMNS}
        return Dataset(columns, {k: v for k, v in header.items() if k != "columns"})

    return read_npz(path, FORMAT, VERSION, "dataset", read)
