"""The guards an update must pass before its weights are published (pure functions).

An update is rejected, and the previous snapshot kept, when any weight or any prediction
on the batch or the held-back samples is not finite, or when the error on the held-back
buffer of recent samples (never trained on) grows beyond `guard_ratio` times its value
before the update plus a noise allowance `guard_slack_n`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from learner.online.methods import Arrays, forward_np
from learner.online.settings import OnlineSettings


@dataclass(frozen=True)
class Verdict:
    accepted: bool
    reason: str  # "" when accepted
    holdout_rmse_before_n: float | None = None
    holdout_rmse_after_n: float | None = None


def check_update(
    old: tuple[Arrays, Arrays],
    new: tuple[Arrays, Arrays],
    batch_x: np.ndarray,
    holdout_x: np.ndarray,
    holdout_y: np.ndarray,
    target_scale_n: float,
    settings: OnlineSettings,
) -> Verdict:
    """Whether the update `old` -> `new` may be published. Inputs and targets standardised;
    `target_scale_n` turns standardised target units into newtons."""
    if not all(np.all(np.isfinite(a)) for a in (*new[0], *new[1])):
        return Verdict(False, "non-finite weights")
    probe = np.concatenate([batch_x, holdout_x]) if len(holdout_x) else batch_x
    with np.errstate(all="ignore"):
        if not np.all(np.isfinite(forward_np(*new, probe))):
            return Verdict(False, "non-finite prediction")
    if len(holdout_x) == 0:
        return Verdict(True, "")
    before = float(np.sqrt(np.mean((forward_np(*old, holdout_x) - holdout_y) ** 2)))
    after = float(np.sqrt(np.mean((forward_np(*new, holdout_x) - holdout_y) ** 2)))
    before_n, after_n = before * target_scale_n, after * target_scale_n
    if after_n > settings.guard_ratio * before_n + settings.guard_slack_n:
        return Verdict(
            False,
            f"held-back RMSE {after_n * 1e3:.3f} mN > {settings.guard_ratio:g} x "
            f"{before_n * 1e3:.3f} mN + {settings.guard_slack_n * 1e3:g} mN",
            before_n,
            after_n,
        )
    return Verdict(True, "", before_n, after_n)
