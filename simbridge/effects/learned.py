"""A learnt residual force: what the gap diagnosis could not name from its catalogue, carried
into the simulator as an effect (`learned_residual` in a world file, `model_path` an .npz
written by `groundfx gap diagnose`), so that the corrected world reproduces even an effect
outside the catalogue.

The model is a small ReLU network on regime features that both a flight log and the simulator
have at every step (`residual_features`), each relative to the body where physics has it so,
so that what is learnt on passes one way carries over to passes another way: each rotor's
height above the surface in rotor radii (log-scaled; the ground effect's shape), the tilt
(the body z axis in the heading frame: x forward, y left, z up), the horizontal speed and
the direction of travel in the heading frame (drag, wind, a ground effect that fades with
speed), the vertical speed, each rotor's thrust over a quarter of the weight (a weak rotor),
the time since take-off (a thrust that decays over the flight) and the position in the world
(a patch of floor unlike the rest; only where the flights disagree). Its output is the force
in newtons in the heading frame, turned into the world by the heading. A model names the
inputs it uses (`ResidualModel.features`). Inference is plain numpy: the simulator does not
import torch.
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
    "tilt_forward", "tilt_left", "body_z_up",  # the body z axis in the heading frame
    "horizontal_speed_m_s",
    "travel_forward", "travel_left",  # v_h / max(|v_h|, TRAVEL_SPEED_M_S), heading frame
    "vz_m_s",
    "thrust_0", "thrust_1", "thrust_2", "thrust_3",  # C_T n_i^2 / (weight / 4)
    "time_since_takeoff_s",
    "x_m", "y_m",  # the position in the world
)  # fmt: skip
POSITION: tuple[str, ...] = ("x_m", "y_m")
HEIGHT_CAP_RADII = 40.0  # above this no surface acts on a rotor; an infinite height reads so
# below this horizontal speed the direction of travel fades to nothing (a hover's velocity
# noise has no direction worth learning)
TRAVEL_SPEED_M_S = 0.2


def headings(rotation: np.ndarray) -> np.ndarray:
    """(N, 2) cos and sin of the heading: the body x axis's horizontal direction ((1, 0)
    where the body x axis is vertical) of (N, 3, 3) body-to-world rotations."""
    h = np.asarray(rotation, dtype=float)[:, :2, 0]
    norm = np.linalg.norm(h, axis=1, keepdims=True)
    return np.where(norm > 1e-9, h / np.maximum(norm, 1e-12), np.array([1.0, 0.0]))


def to_heading(vectors: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """(N, 3) world vectors in the heading frame (x forward, y left, z up)."""
    c, s = heading[:, 0], heading[:, 1]
    x, y = vectors[:, 0], vectors[:, 1]
    return np.column_stack([c * x + s * y, -s * x + c * y, vectors[:, 2]])


def from_heading(vectors: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """(N, 3) heading-frame vectors in the world."""
    c, s = heading[:, 0], heading[:, 1]
    x, y = vectors[:, 0], vectors[:, 1]
    return np.column_stack([c * x - s * y, s * x + c * y, vectors[:, 2]])


def residual_features(
    rotor_heights_m: np.ndarray,
    rotation: np.ndarray,
    position_m: np.ndarray,
    velocity_m_s: np.ndarray,
    rotor_thrust_n: np.ndarray,
    time_since_takeoff_s: np.ndarray,
    rotor_radius_m: float,
    weight_n: float,
) -> np.ndarray:
    """(N, len(FEATURES)) features of N samples: rotor heights (N, 4) in m (inf: nothing
    below), body-to-world rotations (N, 3, 3), world position (N, 3) and velocity (N, 3),
    rotor thrusts (N, 4) in N and the time since take-off (N,) in s."""
    h = np.minimum(np.asarray(rotor_heights_m, dtype=float) / rotor_radius_m, HEIGHT_CAP_RADII)
    h = np.log1p(np.maximum(h, 0.0))
    rotation = np.asarray(rotation, dtype=float)
    heading = headings(rotation)
    tilt = to_heading(rotation[:, :, 2], heading)
    v = to_heading(np.asarray(velocity_m_s, dtype=float), heading)
    speed = np.hypot(v[:, 0], v[:, 1])
    travel = v[:, :2] / np.maximum(speed, TRAVEL_SPEED_M_S)[:, None]
    thrust = np.asarray(rotor_thrust_n, dtype=float) / (weight_n / 4.0)
    t = np.asarray(time_since_takeoff_s, dtype=float).reshape(-1, 1)
    xy = np.asarray(position_m, dtype=float)[:, :2]
    return np.column_stack([h, tilt, speed, travel, v[:, 2], thrust, t, xy])


@dataclass(frozen=True)
class ResidualModel:
    """A ReLU network on the inputs `features` (of FEATURES) with standardised inputs; output
    in newtons in the heading frame."""

    weights: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]
    input_mean: np.ndarray
    input_std: np.ndarray
    output_scale_n: float
    features: tuple[str, ...] = FEATURES

    @functools.cached_property
    def columns(self) -> list[int]:
        """The model's inputs among FEATURES' columns."""
        return [FEATURES.index(f) for f in self.features]

    def heading_force_n(self, features: np.ndarray) -> np.ndarray:
        """(N, 3) heading-frame force of (N, len(FEATURES)) features."""
        x = (np.atleast_2d(features)[:, self.columns] - self.input_mean) / self.input_std
        last = len(self.weights) - 1
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = x @ w.T + b
            if i < last:
                x = np.maximum(x, 0.0)
        return x * self.output_scale_n

    def force_n(self, features: np.ndarray, heading: np.ndarray) -> np.ndarray:
        """(N, 3) world-frame force of (N, len(FEATURES)) features at (N, 2) `headings`."""
        return from_heading(self.heading_force_n(features), heading)


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
    unknown = [f for f in model.features if f not in FEATURES]
    if unknown or layers == 0 or len(model.input_mean) != len(model.features):
        raise ConfigError(
            f"learned_residual.model_path: {path} was written for the features "
            f"{list(model.features)}, this version reads some of {list(FEATURES)}"
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
    rotation: tuple[float, ...],
    position_m: tuple[float, float, float],
    velocity_m_s: tuple[float, float, float],
    rotor_thrust_n: tuple[float, ...],
    time_since_takeoff_s: float,
    rotor_radius_m: float,
    weight_n: float,
) -> tuple[float, float, float]:
    """The learnt world-frame force at one simulator step (`rotation`: the body-to-world
    matrix, row by row)."""
    model = load_residual_model(params.model_path)
    heights = np.array([h if math.isfinite(h) else np.inf for h in rotor_heights_m])
    r = np.array(rotation, dtype=float).reshape(1, 3, 3)
    x = residual_features(
        heights[None, :],
        r,
        np.array(position_m)[None, :],
        np.array(velocity_m_s)[None, :],
        np.array(rotor_thrust_n)[None, :],
        np.array([time_since_takeoff_s]),
        rotor_radius_m,
        weight_n,
    )
    f = model.force_n(x, headings(r))[0] * params.scale
    return (float(f[0]), float(f[1]), float(f[2]))
