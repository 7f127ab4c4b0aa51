"""Offline training as the thesis did it (sections 3.5.2, 3.5.3).

Outliers: samples with f_ge,z outside [-1e-3, 1] N are dropped. Standardisation with the
training set's statistics, stored with the model. Random 80/20 split; Adam, learning rate
1e-3 for 10 epochs then 1e-4; batch 64; MSE; early stopping once the validation loss has not
improved by 0.1 % for `patience` epochs (at most `max_epochs`), keeping the best weights; the
Lipschitz projection after every optimiser step.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import torch
from tqdm import tqdm

from learner.dataset import FEATURES, TARGETS, Dataset, inliers
from learner.model import GroundEffectNet, Normaliser, save_model
from learner.network import (
    CONTROL_COLUMNS,
    DEFAULT_CONTROL_GAIN_BOUND,
    DEFAULT_LAYER_BOUND,
    LAYERS,
    LipschitzProjector,
    build_network,
    control_column_bound,
    export_weights,
    import_weights,
    spectral_norms,
)
from learner.plot_axes import plain_log_axis
from simbridge.config import param


@dataclass(frozen=True)
class TrainConfig:
    learning_rate: float = param(1e-3, lo=0.0, hi=1.0, lo_open=True, doc="first epochs")
    learning_rate_later: float = param(1e-4, lo=0.0, hi=1.0, lo_open=True, doc="after the switch")
    switch_epoch: int = param(10, lo=0, hi=100000, doc="epochs at the first learning rate")
    batch_size: int = param(64, lo=1, hi=100000, doc="mini-batch size")
    max_epochs: int = param(1000, lo=1, hi=100000, doc="at most this many epochs")
    patience: int = param(40, lo=1, hi=100000, doc="epochs without improvement before stopping")
    validation_fraction: float = param(0.2, lo=0.0, hi=0.9, lo_open=True, doc="held out")
    layer_bound: float = param(
        DEFAULT_LAYER_BOUND, lo=0.0, hi=100.0, lo_open=True, doc="spectral norm bound of each layer"
    )
    control_gain_bound: float = param(
        DEFAULT_CONTROL_GAIN_BOUND,
        lo=0.0,
        hi=100.0,
        doc="bound on |d f_ge / d thrust| near hover, N/N (0: none; learner.network)",
    )
    seed: int = param(0, lo=0, hi=2**31 - 1, doc="split, initialisation and batch order")


@dataclass(frozen=True)
class TrainResult:
    net: GroundEffectNet
    train_loss: list[float]
    validation_loss: list[float]
    metrics: dict[str, Any]


def training_arrays(datasets: list[Dataset]) -> tuple[np.ndarray, np.ndarray, int]:
    """Features and targets of all datasets with the outliers dropped; and how many were."""
    x = np.concatenate([d.matrix(FEATURES) for d in datasets])
    y = np.concatenate([d.matrix(TARGETS) for d in datasets])
    keep = inliers(x, y)
    return x[keep], y[keep], int((~keep).sum())


def train(
    datasets: list[Dataset],
    config: TrainConfig = TrainConfig(),
    progress: bool = True,
    sources: list[str] | None = None,
) -> TrainResult:
    t0 = time.perf_counter()
    torch.set_num_threads(1)  # a tiny network: threads cost more than they give
    x, y, dropped = training_arrays(datasets)
    if len(x) < 10:
        raise ValueError(f"only {len(x)} usable samples; gather more data")
    rng = np.random.default_rng(config.seed)
    order = rng.permutation(len(x))
    n_val = max(1, round(config.validation_fraction * len(x)))
    val_idx, train_idx = order[:n_val], order[n_val:]
    norm = Normaliser.fit(x[train_idx], y[train_idx])
    xs = torch.as_tensor((x - norm.x_mean) / norm.x_std, dtype=torch.float32)
    ys = torch.as_tensor((y - norm.y_mean) / norm.y_std, dtype=torch.float32)
    x_train, y_train, x_val, y_val = xs[train_idx], ys[train_idx], xs[val_idx], ys[val_idx]

    control_bound = _control_bound(config, norm, datasets)
    net = build_network(LAYERS, config.seed)
    projector = LipschitzProjector(net, config.layer_bound, config.seed, control_bound)
    # fused: one kernel per step instead of several per tensor (a third faster here)
    optimiser = torch.optim.Adam(net.parameters(), lr=config.learning_rate, fused=True)
    loss_fn = torch.nn.MSELoss()
    generator = torch.Generator().manual_seed(config.seed)
    train_curve: list[float] = []
    val_curve: list[float] = []
    best = (np.inf, export_weights(net), 0)
    bar = tqdm(range(config.max_epochs), unit="epoch", desc="train", disable=not progress)
    for epoch in bar:
        if epoch == config.switch_epoch:
            for group in optimiser.param_groups:
                group["lr"] = config.learning_rate_later
        net.train()
        perm = torch.randperm(len(x_train), generator=generator)
        xs, ys = x_train[perm], y_train[perm]  # shuffled once: batches are then views
        total = torch.zeros(())
        for start in range(0, len(perm), config.batch_size):
            xb, yb = xs[start : start + config.batch_size], ys[start : start + config.batch_size]
            optimiser.zero_grad()
            loss = loss_fn(net(xb), yb)
            loss.backward()
            optimiser.step()
            projector.step()
            total += loss.detach() * len(xb)
        net.eval()
        with torch.no_grad():
            val = loss_fn(net(x_val), y_val).item()
        train_curve.append(float(total) / len(x_train))
        val_curve.append(val)
        bar.set_postfix(train=f"{train_curve[-1]:.5f}", validation=f"{val:.5f}")
        if val < best[0] * (1 - 1e-3):
            best = (val, export_weights(net), epoch)
        elif epoch - best[2] >= config.patience and epoch >= config.switch_epoch:
            break
    bar.close()
    import_weights(net, *best[1])
    projector.finish(net)
    weights, biases = export_weights(net)
    norms = spectral_norms(weights)
    metrics = {
        "samples": len(x),
        "outliers_dropped": dropped,
        "train_samples": len(train_idx),
        "validation_samples": len(val_idx),
        "epochs": len(val_curve),
        "best_epoch": best[2],
        "validation_mse_standardised": float(best[0]),
        "train_mse_standardised": float(train_curve[best[2]]),
        "layer_spectral_norms": norms,
        "lipschitz_bound": float(np.prod(norms)),
        "control_column_norm": float(np.linalg.norm(weights[0][:, list(CONTROL_COLUMNS)], 2)),
        "wall_s": time.perf_counter() - t0,
        "config": asdict(config),
    }
    header = {
        "layers": list(LAYERS),
        "layer_bound": config.layer_bound,
        "lipschitz_bound": config.layer_bound ** (len(LAYERS) - 1),
        "control_gain_bound": config.control_gain_bound or None,
        "control_column_bound": control_bound,
        "training": {
            **metrics,
            "sources": sources or [],
            "rho": sorted({d.meta.get("rho") for d in datasets if d.meta.get("rho") is not None}),
        },
    }
    net_np = GroundEffectNet(weights, biases, norm, header)
    val_pred = net_np.predict_batch(x[val_idx])
    rmse = np.sqrt(np.mean((val_pred - y[val_idx]) ** 2, axis=0))
    metrics["validation_rmse_n"] = {t: float(v) for t, v in zip(TARGETS, rmse, strict=True)}
    return TrainResult(net_np, train_curve, val_curve, metrics)


def _control_bound(config: TrainConfig, norm: Normaliser, datasets: list[Dataset]) -> float | None:
    """The rotor-speed columns' bound for this data's vehicle and standardisation."""
    if config.control_gain_bound == 0.0:
        return None
    vehicle = datasets[0].meta.get("vehicle") or {}
    if "thrust_coefficient_n_s2" not in vehicle or "mass_kg" not in vehicle:
        from simbridge.vehicle import load_vehicle

        v = load_vehicle("nano")
        vehicle = {"thrust_coefficient_n_s2": v.thrust_coefficient_n_s2, "mass_kg": v.mass_kg}
    c_t = float(vehicle["thrust_coefficient_n_s2"])
    hover_rad_s = float(np.sqrt(float(vehicle["mass_kg"]) * 9.81 / (4.0 * c_t)))
    return control_column_bound(
        config.control_gain_bound,
        norm.x_std[list(CONTROL_COLUMNS)],
        float(norm.y_std[2]),
        c_t,
        hover_rad_s,
        config.layer_bound,
    )


def write_outputs(result: TrainResult, out: Path) -> dict[str, Path]:
    """The model file, and beside it the training curve (PNG) and the metrics (JSON)."""
    model = save_model(out, result.net)
    curve = out.with_suffix(".curve.png")
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.semilogy(result.train_loss, label="training")
    ax.semilogy(result.validation_loss, label="validation")
    plain_log_axis(ax.yaxis)
    ax.axvline(result.metrics["best_epoch"], color="0.6", ls="--", lw=0.8, label="kept")
    ax.set_xlabel("epoch")
    ax.set_ylabel("MSE (standardised targets)")
    trained_on = result.net.header.get("training", {}).get("rho") or []
    rhos = ", ".join(f"{r:g}" for r in trained_on) or "unknown"
    ax.set_title(f"Ground-effect network {out.stem}, offline training on rho {rhos}")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(curve, dpi=110)
    plt.close(fig)
    metrics = out.with_suffix(".metrics.json")
    metrics.write_text(json.dumps(result.metrics, indent=2) + "\n")
    return {"model": model, "curve": curve, "metrics": metrics}
