"""The learnt residual's network: a small ReLU network from regime features (both a log and
the simulator have them: simbridge/effects/learned.py) to the world-frame force, with
spectral-norm bounded layers (a smooth force field), trained full-batch with Adam."""

from __future__ import annotations

import numpy as np
import torch

from learner.network import Adam, linear_layers, project_lipschitz
from simbridge.effects.learned import FEATURES, ResidualModel

HIDDEN = (32, 32)
LAYER_BOUND = 3.0  # per-layer spectral norm in standardised units: a smooth force field
EPOCHS = 400
LR = 3e-3
MAX_ROWS = 8_000  # rows a training run uses (evenly spaced): enough for 15 inputs


def train_model(
    x: np.ndarray,
    y: np.ndarray,
    seed: int = 0,
    epochs: int = EPOCHS,
    max_rows: int = MAX_ROWS,
    lr: float = LR,
) -> ResidualModel:
    """A ReLU network x -> y (N) with spectral-norm bounded layers, full-batch Adam (step
    `lr`), on at most `max_rows` rows (evenly spaced) for `epochs` steps."""
    if len(x) > max_rows:
        keep = np.linspace(0, len(x) - 1, max_rows).astype(int)
        x, y = x[keep], y[keep]
    mean = x.mean(axis=0)
    std = np.maximum(x.std(axis=0), 1e-6)
    scale = float(max(np.sqrt(np.mean(y**2)), 1e-9))
    torch.manual_seed(seed)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # a tiny network: threads only contend (25 ms a step on 2 cores)
    try:
        return _train(x, y, mean, std, scale, epochs, lr)
    finally:
        torch.set_num_threads(threads)


def _train(
    x: np.ndarray,
    y: np.ndarray,
    mean: np.ndarray,
    std: np.ndarray,
    scale: float,
    epochs: int,
    lr: float,
) -> ResidualModel:
    sizes = (x.shape[1], *HIDDEN, 3)
    layers: list[torch.nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(torch.nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(torch.nn.ReLU())
    net = torch.nn.Sequential(*layers)
    xt = torch.tensor((x - mean) / std, dtype=torch.float32)
    yt = torch.tensor(y / scale, dtype=torch.float32)
    opt = Adam(net.parameters(), lr=lr, weight_decay=1e-4)
    for _ in range(epochs):
        opt.zero_grad()
        loss = torch.mean((net(xt) - yt) ** 2)
        loss.backward()
        opt.step()
        project_lipschitz(net, LAYER_BOUND)
    lin = linear_layers(net)
    return ResidualModel(
        tuple(layer.weight.detach().double().numpy().copy() for layer in lin),
        tuple(layer.bias.detach().double().numpy().copy() for layer in lin),
        mean,
        std,
        scale,
        FEATURES,
    )
