"""A basis phi(x) shared by several grounds, each ground a point a in its span (Neural-Fly).

The ground-effect estimate is f(x) = phi(x)^T a: phi is the network's hidden layers
(12 -> 25 -> 30 -> 15, ReLU, and a constant 1), learnt offline over several grounds (one
dataset per rho or surface); a (16 x 3, the last layer) is what differs between grounds and
what the vehicle adapts online (learner/online/composite.py).

Training in the manner of Neural-Fly's DAIML (O'Connell et al., Science Robotics 2022,
algorithm 1): at every step, for each ground k, the best coefficients a_k* for the current
basis are solved in closed form (ridge least squares) on an adaptation batch of that
ground, and the loss is the error of phi(x)^T a_k* on another batch of the same ground; so
phi is trained to be a basis in which every ground is linear, not to fit one ground. An
adversarial term (a small classifier that tries to tell the ground from phi(x); the basis
is rewarded for fooling it, weight `adversarial_weight`) discourages phi from encoding the
ground itself, which would make a ground-specific basis instead of a shared one. Every layer
keeps the spectral-norm bounds of the single-ground network (learner.network), including the
rotor-speed columns' bound, after every step; the heads are projected to the layer bound.

After training, each ground's coefficients are the ridge fit on all its training samples;
the file is an ordinary model file whose last layer is the home ground's (the ground the
vehicle flies on unless it learns otherwise), with every ground's coefficients in its
header (`grounds`), so that the controller's inference path is unchanged.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch

from learner.dataset import FEATURES, TARGETS, Dataset, inliers
from learner.model import GroundEffectNet, Normaliser
from learner.network import (
    CONTROL_COLUMNS,
    DEFAULT_LAYER_BOUND,
    LAYERS,
    Adam,
    LipschitzProjector,
    build_network,
    export_weights,
    import_weights,
    spectral_norms,
)
from simbridge.config import param

FAR_ABOVE_M = 0.5  # far from the surface: every ground's effect is below a millinewton


@dataclass(frozen=True)
class BasisConfig:
    learning_rate: float = param(1e-3, lo=0.0, hi=1.0, lo_open=True, doc="Adam step size")
    batch_size: int = param(64, lo=8, hi=100000, doc="training batch per ground and step")
    adaptation_batch: int = param(
        256, lo=16, hi=100000, doc="batch per ground the coefficients a* are solved on"
    )
    ridge: float = param(1e-3, lo=0.0, hi=1e3, doc="ridge weight of the a* solve (standardised)")
    adversarial_weight: float = param(
        0.1, lo=0.0, hi=100.0, doc="alpha: reward for fooling the ground classifier (0: none)"
    )
    classifier_every: int = param(2, lo=1, hi=1000, doc="basis steps per classifier step")
    max_epochs: int = param(300, lo=1, hi=100000, doc="at most this many epochs")
    patience: int = param(30, lo=1, hi=100000, doc="epochs without improvement before stopping")
    validation_fraction: float = param(0.2, lo=0.0, hi=0.9, lo_open=True, doc="held out")
    layer_bound: float = param(
        DEFAULT_LAYER_BOUND, lo=0.0, hi=100.0, lo_open=True, doc="spectral norm bound per layer"
    )
    control_gain_bound: float = param(
        1.0, lo=0.0, hi=100.0, doc="bound on |d f_ge / d thrust| near hover, N/N (0: none)"
    )
    seed: int = param(0, lo=0, hi=2**31 - 1, doc="split, initialisation and batch order")


def ground_name(dataset: Dataset) -> str:
    """What a dataset's ground is called: its `ground` key, else its world and rho."""
    meta = dataset.meta
    if meta.get("ground"):
        return str(meta["ground"])
    world = str(meta.get("world_name") or "")
    rho = meta.get("rho")
    prefix = "" if world in ("", "default") else f"{world}-"
    return f"{prefix}rho{rho:g}" if rho is not None else prefix or "ground"


def with_constant(h: torch.Tensor) -> torch.Tensor:
    return torch.cat([h, torch.ones(len(h), 1, dtype=h.dtype)], dim=1)


def solve_coefficients(phi: torch.Tensor, y: torch.Tensor, ridge: float) -> torch.Tensor:
    """a* = argmin |phi a - y|^2 + ridge |a|^2 (phi with its constant column): (16, 3)."""
    n = phi.shape[1]
    gram = phi.T @ phi + ridge * len(phi) * torch.eye(n, dtype=phi.dtype)
    return torch.linalg.solve(gram, phi.T @ y)


def normalised(a: torch.Tensor, layer_bound: float) -> torch.Tensor:
    """a* with its weight part scaled back to spectral norm <= layer_bound (Neural-Fly
    normalises a* the same way): the basis learns to work with heads the bound allows."""
    sigma = torch.linalg.matrix_norm(a[:-1], ord=2)
    if sigma <= layer_bound:
        return a
    scale = torch.ones(len(a), 1, dtype=a.dtype)
    scale[:-1] = layer_bound / sigma
    return a * scale


def head_arrays(a: np.ndarray, layer_bound: float) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients (16, 3) as a last layer (weights (3, 15), biases (3,)), the weights
    projected back to the layer bound."""
    w, b = a[:-1].T.copy(), a[-1].copy()
    sigma = float(np.linalg.norm(w, 2))
    if sigma > layer_bound:
        w *= layer_bound / sigma
    return w, b


def train_basis(
    grounds: dict[str, list[Dataset]],
    home: str,
    config: BasisConfig = BasisConfig(),
    progress: bool = True,
    sources: list[str] | None = None,
) -> tuple[GroundEffectNet, dict[str, Any]]:
    """The basis and every ground's coefficients; the model's last layer is `home`'s."""
    from tqdm import tqdm

    from learner.train import _control_bound

    if home not in grounds:
        raise ValueError(f"home ground {home!r} is not among {sorted(grounds)}")
    if len(grounds) < 2:
        raise ValueError("a shared basis needs at least two grounds")
    t0 = time.perf_counter()
    torch.set_num_threads(1)
    rng = np.random.default_rng(config.seed)
    names = sorted(grounds)
    data: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name in names:
        x = np.concatenate([d.matrix(FEATURES) for d in grounds[name]])
        y = np.concatenate([d.matrix(TARGETS) for d in grounds[name]])
        keep = inliers(x, y)
        data[name] = (x[keep], y[keep])
    split: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name in names:
        order = rng.permutation(len(data[name][0]))
        n_val = max(1, round(config.validation_fraction * len(order)))
        split[name] = (order[n_val:], order[:n_val])
    norm = Normaliser.fit(
        np.concatenate([data[k][0][split[k][0]] for k in names]),
        np.concatenate([data[k][1][split[k][0]] for k in names]),
    )

    def tensors(k: str, idx: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        x, y = data[k][0][idx], data[k][1][idx]
        return (
            torch.as_tensor((x - norm.x_mean) / norm.x_std, dtype=torch.float32),
            torch.as_tensor((y - norm.y_mean) / norm.y_std, dtype=torch.float32),
        )

    train_t = {k: tensors(k, split[k][0]) for k in names}
    val_t = {k: tensors(k, split[k][1]) for k in names}
    control_bound = _control_bound(config, norm, [d for k in names for d in grounds[k]])  # type: ignore[arg-type]
    net = build_network(LAYERS, config.seed)
    basis = torch.nn.Sequential(*list(net)[:-1])  # 12 -> 25 -> 30 -> 15, ReLU after each
    projector = LipschitzProjector(net, config.layer_bound, config.seed, control_bound)
    optimiser = Adam(basis.parameters(), lr=config.learning_rate)
    classifier = torch.nn.Sequential(
        torch.nn.Linear(LAYERS[-2], 20), torch.nn.ReLU(), torch.nn.Linear(20, len(names))
    )
    classifier_opt = Adam(classifier.parameters(), lr=config.learning_rate)
    generator = torch.Generator().manual_seed(config.seed)
    steps_per_epoch = max(1, min(len(t[0]) for t in train_t.values()) // config.batch_size)
    best: tuple[float, Any, int] = (np.inf, export_weights(net), 0)
    curve: list[float] = []
    step = 0
    bar = tqdm(range(config.max_epochs), unit="epoch", desc="basis", disable=not progress)
    for epoch in bar:
        basis.train()
        for _ in range(steps_per_epoch):
            loss = torch.zeros(())
            features, labels = [], []
            for i, k in enumerate(names):
                x, y = train_t[k]
                pick = torch.randint(len(x), (config.adaptation_batch + config.batch_size,),
                                     generator=generator)  # fmt: skip
                xa, ya = x[pick[: config.adaptation_batch]], y[pick[: config.adaptation_batch]]
                xt, yt = x[pick[config.adaptation_batch :]], y[pick[config.adaptation_batch :]]
                a = solve_coefficients(with_constant(basis(xa)), ya, config.ridge)
                a = normalised(a, config.layer_bound)
                phi_t = basis(xt)
                loss = loss + torch.mean((with_constant(phi_t) @ a - yt) ** 2)
                features.append(phi_t)
                labels.append(torch.full((len(xt),), i, dtype=torch.long))
            phi_all, label_all = torch.cat(features), torch.cat(labels)
            loss = loss / len(names)
            if config.adversarial_weight > 0.0:
                ce = torch.nn.functional.cross_entropy(classifier(phi_all), label_all)
                loss = loss - config.adversarial_weight * ce
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            projector.step()
            step += 1
            if config.adversarial_weight > 0.0 and step % config.classifier_every == 0:
                classifier_opt.zero_grad()
                ce = torch.nn.functional.cross_entropy(classifier(phi_all.detach()), label_all)
                ce.backward()
                classifier_opt.step()
        basis.eval()
        with torch.no_grad():
            val = float(np.mean([_ground_mse(basis, train_t[k], val_t[k], config) for k in names]))
        curve.append(val)
        bar.set_postfix(validation=f"{val:.5f}")
        if val < best[0] * (1 - 1e-3):
            best = (val, export_weights(net), epoch)
        elif epoch - best[2] >= config.patience:
            break
    bar.close()
    import_weights(net, *best[1])
    projector.finish(net)
    weights, biases = export_weights(net)
    heads: dict[str, dict[str, Any]] = {}
    metrics: dict[str, Any] = {"grounds": {}}
    for k in names:
        x, y = train_t[k]
        with torch.no_grad():
            a = solve_coefficients(with_constant(basis(x)), y, config.ridge).double().numpy()
        w, b = head_arrays(a, config.layer_bound)
        heads[k] = {"weights": w.tolist(), "biases": b.tolist()}
        ground_net = GroundEffectNet([*weights[:-1], w], [*biases[:-1], b], norm, {})
        xv, yv = data[k][0][split[k][1]], data[k][1][split[k][1]]
        rmse = np.sqrt(np.mean((ground_net.predict_batch(xv) - yv) ** 2, axis=0))
        metrics["grounds"][k] = {
            "samples": len(data[k][0]),
            "validation_rmse_n": {t: float(v) for t, v in zip(TARGETS, rmse, strict=True)},
        }
    far = far_moment(basis, [train_t[k][0] for k in names], norm)
    home_w = np.asarray(heads[home]["weights"])
    home_b = np.asarray(heads[home]["biases"])
    weights[-1], biases[-1] = home_w, home_b
    norms = spectral_norms(weights)
    metrics |= {
        "epochs": len(curve),
        "best_epoch": best[2],
        "validation_mse_standardised": float(best[0]),
        "layer_spectral_norms": norms,
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
        "basis": {
            "method": "daiml",
            "home": home,
            "grounds": heads,
            "far_moment": far.tolist(),
            "far_above_m": FAR_ABOVE_M,
        },
        "training": {
            **{k: v for k, v in metrics.items() if k != "config"},
            "config": asdict(config),
            "sources": sources or [],
            "rho": sorted({d.meta.get("rho") for k in names for d in grounds[k]} - {None}),
        },
    }
    return GroundEffectNet(weights, biases, norm, header), metrics


def far_moment(basis: torch.nn.Sequential, xs: list[torch.Tensor], norm: Normaliser) -> np.ndarray:
    """The second moment E[phi phi^T] (phi with its constant) of the samples at least
    FAR_ABOVE_M above the surface: a coefficient change d moves the prediction up there by
    sqrt(d^T M d) RMS (standardised). The online prior holds that near zero, where every
    ground's effect is nil."""
    x = torch.cat(xs)
    height_m = x[:, 0].numpy() * norm.x_std[0] + norm.x_mean[0]
    far = x[height_m >= FAR_ABOVE_M]
    n = LAYERS[-2] + 1
    if len(far) == 0:
        return np.zeros((n, n))
    with torch.no_grad():
        phi = with_constant(basis(far)).double().numpy()
    return phi.T @ phi / len(phi)


def _ground_mse(
    basis: torch.nn.Sequential,
    train: tuple[torch.Tensor, torch.Tensor],
    val: tuple[torch.Tensor, torch.Tensor],
    config: BasisConfig,
) -> float:
    """A ground's validation MSE with its coefficients fitted on (a part of) its training set."""
    x, y = train
    n = min(len(x), 4096)
    a = normalised(
        solve_coefficients(with_constant(basis(x[:n])), y[:n], config.ridge), config.layer_bound
    )
    return float(torch.mean((with_constant(basis(val[0])) @ a - val[1]) ** 2))
