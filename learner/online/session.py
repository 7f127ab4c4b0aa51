"""One flight's online learning, without threads or clocks: samples in, snapshots out.

Each new sample is standardised with the offline normaliser; every `holdout_every`-th goes
to the guard's buffer of recent held-back samples instead of training; once `batch_size`
training samples have arrived the method updates the weights, the guards judge the result,
and an accepted update becomes the next snapshot (version + 1). The caller (the autopilot's
learner thread, or the control loop itself in deterministic mode) owns the timing.
"""

from __future__ import annotations

import collections
from dataclasses import asdict, astuple, replace
from typing import Any

import numpy as np

from learner.bounds import DEFAULT_LAYER_BOUND
from learner.dataset import inliers
from learner.model import GroundEffectNet
from learner.online import composite_session
from learner.online.composite import CompositeState, grounds_to_header
from learner.online.guards import check_update
from learner.online.memory import Memory
from learner.online.methods import Anchor, RlsState, diagonal_fisher, forward_np, update
from learner.online.settings import NEEDS_BASIS, NEEDS_MEMORY, OnlineSettings
from learner.online.snapshot import Snapshot, make_snapshot
from simbridge.config import ConfigError


class OnlineSession:
    def __init__(
        self,
        base: GroundEffectNet,
        settings: OnlineSettings,
        memory: Memory | None = None,
        offline: GroundEffectNet | None = None,
    ) -> None:
        """`base`: the network the flight starts from; `offline`: the offline weights it came
        from, when `base` was adapted in an earlier flight (what the protecting methods hold
        on to and what a reset returns to; default `base`)."""
        self.base = base
        self.offline = offline if offline is not None else base
        self.memory = memory
        n = base.normaliser
        m = offline.normaliser if offline is not None else n
        if not all(np.array_equal(a, b) for a, b in zip(astuple(n), astuple(m), strict=True)):
            raise ConfigError(
                "online learning: the offline weights beside the model standardise their "
                "inputs differently (a different model's file?)"
            )
        self._x_mean, self._x_std, self._y_mean, self._y_std = n.x_mean, n.x_std, n.y_mean, n.y_std
        self.target_scale_n = float(np.max(n.y_std))
        self._anchor = Anchor(
            tuple(self.offline.weights),
            tuple(self.offline.biases),
            layer_bound=float(base.header.get("layer_bound", DEFAULT_LAYER_BOUND)),
            control_bound=base.header.get("control_column_bound"),
            output_offset=self._y_mean / self._y_std,
        )
        self.settings = settings
        self.snapshot = Snapshot(0, base, 0.0)
        self._x: list[np.ndarray] = []
        self._y: list[np.ndarray] = []
        self._s: list[float] = []  # the tracking error of each sample (composite)
        self._composite: CompositeState | None = None
        self.last_decision = ""
        # what became of the last update, in words: "accepted", "rejected: <why>", "held: ..."
        self.last_verdict = ""
        self._holdout: collections.deque[tuple[np.ndarray, np.ndarray]] = collections.deque(
            maxlen=settings.holdout_size
        )
        self._rls: RlsState | None = None
        self._seen = 0
        self.counts = collections.Counter[str]()
        self.reject_reasons = collections.Counter[str]()
        self.last_loss: float | None = None
        self.held_statistics: list[float] = []  # composite: each held update's likelihood ratio
        self.configure(settings)

    def configure(self, settings: OnlineSettings) -> None:
        """New method or hyperparameters (MAVLink parameters changed in flight)."""
        if settings.method in NEEDS_MEMORY and self.memory is None:
            raise ConfigError(
                f"online method {settings.method!r} needs stored offline samples: a "
                "NAME.memory.npz beside the model file (groundfx learn memory)"
            )
        if settings.method != self.settings.method:
            self._rls = None
        self.settings = settings
        if settings.method in NEEDS_BASIS:
            layer_bound = self._anchor.layer_bound
            self._composite_config = composite_session.composite_config(
                settings, self.target_scale_n, layer_bound
            )
            if self._composite is None:
                self._composite = composite_session.start_state(self.base, self._composite_config)
                if composite_session.starts_elsewhere(self.base, self._composite):
                    self._publish_composite(0.0, None)  # the home ground, before take-off
        if self._holdout.maxlen != settings.holdout_size:
            self._holdout = collections.deque(self._holdout, maxlen=settings.holdout_size)
        a = self._anchor
        if settings.method in NEEDS_MEMORY and a.memory_x is None:
            assert self.memory is not None
            mx, my = self._standardise(self.memory.x, self.memory.y)
            a = replace(a, memory_x=mx, memory_y=my)
        if settings.method == "ewc" and a.fisher_weights is None:
            assert a.memory_x is not None and a.memory_y is not None
            fw, fb = diagonal_fisher(a.weights, a.biases, a.memory_x, a.memory_y)
            a = replace(a, fisher_weights=fw, fisher_biases=fb)
        self._anchor = a

    def warm_up(self) -> None:
        """One update on a dummy batch, thrown away: the first update pays one-time costs
        (imports, ewc's Fisher set-up, numpy's linear algebra), which must not fall into the
        first update of a flight (with torch's optimiser it was over a second)."""
        n = self.settings.batch_size
        x, y = np.zeros((n, len(self._x_mean))), np.zeros((n, len(self._y_mean)))
        weights, biases = tuple(self.base.weights), tuple(self.base.biases)
        with np.errstate(all="ignore"):
            if self._composite is not None:
                composite_session.step(
                    self._composite, weights, biases, x, y, np.zeros(n), self._composite_config
                )
            else:
                update(weights, biases, x, y, self.settings, self._anchor, None, 0)

    def _standardise(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return (x - self._x_mean) / self._x_std, (y - self._y_mean) / self._y_std

    def add(
        self, features: np.ndarray, target_n: np.ndarray, t_s: float, tracking_m_s: float = 0.0
    ) -> Snapshot | None:
        """One sample (12 features, f_ge of equation 3.16 [N], the position loop's vertical
        composite error [m/s]); the new snapshot if this sample completed a batch whose
        update was accepted."""
        x, y = np.asarray(features, float), np.asarray(target_n, float)
        if not inliers(x[None, :], y[None, :])[0]:
            self.counts["outliers"] += 1  # as offline training drops them (thesis 3.5.2)
            return None
        return self._take(*self._standardise(x, y), t_s, float(tracking_m_s))

    def add_many(
        self,
        features: np.ndarray,
        targets_n: np.ndarray,
        times_s: np.ndarray,
        tracking_m_s: np.ndarray | None = None,
    ) -> list[tuple[float, Snapshot | None, float | None, str]]:
        """Samples in a block (rows as `add` takes them), with the same result as adding
        them one by one; for every update they triggered: (time, the new snapshot or None
        if the guards rejected it, the batch's loss before the update, its verdict)."""
        good = inliers(features, targets_n)
        self.counts["outliers"] += int(np.count_nonzero(~good))
        xs, ys = self._standardise(features[good], targets_n[good])
        track = np.zeros(len(times_s)) if tracking_m_s is None else tracking_m_s
        events: list[tuple[float, Snapshot | None, float | None, str]] = []
        for x, y, t_s, s_m_s in zip(xs, ys, times_s[good], track[good], strict=True):
            updates = self.counts["updates"]
            snapshot = self._take(x, y, float(t_s), float(s_m_s))
            if self.counts["updates"] != updates:
                events.append((float(t_s), snapshot, self.last_loss, self.last_verdict))
        return events

    def _take(
        self, x: np.ndarray, y: np.ndarray, t_s: float, tracking_m_s: float = 0.0
    ) -> Snapshot | None:
        """A standardised sample: to the guard's buffer or the batch; the update when full."""
        self._seen += 1
        self.counts["samples"] += 1
        if self._seen % self.settings.holdout_every == 0:
            self._holdout.append((x, y))
            return None
        self._x.append(x)
        self._y.append(y)
        self._s.append(tracking_m_s)
        batch = self.settings.composite_batch if self._composite else self.settings.batch_size
        if len(self._x) < batch:
            return None
        bx, by, bs = np.array(self._x), np.array(self._y), np.array(self._s)
        self._x, self._y, self._s = [], [], []
        if self._composite is not None:
            return self._composite_update(bx, by, bs, t_s)
        return self._update(bx, by, t_s)

    def _composite_update(
        self, bx: np.ndarray, by: np.ndarray, bs: np.ndarray, t_s: float
    ) -> Snapshot | None:
        """`composite`: the estimate always moves; a snapshot only when the confidence test
        publishes a change (adapted, or a ground recalled)."""
        assert self._composite is not None
        s = self.snapshot
        weights, biases = tuple(s.net.weights), tuple(s.net.biases)
        self.counts["updates"] += 1
        self.last_loss = float(np.mean((forward_np(weights, biases, bx) - by) ** 2))
        # the tracking term only near the surface: far from it a hold's error is not the
        # ground's doing (and every ground agrees there)
        height_m = bx[:, 0] * self._x_std[0] + self._x_mean[0]
        bs = np.where(height_m < self.settings.composite_tracking_below_m, bs, 0.0)
        with np.errstate(all="ignore"):
            state, decision = composite_session.step(
                self._composite, weights, biases, bx, by, bs, self._composite_config
            )
        if not np.all(np.isfinite(state.estimate)) or not np.all(np.isfinite(state.covariance)):
            return self._reject("non-finite estimate")
        self._composite = state
        self.last_decision = decision.kind
        self.counts[decision.kind] += 1
        threshold = self._composite_config.confidence
        if decision.kind == "held" and decision.statistic > threshold:
            # confident of a change, but the estimate still moving or the change too small
            self.counts["settling"] += 1
            self.last_verdict = (
                f"held: likelihood ratio {decision.statistic:.3g} over the threshold "
                f"{threshold:g}, the estimate still converging or the change too small"
            )
            return None
        if decision.kind == "held":
            self.held_statistics.append(float(decision.statistic))
            self.last_verdict = (
                f"held: likelihood ratio {decision.statistic:.3g} under the confidence "
                f"threshold {threshold:g}"
            )
            return None
        self.counts["accepted"] += 1
        merged = f", merging {decision.merged}" if decision.merged else ""
        self.last_verdict = f"accepted ({decision.kind}{merged})"
        return self._publish_composite(t_s, self.last_loss)

    def held_evidence(self) -> dict[str, float] | None:
        """`composite`: why updates published nothing: their likelihood ratios (median and
        largest) against the threshold a change must pass."""
        if not self.held_statistics or self._composite is None:
            return None
        ratios = np.asarray(self.held_statistics)
        return {
            "median": float(np.median(ratios)),
            "max": float(ratios.max()),
            "threshold": float(self._composite_config.confidence),
            # over the threshold, held while the estimate converged or too small a change
            "over_threshold": int(self.counts["settling"]),
        }

    def _publish_composite(self, t_s: float, loss: float | None) -> Snapshot:
        assert self._composite is not None
        s = self.snapshot
        weights, biases = tuple(s.net.weights), tuple(s.net.biases)
        layer = composite_session.with_coefficients(weights, biases, self._composite.published)
        self.snapshot = make_snapshot(
            s.version + 1,
            layer.weights,
            layer.biases,
            self.base.normaliser,
            self.adapted_header(),
            t_s,
            loss,
        )
        return self.snapshot

    def _update(self, bx: np.ndarray, by: np.ndarray, t_s: float) -> Snapshot | None:
        s = self.snapshot
        old = (tuple(s.net.weights), tuple(s.net.biases))
        self.counts["updates"] += 1
        try:
            with np.errstate(all="ignore"):
                result = update(
                    *old, bx, by, self.settings, self._anchor, self._rls, self.counts["updates"]
                )
        except (FloatingPointError, np.linalg.LinAlgError, RuntimeError) as err:
            return self._reject(f"update failed ({type(err).__name__})")
        self.last_loss = result.loss_before
        hx = np.array([h[0] for h in self._holdout]).reshape(-1, len(self._x_mean))
        hy = np.array([h[1] for h in self._holdout]).reshape(-1, len(self._y_mean))
        verdict = check_update(
            old, (result.weights, result.biases), bx, hx, hy, self.target_scale_n, self.settings
        )
        if not verdict.accepted:
            return self._reject(verdict.reason)
        self._rls = result.rls
        self.counts["accepted"] += 1
        self.last_verdict = "accepted"
        self.snapshot = make_snapshot(
            s.version + 1,
            result.weights,
            result.biases,
            self.base.normaliser,
            self.adapted_header(),
            t_s,
            result.loss_before,
        )
        return self.snapshot

    def _reject(self, reason: str) -> None:
        self.counts["rejected"] += 1
        self.last_verdict = f"rejected: {reason}"
        # the kind of reason, without its numbers, so that counts add up
        self.reject_reasons[reason.split(" ")[0] + (" RMSE" if "RMSE" in reason else "")] += 1
        return None

    def reset(self, t_s: float) -> Snapshot:
        """Back to the offline weights (a new version, so readers see the change); the RLS
        prior is built again from them."""
        self._x, self._y, self._s = [], [], []
        self._holdout.clear()
        self._rls = None
        if self._composite is not None:
            self._composite = composite_session.start_state(self.offline, self._composite_config)
        self.counts["resets"] += 1
        self.snapshot = Snapshot(self.snapshot.version + 1, self.offline, t_s)
        return self.snapshot

    def known_grounds(self) -> dict[str, Any] | None:
        """`composite`: the grounds as known now (a learnt ground's memory follows the estimate
        between publications), for the model file saved after the flight."""
        if self._composite is None:
            return None
        return grounds_to_header(self.base.header, self._composite)["basis"]

    def adapted_header(self) -> dict[str, Any]:
        """The model file's header for the current snapshot: where it came from, how."""
        header = adapted_header(self.base.header, self.settings, self.snapshot.version, self.counts)
        return grounds_to_header(header, self._composite) if self._composite else header


def adapted_header(
    base_header: dict[str, Any], settings: OnlineSettings, version: int, counts: dict[str, int]
) -> dict[str, Any]:
    return {
        **base_header,
        "online": {
            "settings": asdict(settings),
            "version": version,
            "updates": counts.get("updates", 0),
            "accepted": counts.get("accepted", 0),
            "samples": counts.get("samples", 0),
        },
    }
