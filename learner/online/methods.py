"""The online update rules as pure functions: (weights, batch, settings, anchor) -> weights.

Everything is in standardised units (the offline normaliser's): inputs, targets, losses.
The gradient methods take `settings.steps` Adam steps on the batch, from fresh optimiser
moments (no state survives an update but the weights), each followed by the exact Lipschitz
projection; `rls` solves for the last layer in closed form and carries its covariance.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from learner.bounds import DEFAULT_LAYER_BOUND
from learner.online.gradient import adam, loss_and_gradient, penalty_gradient, project
from learner.online.settings import NEEDS_MEMORY, OnlineSettings

if TYPE_CHECKING:  # torch only for ewc's Fisher information: the learner starts without it
    import torch

Arrays = tuple[np.ndarray, ...]


@dataclass(frozen=True)
class Anchor:
    """What the protecting methods hold on to: the offline weights, the diagonal Fisher
    information of the offline data (ewc; normalised to mean 1, so that its lambda compares
    with the constraint's) and stored offline samples (replay), standardised."""

    weights: Arrays
    biases: Arrays
    layer_bound: float = DEFAULT_LAYER_BOUND  # the model's own bounds (its header)
    control_bound: float | None = None  # the first layer's rotor-speed columns
    fisher_weights: Arrays | None = None
    fisher_biases: Arrays | None = None
    memory_x: np.ndarray | None = None
    memory_y: np.ndarray | None = None
    output_offset: np.ndarray | None = None  # y_mean / y_std: the standardised zero force


@dataclass(frozen=True)
class RlsState:
    covariance: np.ndarray  # P over the last hidden layer's outputs and a constant 1
    max_trace: float  # P's trace at the start: forgetting without excitation winds P up


@dataclass(frozen=True)
class Update:
    weights: Arrays
    biases: Arrays
    loss_before: float  # MSE of the batch's new samples, standardised, before the update
    loss_after: float
    rls: RlsState | None = None


def forward(ws: list[torch.Tensor], bs: list[torch.Tensor], x: torch.Tensor) -> torch.Tensor:
    import torch

    h = x
    for i, (w, b) in enumerate(zip(ws, bs, strict=True)):
        h = h @ w.T + b
        if i < len(ws) - 1:
            h = torch.relu(h)
    return h


def forward_np(
    weights: Arrays, biases: Arrays, x: np.ndarray, upto: int | None = None
) -> np.ndarray:
    """The network on standardised inputs; `upto`: stop after that many layers (features)."""
    h = x
    n = len(weights) if upto is None else upto
    for i in range(n):
        h = h @ weights[i].T + biases[i]
        if i < len(weights) - 1:
            h = np.maximum(h, 0.0)
    return h


def mse(weights: Arrays, biases: Arrays, x: np.ndarray, y: np.ndarray) -> float:
    return float(np.mean((forward_np(weights, biases, x) - y) ** 2))


def gradient_update(
    weights: Arrays,
    biases: Arrays,
    x: np.ndarray,
    y: np.ndarray,
    settings: OnlineSettings,
    anchor: Anchor,
    update_index: int = 0,
) -> Update:
    """`naive`, `constraint`, `margin`, `ewc`, `replay`: Adam on MSE + penalty."""
    loss_before = mse(weights, biases, x, y)
    xb, yb = x, y
    if settings.method == "replay" and settings.replay_samples > 0:
        assert anchor.memory_x is not None and anchor.memory_y is not None
        rng = np.random.default_rng((settings.seed, update_index))
        pick = rng.choice(len(anchor.memory_x), size=settings.replay_samples, replace=True)
        xb = np.concatenate([x, anchor.memory_x[pick]])
        yb = np.concatenate([y, anchor.memory_y[pick]])
    n = len(weights)
    params = [np.array(a, dtype=np.float64) for a in (*weights, *biases)]
    penalised = settings.method in ("constraint", "margin", "ewc") and settings.penalty != 0.0
    refs = (*anchor.weights, *anchor.biases)
    fisher = (
        (*anchor.fisher_weights, *anchor.fisher_biases)
        if settings.method == "ewc" and anchor.fisher_weights is not None
        else None
    )
    if settings.method == "ewc" and penalised and fisher is None:
        raise ValueError("online method 'ewc' needs the Fisher information of the offline data")

    def gradient(ps: list[np.ndarray]) -> list[np.ndarray]:
        _, gw, gb = loss_and_gradient(ps[:n], ps[n:], xb, yb)
        grads = [*gw, *gb]
        if penalised:
            extra = penalty_gradient(
                settings.method, ps, refs, fisher, settings.penalty, settings.margin
            )
            grads = [g + e for g, e in zip(grads, extra, strict=True)]
        return grads

    adam(params, gradient, settings.steps, settings.learning_rate)
    new_w, new_b = params[:n], params[n:]
    project(new_w, anchor.layer_bound, anchor.control_bound)  # the bounds, after the update
    return Update(tuple(new_w), tuple(new_b), loss_before, mse(new_w, new_b, x, y))


def initial_rls(
    weights: Arrays, biases: Arrays, settings: OnlineSettings, offset: np.ndarray | None = None
) -> RlsState:
    """P0 = p0 I + s^2 u u^T. u is the change of the last layer's vertical row that scales
    the offline prediction f_z by (1 + a): the size of the effect (rho, the surface) is a
    priori far less certain than its shape, so data from one height moves the prediction at
    every height in proportion, instead of only where the vehicle happens to be."""
    n = weights[-1].shape[1] + 1
    p = np.eye(n) * settings.rls_initial_covariance
    if settings.rls_scale_sd > 0.0:
        u = np.concatenate([weights[-1][2], biases[-1][2:3]])
        if offset is not None:
            u[-1] += offset[2]
        p += settings.rls_scale_sd**2 * np.outer(u, u)
    return RlsState(p, float(np.trace(p)))


def rls_update(
    weights: Arrays,
    biases: Arrays,
    x: np.ndarray,
    y: np.ndarray,
    settings: OnlineSettings,
    state: RlsState,
    layer_bound: float = DEFAULT_LAYER_BOUND,
) -> Update:
    """Recursive least squares on the last layer, sample by sample, with forgetting factor
    lambda: the hidden layers stay the offline features; [W b] of the last layer is the
    estimate, P its covariance (Neural-Fly's adaptation, in discrete form)."""
    loss_before = mse(weights, biases, x, y)
    phi_all = forward_np(weights, biases, x, upto=len(weights) - 1)
    phi_all = np.concatenate([phi_all, np.ones((len(x), 1))], axis=1)
    theta = np.concatenate([weights[-1], biases[-1][:, None]], axis=1)  # (3, n + 1)
    p = state.covariance.copy()
    lam = settings.forgetting
    for phi, target in zip(phi_all, y, strict=True):
        p_phi = p @ phi
        gain = p_phi / (lam + phi @ p_phi)
        theta = theta + np.outer(target - theta @ phi, gain)
        p = (p - np.outer(gain, p_phi)) / lam
        p = 0.5 * (p + p.T)  # keep it symmetric against rounding
    trace = float(np.trace(p))
    if trace > state.max_trace:  # bounded covariance: no wind-up without excitation
        p *= state.max_trace / trace
    last_w = theta[:, :-1].copy()
    project([last_w], layer_bound, None)  # the last layer's bound (no rotor-speed columns)
    new_w = (*weights[:-1], last_w)
    new_b = (*biases[:-1], theta[:, -1].copy())
    return Update(new_w, new_b, loss_before, mse(new_w, new_b, x, y), RlsState(p, state.max_trace))


def update(
    weights: Arrays,
    biases: Arrays,
    x: np.ndarray,
    y: np.ndarray,
    settings: OnlineSettings,
    anchor: Anchor,
    rls: RlsState | None = None,
    update_index: int = 0,
) -> Update:
    """One online update with the method `settings.method` on a standardised batch."""
    if settings.method in NEEDS_MEMORY and anchor.memory_x is None:
        raise ValueError(f"online method {settings.method!r} needs offline samples (memory)")
    if settings.method == "rls":
        return rls_update(
            weights,
            biases,
            x,
            y,
            settings,
            rls
            if rls is not None
            else initial_rls(weights, biases, settings, anchor.output_offset),
            anchor.layer_bound,
        )
    return gradient_update(weights, biases, x, y, settings, anchor, update_index)


def diagonal_fisher(
    weights: Arrays, biases: Arrays, x: np.ndarray, y: np.ndarray
) -> tuple[Arrays, Arrays]:
    """The empirical diagonal Fisher information of the (standardised) offline samples: the
    mean squared per-sample gradient of the squared error, normalised to mean 1."""
    import torch
    from torch.func import grad, vmap

    torch.set_num_threads(1)  # a tiny network beside a control loop: one core

    params = tuple(torch.tensor(a, dtype=torch.float64) for a in (*weights, *biases))
    n = len(weights)

    def sample_loss(
        ps: tuple[torch.Tensor, ...], xi: torch.Tensor, yi: torch.Tensor
    ) -> torch.Tensor:
        out = forward(list(ps[:n]), list(ps[n:]), xi[None, :])[0]
        return torch.sum((out - yi) ** 2)

    grads = vmap(grad(sample_loss), in_dims=(None, 0, 0))(
        params, torch.as_tensor(x, dtype=torch.float64), torch.as_tensor(y, dtype=torch.float64)
    )
    fisher = [(g**2).mean(dim=0).numpy() for g in grads]
    scale = np.mean(np.concatenate([f.ravel() for f in fisher]))
    fisher = [f / scale if scale > 0 else np.ones_like(f) for f in fisher]
    return tuple(fisher[:n]), tuple(fisher[n:])
