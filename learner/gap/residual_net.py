"""The learnt residual's network: a small ReLU network from regime features (both a log and
the simulator have them: simbridge/effects/learned.py) to the force in the heading frame, with
spectral-norm bounded layers (a smooth force field), trained full-batch with Adam. An input
that hardly varies over the training rows is left out of the network: there is nothing to
learn from it, and on other flights its untrained weights would answer for it."""

from __future__ import annotations

import numpy as np
import torch

from learner.network import Adam, linear_layers, project_lipschitz
from simbridge.effects.learned import FEATURES, POSITION, ResidualModel

HIDDEN = (32, 32)
LAYER_BOUND = 3.0  # per-layer spectral norm in standardised units: a smooth force field
EPOCHS = 400
LR = 3e-3
MAX_ROWS = 8_000  # rows a training run uses (evenly spaced): enough for 18 inputs
# the inputs without a position: what holds wherever the vehicle flies
STATE_INPUTS = tuple(f for f in FEATURES if f not in POSITION)
# each input's natural scale (by name's start): one whose standard deviation over the
# training rows is under MIN_SPREAD of it is left out
INPUT_SCALES = {
    "height": 1.0, "tilt": 0.1, "body_z_up": 0.01, "horizontal_speed": 0.3, "travel": 1.0,
    "vz": 0.3, "thrust": 0.1, "time": 10.0, "x_m": 0.5, "y_m": 0.5,
}  # fmt: skip
MIN_SPREAD = 0.1


def varying(x: np.ndarray, inputs: tuple[str, ...]) -> tuple[str, ...]:
    """The `inputs` whose columns of (N, len(FEATURES)) `x` vary by at least MIN_SPREAD of
    their natural scale."""
    std = x.std(axis=0)
    out = []
    for name in inputs:
        scale = next(v for k, v in INPUT_SCALES.items() if name.startswith(k))
        if std[FEATURES.index(name)] >= MIN_SPREAD * scale:
            out.append(name)
    return tuple(out)


def train_model(
    x: np.ndarray,
    y: np.ndarray,
    seed: int = 0,
    epochs: int = EPOCHS,
    max_rows: int = MAX_ROWS,
    lr: float = LR,
    inputs: tuple[str, ...] = STATE_INPUTS,
) -> ResidualModel:
    """A ReLU network from the `inputs` that vary (`varying`) of (N, len(FEATURES)) `x` to
    the (N, 3) heading-frame force `y`, with spectral-norm bounded layers, full-batch Adam
    (step `lr`), on at most `max_rows` rows (evenly spaced) for `epochs` steps."""
    if len(x) > max_rows:
        keep = np.linspace(0, len(x) - 1, max_rows).astype(int)
        x, y = x[keep], y[keep]
    used = varying(x, inputs) or inputs
    x = x[:, [FEATURES.index(f) for f in used]]
    mean = x.mean(axis=0)
    std = np.maximum(x.std(axis=0), 1e-6)
    scale = float(max(np.sqrt(np.mean(y**2)), 1e-9))
    torch.manual_seed(seed)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # a tiny network: threads only contend (25 ms a step on 2 cores)
    try:
        return _train(x, y, mean, std, scale, epochs, lr, used)
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
    used: tuple[str, ...],
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
        used,
    )
