"""`composite`: the coefficients a of f = phi(x)^T a adapted online, with a memory of
grounds and a confidence test that leaves a correct model alone (pure functions).

The basis phi (the network's hidden layers and a constant, learner/basis.py) stays fixed;
only the vertical column a of the last layer moves (the lateral ground effect is zero here,
the lateral targets are measurement noise). In standardised units throughout.

- Estimate (Neural-Fly's composite adaptation, in discrete form): a Kalman filter on a,
  sample by sample, with measurement noise r and a random-walk process noise Q (the
  forgetting: after `memory_samples` samples without information the prior uncertainty is
  back). Its measurement is the composite target: the force of equation 3.16 plus the
  tracking term k s, s = (v_z - v_dz) + Lambda (z - z_d) the position loop's vertical
  composite error (Neural-Fly's a' = ... - P phi R^-1 (phi a - y) + P phi s): a vehicle
  that floats above its setpoint asks for more predicted force than its accelerometer
  shows, so that what the measurement cannot see (its bias, a lag) is learnt as well.
- Prior (`prior_covariance`): the size of the effect (a scale of the home prediction) and
  the directions in which the training grounds' coefficients differ are uncertain, every
  other direction nearly certain, and a change of the prediction far from the surface
  (0.5 m and more up, where every ground agrees) tightly bounded. a moves readily where
  grounds differ (near the surface), hardly elsewhere.
- No harm: the estimate is published (becomes the controller's model) only when, over the
  recent window of samples, it explains the composite target (the measured force plus the
  tracking error's) better than what is published by more than `confidence` in units of
  the noise variance (a likelihood-ratio test: (SSR_published - SSR_estimate) / sigma^2,
  sigma^2 inflated by the residual's lag-1 autocorrelation: correlated samples are fewer
  independent ones).
  A correct model is therefore left alone; a consistent error (the same sign sample after
  sample) passes the test within a fraction of a second. A change that passes is published
  once the estimate has converged (`settle`: its last batch improved its fit to the window
  by at most that much), not while it is still moving towards the data: an estimate
  published on the way would be published again within the second. A change that lowers
  the RMS error over the window by less than `min_change` is not worth a new model to the
  controller: the memory of a learnt ground in use takes it (for the next flight's recall),
  the controller does not (a refinement published every second or two, as the hold's
  operating point drifts, is a change the controller has to fly through each time).
- Memory: the grounds known (the offline training grounds, protected, and every ground
  learnt in flight) are kept with their coefficients. A ground is identified by how it
  pushes where the vehicle is now: when a stored ground explains the last `recall_window`
  samples better than what is published (a likelihood ratio against the noise of the
  stored ground's own residual; the threshold of a hypothesis fitted to nothing,
  `recall_confidence`, while the flight is on the ground it started on, the change's once
  it recalled or learnt one) and the fresh estimate does not explain them better by the
  change's threshold, it is recalled whole (estimate, publication and a fresh prior around
  it). A learnt ground was fitted where the vehicle held, near the surface: judged on the
  whole window, the descent before would count against it for seconds. A learnt ground's
  coefficients follow the converged estimate while it is the ground in use, published or
  not; a protected one is never changed (learning on it starts a new entry), nor is a
  stored ground this flight recalled once the estimate has moved from it by more than half
  the distance to its nearest known ground (`another_ground`: it was recalled on too little
  evidence; learning starts a new entry and the stored ground stays as it was learnt). A
  ground this flight created and then leaves for a stored one is dropped (merged): it was
  the stored ground, learnt again before the memory told them apart.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

Z = 2  # the vertical target's row in the last layer
MAX_LEARNT = 8  # grounds learnt in flight that the memory keeps (the oldest goes first)


@dataclass(frozen=True)
class CompositeConfig:
    """The method's numbers in standardised units (learner.online.settings converts)."""

    measurement_var: float  # r: the target's noise variance
    noise_floor_var: float  # the smallest noise variance the confidence test assumes
    prior_scale: float  # s
    prior_isotropic: float  # p0
    memory_samples: float  # samples over which the prior uncertainty comes back
    tracking_gain: float  # standardised force per (m/s) of composite error
    confidence: float  # the likelihood-ratio threshold of a change (an estimate, fitted)
    # ... and of a recall: a stored ground is a fixed hypothesis, nothing fitted to the window
    # (two simple hypotheses: a threshold of 2 ln(1/alpha), 9.2 for a 1 % error)
    recall_confidence: float
    window: int  # samples the tests look at
    recall_window: int  # the most recent samples a stored ground is judged on
    # a change is published once the estimate has converged: its last batch improved its
    # fit to the window by at most this many noise variances (a moving estimate would be
    # published again within the second)
    settle: float
    min_change: float  # the smallest drop of the RMS error over the window published
    far_var: float  # the prior's variance of the prediction far from the surface
    size_sd: float  # the prior sd of a relative change of the effect's size
    layer_bound: float  # spectral norm of the last layer, kept


@dataclass(frozen=True)
class Ground:
    name: str
    coefficients: np.ndarray  # (n_features + 1,): the vertical row and its bias
    protected: bool  # an offline ground: never overwritten


@dataclass(frozen=True)
class CompositeState:
    estimate: np.ndarray  # a
    covariance: np.ndarray  # P
    prior: np.ndarray  # P0: the shape the process noise restores
    published: np.ndarray  # what the controller uses
    current: int  # index into grounds of the ground in use
    grounds: tuple[Ground, ...]
    window_phi: np.ndarray  # (<= window, n + 1) recent basis values
    window_y: np.ndarray  # (<= window,) recent vertical targets
    learnt: int = 0  # grounds learnt so far (names)
    settled: bool = False  # a ground was recalled or learnt in this flight
    created: str = ""  # the ground this flight created, if any


@dataclass(frozen=True)
class Decision:
    kind: str  # "held" (nothing published), "adapted", "recalled"
    statistic: float  # the likelihood ratio of the change published (or the best refused)
    ground: str  # the ground in use afterwards
    merged: str = ""  # a ground this flight created, dropped for the stored one recalled


def prior_covariance(
    home: np.ndarray,
    others: list[np.ndarray],
    scale: float,
    p0: float,
    far_moment: np.ndarray | None = None,
    far_var: float = 1.0,
    size: np.ndarray | None = None,
    size_sd: float = 0.0,
) -> np.ndarray:
    """P0 = (P^-1 + M / far_var)^-1 with P = k^2 u u^T + s^2 C + p0 I: u the change that
    scales the home prediction by (1 + b) (`size`: the size of the effect, rho to first
    order, is the least certain thing about a new ground; k its prior sd), C the mean outer
    product of the other grounds' offsets from home (how grounds were seen to differ in
    shape); M the second moment of phi far from the surface, so that a change that would
    move the prediction up there by more than sqrt(far_var) RMS is a priori unlikely (a
    tight prior where every ground agrees)."""
    n = len(home)
    c = np.zeros((n, n))
    for a in others:
        d = a - home
        c += np.outer(d, d)
    if others:
        c /= len(others)
    p = scale**2 * c + p0 * np.eye(n)
    if size is not None:
        p += size_sd**2 * np.outer(size, size)
    if far_moment is not None and np.any(far_moment):
        p = np.linalg.inv(np.linalg.inv(p) + far_moment / far_var)
    return 0.5 * (p + p.T)


def initial_state(
    grounds: tuple[Ground, ...],
    current: int,
    others: list[np.ndarray],
    config: CompositeConfig,
    far_moment: np.ndarray | None = None,
    output_offset: float = 0.0,
) -> CompositeState:
    """`output_offset`: the standardised zero force (y_mean / y_std) of the vertical axis."""
    a = grounds[current].coefficients.copy()
    size = a.copy()
    size[-1] += output_offset  # phi^T size is the prediction in units of y_std
    prior = prior_covariance(
        a,
        others,
        config.prior_scale,
        config.prior_isotropic,
        far_moment,
        config.far_var,
        size,
        config.size_sd,
    )
    n = len(a)
    return CompositeState(
        a, prior.copy(), prior, a.copy(), current, grounds, np.zeros((0, n)), np.zeros(0)
    )


def ssr(phi: np.ndarray, y: np.ndarray, a: np.ndarray) -> float:
    return float(np.sum((y - phi @ a) ** 2))


MAX_CORRELATION = 0.95  # the lag-1 correlation the test credits at most (a factor of 39)


def correlation_factor(residual: np.ndarray) -> float:
    """How many samples of `residual` carry one sample's evidence: (1 + r) / (1 - r), r its
    lag-1 autocorrelation (an AR(1) series' variance inflation; 1 for independent noise).
    In flight the targets' noise is correlated (an estimated acceleration, filtered), and a
    test that counted each sample as independent would publish changes to a correct model."""
    e = residual - residual.mean()
    denominator = float(e @ e)
    if len(e) < 3 or denominator <= 0.0:
        return 1.0
    r = min(max(float(e[1:] @ e[:-1]) / denominator, 0.0), MAX_CORRELATION)
    return (1.0 + r) / (1.0 - r)


def kalman(
    a: np.ndarray,
    p: np.ndarray,
    prior: np.ndarray,
    phi: np.ndarray,
    y: np.ndarray,
    tracking: np.ndarray,
    config: CompositeConfig,
) -> tuple[np.ndarray, np.ndarray]:
    """The estimate and its covariance after the samples (rows of phi, y, tracking errors)."""
    q = prior / config.memory_samples
    r = config.measurement_var
    for phi_i, y_i, s_i in zip(phi, y, tracking, strict=True):
        p = p + q
        p_phi = p @ phi_i
        denominator = r + phi_i @ p_phi
        gain = p_phi / denominator
        # the measurement's innovation and the tracking error's force, through one gain
        a = a + gain * ((y_i - phi_i @ a) + config.tracking_gain * s_i)
        p = p - np.outer(gain, p_phi)
        p = 0.5 * (p + p.T)
    return a, p


def bounded(
    a: np.ndarray, others: np.ndarray, layer_bound: float, anchor: np.ndarray
) -> np.ndarray:
    """The vertical row (weights and bias) moved back towards `anchor` (the home ground, which
    keeps the bound) until the last layer keeps its spectral-norm bound (`others`: the
    lateral rows, unchanged). Shrinking the change, not the weights alone, keeps what the
    prior holds: a change the prior allows little far from the surface stays small there
    (scaling the weights and leaving the bias would move the prediction everywhere)."""

    def norm(row: np.ndarray) -> float:
        return float(np.linalg.norm(np.vstack([others, row[None, :-1]]), 2))

    if norm(a) <= layer_bound:
        return a
    lo, hi = 0.0, 1.0  # the share of the change kept (bisection: the norm is convex in it)
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if norm(anchor + mid * (a - anchor)) <= layer_bound:
            lo = mid
        else:
            hi = mid
    return anchor + lo * (a - anchor)


def best_stored(
    state: CompositeState,
    wp: np.ndarray,
    wy: np.ndarray,
    fresh: np.ndarray,
    config: CompositeConfig,
) -> tuple[int, float]:
    """The stored ground that best explains the last `recall_window` samples against what is
    published (its index, -1 if none, and the likelihood ratio), among those the fresh
    estimate does not beat there by the change's threshold.

    A stored ground is a fixed hypothesis about the surface under the vehicle: it is judged
    on the last second of data, not on the descent that came before (a ground learnt at the
    hold says little about 10 cm up), and against the noise its own residual shows (the
    residual of the hypothesis being tested; the fresh estimate's, still fitting the
    descent, would count a clear match as noise)."""
    rp, ry = wp[-config.recall_window :], wy[-config.recall_window :]
    published = ssr(rp, ry, state.published)
    fresh_ssr = ssr(rp, ry, fresh)
    best, best_gain = -1, -np.inf
    for k, g in enumerate(state.grounds):
        if k == state.current:  # its memory may be ahead of what is published: not a recall
            continue
        residual = ry - rp @ g.coefficients
        g_ssr = float(residual @ residual)
        sigma2 = max(g_ssr / len(ry), config.noise_floor_var) * correlation_factor(residual)
        g_gain = (published - g_ssr) / sigma2
        if g_gain > best_gain and (g_ssr - fresh_ssr) / sigma2 < config.confidence:
            best, best_gain = k, g_gain
    return best, best_gain


def another_ground(state: CompositeState, a: np.ndarray, wp: np.ndarray) -> bool:
    """Whether the estimate `a` belongs in a new entry rather than the ground in use: the
    ground in use is an offline one (never overwritten), or a stored ground this flight
    recalled from which the estimate has moved by more than half the distance to the known
    ground nearest it (the RMS difference of their predictions over the window): past that
    the data no longer say it is that ground. A stored ground recalled on too little
    evidence (one pushing more like it than like home, over a ground neither knows) is then
    kept as it was learnt, not written over with the ground under the vehicle now; a ground
    this flight created is the one being learnt."""
    current = state.grounds[state.current]
    if current.protected:
        return True
    if current.name == state.created:
        return False

    def distance(b: np.ndarray) -> float:
        return float(np.sqrt(np.mean((wp @ (b - current.coefficients)) ** 2)))

    nearest = min(distance(g.coefficients) for g in state.grounds if g is not current)
    return distance(a) > 0.5 * nearest


def composite_update(
    state: CompositeState,
    phi: np.ndarray,
    y: np.ndarray,
    tracking: np.ndarray,
    lateral_rows: np.ndarray,
    config: CompositeConfig,
) -> tuple[CompositeState, Decision]:
    """A batch of samples (basis values with their constant, vertical targets, tracking
    errors as standardised forces per gain): the new state and what was published."""
    previous = state.estimate
    a, p = kalman(state.estimate, state.covariance, state.prior, phi, y, tracking, config)
    anchor = next(g.coefficients for g in state.grounds if g.protected)
    a = bounded(a, lateral_rows, config.layer_bound, anchor)
    # the tests judge the composite target: the measured force and the tracking error's
    wp = np.concatenate([state.window_phi, phi])[-config.window :]
    wy = np.concatenate([state.window_y, y + config.tracking_gain * tracking])[-config.window :]
    state = replace(state, estimate=a, covariance=p, window_phi=wp, window_y=wy)
    n = len(wy)
    published = ssr(wp, wy, state.published)
    fresh = ssr(wp, wy, a)
    # the noise variance per independent sample: correlated samples count for fewer
    sigma2 = max(fresh / n, config.noise_floor_var) * correlation_factor(wy - wp @ a)
    gain = (published - fresh) / sigma2
    name = state.grounds[state.current].name
    # leaving the ground the flight started on for a stored one takes the recall's evidence;
    # once the flight's data chose a ground, going over to another is a change like any
    # other (two stored grounds that differ little would otherwise take turns)
    threshold = config.confidence if state.settled else config.recall_confidence
    best, best_gain = best_stored(state, wp, wy, a, config)
    if best >= 0 and best_gain > threshold:
        return recall(state, best, best_gain)
    if gain <= config.confidence:
        return state, Decision("held", gain, name)
    # sure of a change: publish it once the estimate has stopped moving, and only if it is
    # large enough to matter to the controller
    moving = (ssr(wp, wy, previous) - fresh) / sigma2
    if moving > config.settle:
        return state, Decision("held", gain, name)
    better = float(np.sqrt(published / n) - np.sqrt(fresh / n))  # the RMS error it removes
    new_ground = another_ground(state, a, wp)
    if better < config.min_change:
        # too small a change for the controller; the memory of a learnt ground keeps it
        if not new_ground:
            grounds = list(state.grounds)
            grounds[state.current] = replace(grounds[state.current], coefficients=a.copy())
            state = replace(state, grounds=tuple(grounds))
        return state, Decision("held", gain, name)
    grounds = list(state.grounds)
    current, learnt, created = state.current, state.learnt, state.created
    if new_ground:  # an offline ground, or one the data left: learning starts a new entry
        learnt += 1
        grounds.append(Ground(f"learnt-{learnt}", a.copy(), False))
        kept = [g for g in grounds if not g.protected]
        if len(kept) > MAX_LEARNT:  # the oldest learnt ground makes room
            grounds.remove(kept[0])
        current = len(grounds) - 1
        created = grounds[current].name
    else:
        grounds[current] = replace(grounds[current], coefficients=a.copy())
    state = replace(
        state,
        published=a.copy(),
        grounds=tuple(grounds),
        current=current,
        learnt=learnt,
        settled=True,
        created=created,
    )
    return state, Decision("adapted", gain, grounds[current].name)


def recall(state: CompositeState, best: int, statistic: float) -> tuple[CompositeState, Decision]:
    """Stored ground `best` whole: estimate, publication and a fresh prior around it. A ground
    this flight created and now leaves for a stored one that explains the last second better
    was that ground, learnt again before the memory told them apart: it is dropped (merged),
    not kept as a second copy."""
    grounds = list(state.grounds)
    recalled = grounds[best]
    merged = ""
    if state.created and grounds[state.current].name == state.created:
        merged = grounds.pop(state.current).name
    state = replace(
        state,
        estimate=recalled.coefficients.copy(),
        covariance=state.prior.copy(),
        published=recalled.coefficients.copy(),
        grounds=tuple(grounds),
        current=next(i for i, g in enumerate(grounds) if g is recalled),
        settled=True,
        created="" if merged else state.created,
    )
    return state, Decision("recalled", statistic, recalled.name, merged)


def grounds_from_header(header: dict, n_features: int) -> tuple[tuple[Ground, ...], int]:
    """The grounds a model file knows (its basis's offline grounds, protected, and those
    learnt in earlier flights) and the index of the one to start on."""
    basis = header.get("basis") or {}
    grounds: list[Ground] = []
    for name, head in sorted((basis.get("grounds") or {}).items()):
        row = np.concatenate([np.asarray(head["weights"])[Z], [np.asarray(head["biases"])[Z]]])
        grounds.append(Ground(name, row.astype(float), True))
    for entry in basis.get("learnt") or []:
        grounds.append(Ground(entry["name"], np.asarray(entry["coefficients"], float), False))
    if any(len(g.coefficients) != n_features + 1 for g in grounds):
        raise ValueError("the basis's grounds do not match the network's last layer")
    names = [g.name for g in grounds]
    start = basis.get("current", basis.get("home"))
    return tuple(grounds), names.index(start) if start in names else -1


def grounds_to_header(header: dict, state: CompositeState) -> dict:
    """The header of a model file saved after a flight: the learnt grounds and the one in
    use, for the next flight to recall."""
    basis = dict(header.get("basis") or {})
    basis["learnt"] = [
        {"name": g.name, "coefficients": g.coefficients.tolist()}
        for g in state.grounds
        if not g.protected
    ]
    basis["current"] = state.grounds[state.current].name
    return {**header, "basis": basis}
