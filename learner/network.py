"""The ground-effect network of thesis section 3.5.3 with a Lipschitz bound (equation 2.33).

12 -> 25 -> 30 -> 15 -> 3, ReLU. Spectral normalisation as Neural Lander applies it: after
every optimiser step each weight matrix whose spectral norm exceeds the per-layer bound
(default 4, learner.bounds says why not Neural Lander's 2) is scaled back onto it, so the
network's Lipschitz constant (in standardised units) is at most the product of the bounds.

The rotor speeds are the control input, and the controller finds the input that the
prediction itself depends on (a fixed point). Neural Lander's stability condition is that the
prediction's Lipschitz constant in the control input is below 1 (newtons of predicted force
per newton of thrust). The overall bound in standardised units is far looser than that: the
columns of the first layer that read the rotor speeds get their own, tighter bound
(`control_column_bound`). Without it the network learns the shortcut f_z = m g - thrust,
which fits every hover sample at any height and rho: near the ground that shortcut has a slope
of -1 in thrust, and the controller's fixed point drifts.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable

import numpy as np
import torch

from learner.bounds import (
    CONTROL_COLUMNS,
    DEFAULT_CONTROL_GAIN_BOUND,
    DEFAULT_LAYER_BOUND,
    LAYERS,
    control_column_bound,
)

__all__ = [
    "CONTROL_COLUMNS",
    "DEFAULT_CONTROL_GAIN_BOUND",
    "DEFAULT_LAYER_BOUND",
    "LAYERS",
    "control_column_bound",
]


def build_network(layers: tuple[int, ...] = LAYERS, seed: int = 0) -> torch.nn.Sequential:
    torch.manual_seed(seed)
    modules: list[torch.nn.Module] = []
    for i, (n_in, n_out) in enumerate(itertools.pairwise(layers)):
        modules.append(torch.nn.Linear(n_in, n_out))
        if i < len(layers) - 2:
            modules.append(torch.nn.ReLU())
    return torch.nn.Sequential(*modules)


def linear_layers(net: torch.nn.Sequential) -> list[torch.nn.Linear]:
    return [m for m in net if isinstance(m, torch.nn.Linear)]


@torch.no_grad()
def project_control_columns(w: torch.Tensor, bound: float | None) -> None:
    """The first layer's rotor-speed columns back to spectral norm <= bound (exact)."""
    if bound is None:
        return
    cols = list(CONTROL_COLUMNS)
    sigma = torch.linalg.matrix_norm(w[:, cols], ord=2)
    if sigma > bound:
        w[:, cols] *= bound / sigma


@torch.no_grad()
def project_lipschitz(
    net: torch.nn.Sequential, layer_bound: float, control_bound: float | None = None
) -> None:
    """Scale every weight matrix back to spectral norm <= layer_bound (exact, by SVD), and
    the rotor-speed columns to control_bound."""
    for layer in linear_layers(net):
        sigma = torch.linalg.matrix_norm(layer.weight, ord=2)
        if sigma > layer_bound:
            layer.weight.mul_(layer_bound / sigma)
    project_control_columns(linear_layers(net)[0].weight, control_bound)


class LipschitzProjector:
    """The projection after every optimiser step, with one power iteration per layer and
    step (as torch's spectral_norm estimates sigma): the weights move little between steps,
    so the persistent vectors track the top singular pair. A small margin covers what the
    estimate may miss; `finish` projects exactly once at the end."""

    def __init__(
        self,
        net: torch.nn.Sequential,
        layer_bound: float,
        seed: int = 0,
        control_bound: float | None = None,
    ) -> None:
        self.layers = linear_layers(net)
        self.bound = layer_bound
        self.control_bound = control_bound
        g = torch.Generator().manual_seed(seed)
        self.u = [torch.randn(layer.weight.shape[0], generator=g) for layer in self.layers]
        project_lipschitz(net, layer_bound, control_bound)
        for _ in range(20):
            self.step()

    @torch.no_grad()
    def step(self) -> None:
        for k, layer in enumerate(self.layers):
            w = layer.weight
            v = torch.nn.functional.normalize(w.t() @ self.u[k], dim=0)
            u = torch.nn.functional.normalize(w @ v, dim=0)
            self.u[k] = u
            sigma = torch.dot(u, w @ v)
            if sigma > self.bound * 0.999:
                w.mul_(self.bound * 0.999 / sigma)
        # a 25 x 4 block: the exact norm costs little
        project_control_columns(self.layers[0].weight, self.control_bound)

    def finish(self, net: torch.nn.Sequential) -> None:
        project_lipschitz(net, self.bound, self.control_bound)


def spectral_norms(weights: list[np.ndarray]) -> list[float]:
    return [float(np.linalg.norm(w, ord=2)) for w in weights]


def export_weights(net: torch.nn.Sequential) -> tuple[list[np.ndarray], list[np.ndarray]]:
    layers = linear_layers(net)
    return (
        [layer.weight.detach().numpy().astype(np.float64).copy() for layer in layers],
        [layer.bias.detach().numpy().astype(np.float64).copy() for layer in layers],
    )


@torch.no_grad()
def import_weights(
    net: torch.nn.Sequential, weights: list[np.ndarray], biases: list[np.ndarray]
) -> None:
    for layer, w, b in zip(linear_layers(net), weights, biases, strict=True):
        layer.weight.copy_(torch.tensor(np.array(w), dtype=layer.weight.dtype))
        layer.bias.copy_(torch.tensor(np.array(b), dtype=layer.bias.dtype))


class Adam:
    """torch.optim.Adam's update (single-tensor path, L2 `weight_decay` added to the
    gradient), without torch.optim: an optimiser's first construction imports torch._dynamo
    (1.7 s on these machines), which a diagnosis or a flight's learner process would pay once
    per process for a few hundred steps of a tiny network."""

    def __init__(
        self,
        params: Iterable[torch.Tensor],
        lr: float,
        weight_decay: float = 0.0,
        betas: tuple[float, float] = (0.9, 0.999),
        eps: float = 1e-8,
    ) -> None:
        self.params = list(params)
        self.lr, self.weight_decay, self.betas, self.eps = lr, weight_decay, betas, eps
        self.m = [torch.zeros_like(p) for p in self.params]
        self.v = [torch.zeros_like(p) for p in self.params]
        self.steps = 0

    def zero_grad(self) -> None:
        for p in self.params:
            p.grad = None

    @torch.no_grad()
    def step(self) -> None:
        self.steps += 1
        b1, b2 = self.betas
        step_size = self.lr / (1.0 - b1**self.steps)
        correction2_sqrt = (1.0 - b2**self.steps) ** 0.5
        for p, m, v in zip(self.params, self.m, self.v, strict=True):
            if p.grad is None:
                continue
            g = p.grad if self.weight_decay == 0.0 else p.grad.add(p, alpha=self.weight_decay)
            m.lerp_(g, 1.0 - b1)
            v.mul_(b2).addcmul_(g, g, value=1.0 - b2)
            p.addcdiv_(m, (v.sqrt() / correction2_sqrt).add_(self.eps), value=-step_size)
