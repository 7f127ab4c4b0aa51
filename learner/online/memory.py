"""Stored offline samples for `replay` and `ewc`: a small file beside the model it came with.

`learner/models/rho1.memory.npz` goes with `rho1.npz`: features and targets (raw units) of
samples drawn from the offline training data (outliers dropped as in training).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from learner.dataset import Dataset
from learner.npzfile import read_npz
from simbridge.config import ConfigError

FORMAT = "groundfx-online-memory"
VERSION = 1


@dataclass(frozen=True)
class Memory:
    x: np.ndarray  # (n, 12) features
    y: np.ndarray  # (n, 3) targets [N]
    header: dict


def make_memory(datasets: list[Dataset], samples: int, seed: int = 0) -> Memory:
    from learner.train import training_arrays

    x, y, _ = training_arrays(datasets)
    pick = np.random.default_rng(seed).choice(len(x), size=min(samples, len(x)), replace=False)
    rho = sorted({d.meta.get("rho") for d in datasets if d.meta.get("rho") is not None})
    return Memory(x[pick], y[pick], {"rho": rho, "seed": seed, "samples": len(pick)})


def save_memory(path: Path, memory: Memory) -> Path:
    header = {"format": FORMAT, "version": VERSION, **memory.header}
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as f:
        np.savez_compressed(f, header=np.array(json.dumps(header)), x=memory.x, y=memory.y)
    return path


def memory_path_for(model_path: Path) -> Path:
    """Where the memory of a model file lives: `NAME.memory.npz` beside `NAME.npz`."""
    return model_path.with_name(model_path.stem + ".memory.npz")


def offline_path_for(model_path: Path) -> Path:
    """Where an adapted model keeps the offline weights it came from: `NAME.offline.npz`.
    The protecting methods hold on to those, not to whatever the last flight left."""
    return model_path.with_name(model_path.stem + ".offline.npz")


def load_memory(path: Path) -> Memory:
    def read(header: dict, data: object) -> Memory:
        x = np.asarray(data["x"], dtype=np.float64)  # type: ignore[index]
        y = np.asarray(data["y"], dtype=np.float64)  # type: ignore[index]
        if x.ndim != 2 or x.shape[1] != 12 or y.shape != (len(x), 3) or len(x) == 0:
            raise ConfigError(f"{path}: expected x (n, 12) and y (n, 3), got {x.shape}, {y.shape}")
        return Memory(x, y, {**header, "path": str(path)})

    return read_npz(path, FORMAT, VERSION, "online memory", read)
