"""`composite` inside a flight's session: settings into standardised numbers, the network's
last layer to and from the coefficients, the grounds of a basis model file."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from learner.model import GroundEffectNet
from learner.online.composite import (
    CompositeConfig,
    CompositeState,
    Decision,
    Z,
    composite_update,
    grounds_from_header,
    initial_state,
)
from learner.online.methods import Arrays, forward_np
from learner.online.settings import OnlineSettings
from simbridge.config import ConfigError

LAMBDA_PER_S = 1.0  # the composite error s = (v_z - v_dz) + Lambda (z - z_d)


def composite_config(
    settings: OnlineSettings, target_scale_n: float, layer_bound: float
) -> CompositeConfig:
    noise = (settings.composite_noise_n / target_scale_n) ** 2
    return CompositeConfig(
        measurement_var=noise,
        noise_floor_var=noise,
        prior_scale=settings.composite_prior_scale,
        prior_isotropic=settings.composite_prior_p0,
        memory_samples=settings.composite_memory_samples,
        tracking_gain=settings.composite_tracking_n_s_m / target_scale_n,
        confidence=settings.composite_confidence,
        recall_confidence=settings.composite_recall_confidence,
        window=settings.composite_window,
        recall_window=settings.composite_recall_window,
        settle=settings.composite_settle,
        min_change=settings.composite_min_change_n / target_scale_n,
        far_var=(settings.composite_far_n / target_scale_n) ** 2,
        size_sd=settings.composite_size_sd,
        layer_bound=layer_bound,
    )


def start_state(base: GroundEffectNet, config: CompositeConfig) -> CompositeState:
    """The memory a basis model brings: its home ground (protected) and the grounds learnt
    in earlier flights; the other offline grounds shape the prior (where grounds differ).
    A flight starts on the home ground, whatever ground the file's last layer holds: before
    take-off nothing tells the grounds apart (a vehicle that starts on a ground pushing
    harder than the one under it may not leave it), and a learnt ground is recalled once
    the data show it."""
    header = base.header
    if not header.get("basis"):
        raise ConfigError(
            "online method 'composite' needs a model trained over several grounds "
            "(groundfx learn basis; the packaged `grounds`)"
        )
    n = base.weights[-1].shape[1]
    known, _ = grounds_from_header(header, n)
    home = header["basis"]["home"]
    memory = tuple(g for g in known if not g.protected or g.name == home)
    others = [g.coefficients for g in known if g.protected and g.name != home]
    names = [g.name for g in memory]
    far = np.asarray(header["basis"].get("far_moment") or np.zeros((n + 1, n + 1)))
    offset = float(base.normaliser.y_mean[Z] / base.normaliser.y_std[Z])
    state = initial_state(memory, names.index(home), others, config, far, offset)
    learnt = sum(1 for g in memory if g.name.startswith("learnt-"))
    return replace(state, learnt=learnt)


def starts_elsewhere(base: GroundEffectNet, state: CompositeState) -> bool:
    """Whether the file's last layer holds another ground than the one the flight starts on."""
    in_use = np.concatenate([base.weights[-1][Z], base.biases[-1][Z : Z + 1]])
    return not np.array_equal(in_use, state.published)


def basis_values(weights: Arrays, biases: Arrays, x: np.ndarray) -> np.ndarray:
    """phi(x) with its constant column, on standardised inputs."""
    h = forward_np(weights, biases, x, upto=len(weights) - 1)
    return np.concatenate([h, np.ones((len(x), 1))], axis=1)


def step(
    state: CompositeState,
    weights: Arrays,
    biases: Arrays,
    x: np.ndarray,
    y: np.ndarray,
    tracking_m_s: np.ndarray,
    config: CompositeConfig,
) -> tuple[CompositeState, Decision]:
    lateral = np.delete(weights[-1], Z, axis=0)
    return composite_update(
        state, basis_values(weights, biases, x), y[:, Z], tracking_m_s, lateral, config
    )


@dataclass(frozen=True)
class LastLayer:
    weights: Arrays
    biases: Arrays


def with_coefficients(weights: Arrays, biases: Arrays, a: np.ndarray) -> LastLayer:
    """The network with its vertical row replaced by the coefficients a."""
    w, b = weights[-1].copy(), biases[-1].copy()
    w[Z], b[Z] = a[:-1], a[-1]
    return LastLayer((*weights[:-1], w), (*biases[:-1], b))
