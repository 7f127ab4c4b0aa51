"""A learnt residual force: what the gap diagnosis could not name from its catalogue, carried
into the simulator as an effect (`learned_residual` in a world file, `model_path` an .npz
written by `groundfx gap diagnose`), so that the corrected world reproduces even an effect
outside the catalogue.

The model is a small ReLU network on regime features that both a flight log and the simulator
have at every step (`residual_features`): each rotor's height above the surface in rotor
radii (log-scaled; the ground effect's shape), the body z axis in the world (tilt), the
world-frame velocity (drag, wind), each rotor's thrust over a quarter of the weight (a weak
rotor) and the time since take-off (a thrust that decays over the flight). Its output is the
world-frame force in newtons. Inference is plain numpy: the simulator does not import torch.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simbridge.config import ConfigError, param

FEATURES: tuple[str, ...] = (
    "height_0", "height_1", "height_2", "height_3",  # log(1 + h / R), h capped at 40 R
    "body_z_x", "body_z_y", "body_z_z",
    "vx_m_s", "vy_m_s", "vz_m_s",
    "thrust_0", "thrust_1", "thrust_2", "thrust_3",  # C_T n_i^2 / (weight / 4)
    "time_since_takeoff_s",
)  # fmt: skip
HEIGHT_CAP_RADII = 40.0  # above this no surface acts on a rotor; an infinite height reads so


def residual_features(
    rotor_heights_m: np.ndarray,
    body_z: np.ndarray,
    velocity_m_s: np.ndarray,
    rotor_thrust_n: np.ndarray,
    time_since_takeoff_s: np.ndarray,
    rotor_radius_m: float,
    weight_n: float,
) -> np.ndarray:
    """(N, len(FEATURES)) features of N samples: rotor heights (N, 4) in m (inf: nothing
    below), body z axis in the world (N, 3), world velocity (N, 3), rotor thrusts (N, 4) in N
    and the time since take-off (N,) in s."""
    h = np.minimum(np.asarray(rotor_heights_m, dtype=float) / rotor_radius_m, HEIGHT_CAP_RADII)
    h = np.log1p(np.maximum(h, 0.0))
    thrust = np.asarray(rotor_thrust_n, dtype=float) / (weight_n / 4.0)
    t = np.asarray(time_since_takeoff_s, dtype=float).reshape(-1, 1)
    return np.column_stack([h, body_z, velocity_m_s, thrust, t])


@dataclass(frozen=True)
class ResidualModel:
    """A ReLU network with standardised inputs; output in newtons (world frame)."""

    weights: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]
    input_mean: np.ndarray
    input_std: np.ndarray
    output_scale_n: float
    features: tuple[str, ...] = FEATURES

    def force_n(self, features: np.ndarray) -> np.ndarray:
        """(N, 3) world-frame force of (N, F) features."""
        x = (np.atleast_2d(features) - self.input_mean) / self.input_std
        last = len(self.weights) - 1
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = x @ w.T + b
            if i < last:
                x = np.maximum(x, 0.0)
        return x * self.output_scale_n


def save_residual_model(path: Path, model: ResidualModel, meta: dict | None = None) -> Path:
    arrays = {f"w{i}": w for i, w in enumerate(model.weights)}
    arrays.update({f"b{i}": b for i, b in enumerate(model.biases)})
    np.savez(
        path,
        **arrays,
        input_mean=model.input_mean,
        input_std=model.input_std,
        output_scale_n=np.array(model.output_scale_n),
        features=np.array(model.features),
        meta=np.array(repr(meta or {})),
    )
    return path


@functools.lru_cache(maxsize=8)
def load_residual_model(path: str) -> ResidualModel:
    """The model at `path`; a missing or malformed file stops with a ConfigError."""
    try:
        with np.load(path, allow_pickle=False) as z:
            layers = sum(1 for k in z.files if k.startswith("w"))
            model = ResidualModel(
                tuple(np.asarray(z[f"w{i}"], dtype=float) for i in range(layers)),
                tuple(np.asarray(z[f"b{i}"], dtype=float) for i in range(layers)),
                np.asarray(z["input_mean"], dtype=float),
                np.asarray(z["input_std"], dtype=float),
                float(z["output_scale_n"]),
                tuple(str(x) for x in z["features"]),
            )
    except (OSError, KeyError, ValueError) as err:
        raise ConfigError(f"learned_residual.model_path: cannot read {path}: {err}") from None
    if model.features != FEATURES or layers == 0:
        raise ConfigError(
            f"learned_residual.model_path: {path} was written for the features "
            f"{list(model.features)}, this version reads {list(FEATURES)}"
        )
    return model


@dataclass(frozen=True)
class LearnedResidualParams:
    """A residual force learnt by `groundfx gap diagnose` (its `learned_residual.npz`)."""

    model_path: str = param("learned_residual.npz", doc="the model file (.npz); relative "
                            "paths are read from the world file's folder")  # fmt: skip
    scale: float = param(1.0, lo=0.0, hi=10.0, doc="multiplies the learnt force")


def learned_force_n(
    params: LearnedResidualParams,
    rotor_heights_m: tuple[float, ...],
    body_z: tuple[float, float, float],
    velocity_m_s: tuple[float, float, float],
    rotor_thrust_n: tuple[float, ...],
    time_since_takeoff_s: float,
    rotor_radius_m: float,
    weight_n: float,
) -> tuple[float, float, float]:
    """The learnt world-frame force at one simulator step."""
    model = load_residual_model(params.model_path)
    heights = np.array([h if math.isfinite(h) else np.inf for h in rotor_heights_m])
    x = residual_features(
        heights[None, :],
        np.array(body_z)[None, :],
        np.array(velocity_m_s)[None, :],
        np.array(rotor_thrust_n)[None, :],
        np.array([time_since_takeoff_s]),
        rotor_radius_m,
        weight_n,
    )
    f = model.force_n(x)[0] * params.scale
    return (float(f[0]), float(f[1]), float(f[2]))
