"""`groundfx bench model`: the controller's inference path, timed one sample at a time, beside
a reference measured in the same run: the same network, with the same weights, in torch (the
framework it was trained in: `build_network` and `import_weights`, eval mode, inference mode),
as a controller written with torch would call it for one sample. Both are timed in interleaved
blocks (a shared machine's load drifts) and checked to give the same forces."""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np

from learner.model import GroundEffectNet, load_model

BLOCKS = 10  # interleaved blocks of each path


def _timed(predict: Any, inputs: list[tuple[float, ...]], samples: int) -> np.ndarray:
    times = np.empty(samples)
    for k in range(samples):
        row = inputs[k % len(inputs)]
        t0 = time.perf_counter()
        predict(row)
        times[k] = time.perf_counter() - t0
    return times * 1e6


def torch_predictor(net: GroundEffectNet) -> Any:
    """The reference: `net` as torch runs it, one sample in, one force (N) out."""
    import torch

    from learner.network import build_network, import_weights

    layers = (net.weights[0].shape[1], *(w.shape[0] for w in net.weights))
    module = build_network(layers).double().eval()
    import_weights(module, net.weights, net.biases)
    n = net.normaliser

    def predict(features: tuple[float, ...]) -> np.ndarray:
        x = torch.from_numpy((np.asarray(features, dtype=np.float64) - n.x_mean) / n.x_std)
        with torch.inference_mode():
            return module(x).numpy() * n.y_std + n.y_mean

    return predict


def bench_model(network: str = "rho2", samples: int = 20000) -> dict[str, Any]:
    net = load_model(network)
    reference = torch_predictor(net)
    rng = np.random.default_rng(0)
    inputs = [
        tuple(row) for row in rng.normal(net.normaliser.x_mean, net.normaliser.x_std, (256, 12))
    ]
    # the same forces from both (float64 throughout), before anything is timed
    disagreement = max(float(np.max(np.abs(net.predict(r) - reference(r)))) for r in inputs)
    for row in inputs:  # warm up
        net.predict(row)
        reference(row)
    load_before = os.getloadavg()[0]
    block = max(1, samples // BLOCKS)
    ours, torch_us = [], []
    for _ in range(BLOCKS):
        ours.append(_timed(net.predict, inputs, block))
        torch_us.append(_timed(reference, inputs, block))
    us, ref = np.concatenate(ours), np.concatenate(torch_us)
    p50, ref_p50 = float(np.percentile(us, 50)), float(np.percentile(ref, 50))
    return {
        "network": network,
        "predict_us_p50": p50,
        "predict_us_p99": float(np.percentile(us, 99)),
        "torch_us_p50": ref_p50,
        "torch_us_p99": float(np.percentile(ref, 99)),
        "speedup_over_torch": ref_p50 / p50,
        "max_force_difference_n": disagreement,
        "samples": len(us),
        "load_average": (load_before, os.getloadavg()[0]),
    }
