"""Ground-effect model files and the controller's fast inference path.

A model file (`.npz`, no pickles) holds the weights and biases of each layer, the
normaliser (the offline training set's means and standard deviations of features and
targets), and a JSON header: format, version, feature and target order, layer sizes, the
Lipschitz bound and the training metadata. `GroundEffectNet.predict` is a plain numpy
forward pass of one sample: about 10 us, several times faster than torch for one sample.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from learner.bounds import LAYERS
from learner.dataset import FEATURES, TARGETS
from learner.npzfile import read_npz
from simbridge.config import ConfigError, resolve_packaged

FORMAT = "groundfx-ground-effect-model"
VERSION = 1
PACKAGED_DIR = Path(__file__).parent / "models"


@dataclass(frozen=True)
class Normaliser:
    x_mean: np.ndarray
    x_std: np.ndarray
    y_mean: np.ndarray
    y_std: np.ndarray

    @staticmethod
    def fit(x: np.ndarray, y: np.ndarray) -> Normaliser:
        """Thesis 3.5.2 (equation 2.28): each feature's mean and standard deviation; the
        targets' means, and one standard deviation shared by the three axes (the largest).

        The shared scale keeps the loss proportional to the error in newtons. Scaling each
        axis alone would blow the lateral targets, here measurement noise under 0.4 mN, up
        to unit variance: they would dominate the loss and the stopping rule, and the
        network would spend itself on noise instead of the vertical force.
        """
        x_std = x.std(axis=0)
        x_std = np.where(x_std > 1e-12, x_std, 1.0)  # a constant column stays as it is
        y_scale = max(float(y.std(axis=0).max()), 1e-12)
        return Normaliser(x.mean(axis=0), x_std, y.mean(axis=0), np.full(y.shape[1], y_scale))


class GroundEffectNet:
    """The current weights as an immutable snapshot, with a one-sample numpy forward pass."""

    def __init__(
        self,
        weights: list[np.ndarray],
        biases: list[np.ndarray],
        normaliser: Normaliser,
        header: dict[str, Any],
    ) -> None:
        self.weights = [np.ascontiguousarray(w, dtype=np.float64) for w in weights]
        self.biases = [np.ascontiguousarray(b, dtype=np.float64) for b in biases]
        self.normaliser = normaliser
        self.header = header
        n = normaliser
        self._x_scale = 1.0 / n.x_std
        self._x_shift = -n.x_mean / n.x_std
        for w in self.weights + self.biases:
            w.setflags(write=False)

    def predict(self, features: tuple[float, ...] | np.ndarray) -> np.ndarray:
        """The ground-effect force [N], world frame, for one sample of the 12 features."""
        h = np.asarray(features, dtype=np.float64) * self._x_scale + self._x_shift
        last = len(self.weights) - 1
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            h = w @ h + b
            if i < last:
                np.maximum(h, 0.0, out=h)
        return h * self.normaliser.y_std + self.normaliser.y_mean

    def predict_batch(self, features: np.ndarray) -> np.ndarray:
        h = (features - self.normaliser.x_mean) / self.normaliser.x_std
        last = len(self.weights) - 1
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            h = h @ w.T + b
            if i < last:
                h = np.maximum(h, 0.0)
        return h * self.normaliser.y_std + self.normaliser.y_mean


def save_model(path: Path, net: GroundEffectNet) -> Path:
    n = net.normaliser
    arrays = {f"w{i}": w for i, w in enumerate(net.weights)}
    arrays |= {f"b{i}": b for i, b in enumerate(net.biases)}
    header = {
        "format": FORMAT,
        "version": VERSION,
        "features": list(FEATURES),
        "targets": list(TARGETS),
        **net.header,
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as f:
        np.savez(
            f,
            header=np.array(json.dumps(header)),
            x_mean=n.x_mean,
            x_std=n.x_std,
            y_mean=n.y_mean,
            y_std=n.y_std,
            **arrays,
        )
    return path


def resolve_model_path(name_or_path: str | Path) -> Path:
    """A packaged network name (`rho1`, `rho2`) or a path to a model file."""
    return resolve_packaged(name_or_path, PACKAGED_DIR, ".npz", "network")


def load_model(name_or_path: str | Path) -> GroundEffectNet:
    """A model file; a wrong, damaged or foreign file stops with a message naming it."""
    path = resolve_model_path(name_or_path)

    def read(header: dict[str, Any], data: Any) -> tuple[Any, ...]:
        if tuple(header.get("features", ())) != FEATURES:
            raise ConfigError(
                f"{path}: features {header.get('features')} differ from {list(FEATURES)}"
            )
        layers = tuple(header.get("layers", LAYERS))
        weights = [np.asarray(data[f"w{i}"], dtype=np.float64) for i in range(len(layers) - 1)]
        biases = [np.asarray(data[f"b{i}"], dtype=np.float64) for i in range(len(layers) - 1)]
        normaliser = Normaliser(
            *(np.asarray(data[k], dtype=np.float64) for k in ("x_mean", "x_std", "y_mean", "y_std"))
        )
        return header, layers, weights, biases, normaliser

    header, layers, weights, biases, normaliser = read_npz(path, FORMAT, VERSION, "model", read)
    for i, (w, b) in enumerate(zip(weights, biases, strict=True)):
        if w.shape != (layers[i + 1], layers[i]) or b.shape != (layers[i + 1],):
            raise ConfigError(
                f"{path}: layer {i} has shape {w.shape}, expected {(layers[i + 1], layers[i])}"
            )
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
            raise ConfigError(f"{path}: layer {i} holds non-finite weights")
    return GroundEffectNet(
        weights,
        biases,
        normaliser,
        {k: v for k, v in header.items() if k not in ("format", "version")},
    )
