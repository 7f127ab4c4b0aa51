"""The gradient methods' arithmetic in numpy: the MLP's loss and its gradient by hand, the
penalties, Adam (torch's update rule, step for step) and the exact Lipschitz projection.

Why not torch: a batch of 64 through a 12-25-30-15-3 network is a few hundred small array
operations, and torch's per-operation overhead (autograd graph, dispatcher, optimiser
bookkeeping) made an update 5 ms, and its first one over a second. By hand in numpy an
update takes about a millisecond, which is what lets the learner keep up with a lockstep
flight at 15 times real time on a core the control loop leaves it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from learner.bounds import CONTROL_COLUMNS

Arrays = tuple[np.ndarray, ...]
GradientFn = Callable[[list[np.ndarray]], list[np.ndarray]]
ADAM_BETAS = (0.9, 0.999)  # torch.optim.Adam's defaults
ADAM_EPS = 1e-8


def loss_and_gradient(
    weights: list[np.ndarray], biases: list[np.ndarray], x: np.ndarray, y: np.ndarray
) -> tuple[float, list[np.ndarray], list[np.ndarray]]:
    """MSE over every output of the batch (torch.mean((f(x) - y) ** 2)) and its gradient."""
    hidden = [x]  # the input of every layer
    pre: list[np.ndarray] = []  # every hidden layer's pre-activation
    h = x
    last = len(weights) - 1
    for i, (w, b) in enumerate(zip(weights, biases, strict=True)):
        z = h @ w.T + b
        if i < last:
            pre.append(z)
            h = np.maximum(z, 0.0)
            hidden.append(h)
        else:
            h = z
    residual = h - y
    loss = float(np.mean(residual * residual))
    g = residual * (2.0 / residual.size)
    grad_w: list[np.ndarray] = [np.empty(0)] * len(weights)
    grad_b: list[np.ndarray] = [np.empty(0)] * len(weights)
    for i in range(last, -1, -1):
        grad_w[i] = g.T @ hidden[i]
        grad_b[i] = g.sum(axis=0)
        if i > 0:
            g = (g @ weights[i]) * (pre[i - 1] > 0.0)  # ReLU: no gradient at 0, as torch
    return loss, grad_w, grad_b


def penalty_gradient(
    method: str,
    params: list[np.ndarray],
    refs: Arrays,
    fisher: Arrays | None,
    penalty: float,
    margin: float,
) -> list[np.ndarray]:
    """d/dp of constraint: lambda sum (p - p0)^2; margin: lambda sum max(|p - p0| - m, 0)^2;
    ewc: lambda sum F (p - p0)^2."""
    out = []
    for k, (p, ref) in enumerate(zip(params, refs, strict=True)):
        d = p - ref
        if method == "margin":
            g = 2.0 * penalty * np.maximum(np.abs(d) - margin, 0.0) * np.sign(d)
        elif method == "ewc":
            assert fisher is not None
            g = 2.0 * penalty * fisher[k] * d
        else:
            g = 2.0 * penalty * d
        out.append(g)
    return out


def adam(
    params: list[np.ndarray],
    gradient: GradientFn,
    steps: int,
    learning_rate: float,
) -> None:
    """`steps` Adam steps from fresh moments, in place (torch.optim.Adam's arithmetic)."""
    b1, b2 = ADAM_BETAS
    m = [np.zeros_like(p) for p in params]
    v = [np.zeros_like(p) for p in params]
    for t in range(1, steps + 1):
        grads = gradient(params)
        step_size = learning_rate / (1.0 - b1**t)
        c2 = np.sqrt(1.0 - b2**t)
        for p, g, mk, vk in zip(params, grads, m, v, strict=True):
            mk *= b1
            mk += (1.0 - b1) * g
            vk *= b2
            vk += (1.0 - b2) * g * g
            p -= step_size * mk / (np.sqrt(vk) / c2 + ADAM_EPS)


def project(weights: list[np.ndarray], layer_bound: float, control_bound: float | None) -> None:
    """Every weight matrix back to spectral norm <= layer_bound (exact, by SVD): equation
    2.33; and the first layer's rotor-speed columns to their own bound. In place."""
    for w in weights:
        sigma = float(np.linalg.norm(w, ord=2))
        if sigma > layer_bound:
            w *= layer_bound / sigma
    if control_bound is not None:
        cols = list(CONTROL_COLUMNS)
        sigma = float(np.linalg.norm(weights[0][:, cols], ord=2))
        if sigma > control_bound:
            weights[0][:, cols] *= control_bound / sigma
