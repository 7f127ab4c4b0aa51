"""`groundfx bench model`: the controller's inference path, timed one sample at a time."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from learner.model import load_model


def bench_model(network: str = "rho2", samples: int = 20000) -> dict[str, Any]:
    net = load_model(network)
    rng = np.random.default_rng(0)
    inputs = [
        tuple(row) for row in rng.normal(net.normaliser.x_mean, net.normaliser.x_std, (256, 12))
    ]
    for row in inputs:  # warm up
        net.predict(row)
    times = np.empty(samples)
    for k in range(samples):
        row = inputs[k % len(inputs)]
        t0 = time.perf_counter()
        net.predict(row)
        times[k] = time.perf_counter() - t0
    us = times * 1e6
    return {
        "network": network,
        "predict_us_p50": float(np.percentile(us, 50)),
        "predict_us_p99": float(np.percentile(us, 99)),
        "samples": samples,
    }
