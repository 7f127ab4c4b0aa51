"""The immutable weight snapshot the controller reads: published by one reference assignment."""

from __future__ import annotations

from dataclasses import dataclass

from learner.model import GroundEffectNet, Normaliser
from learner.online.methods import Arrays


@dataclass(frozen=True)
class Snapshot:
    version: int  # 0: the offline weights; +1 per accepted update
    net: GroundEffectNet  # read-only arrays: no reader can see a half-written update
    t_s: float  # simulated time it was published at
    loss: float | None = None  # the batch's standardised MSE before the update that made it


def make_snapshot(
    version: int,
    weights: Arrays,
    biases: Arrays,
    normaliser: Normaliser,
    header: dict,
    t_s: float,
    loss: float | None = None,
) -> Snapshot:
    return Snapshot(
        version, GroundEffectNet(list(weights), list(biases), normaliser, header), t_s, loss
    )
