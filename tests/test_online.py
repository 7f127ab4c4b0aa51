"""Online learning: the update rules, guards and snapshots, the learner thread, the options."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from autopilot.online.online_learner import OnlineLearner
from autopilot.params import ORDER, SPECS, ParamStore, check_value, float32
from learner.model import load_model
from learner.network import CONTROL_COLUMNS
from learner.online.guards import check_update
from learner.online.memory import load_memory
from learner.online.methods import Anchor, forward_np, update
from learner.online.names import METHODS, NETWORK_METHODS, method_number, method_of_number
from learner.online.session import OnlineSession
from learner.online.settings import OnlineSettings
from simbridge.config import ConfigError
from tests.helpers import REPO, run_groundfx

torch.set_num_threads(1)  # as the learner thread does: a tiny network, two shared cores

BASE = load_model("rho1")
MEMORY = load_memory(REPO / "learner" / "models" / "rho1.memory.npz")


def shifted_batch(n: int = 64, shift_n: float = 0.02, seed: int = 0):
    """Offline states whose f_ge,z is `shift_n` stronger than the network predicts: a world
    the network has not seen. The targets are the network's own (the stored ones carry the
    accelerometer's noise, which no update can learn and which would hide what it did)."""
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(MEMORY.x), n, replace=False)
    x = MEMORY.x[pick]
    nz = BASE.normaliser
    y = forward_np(BASE.weights, BASE.biases, (x - nz.x_mean) / nz.x_std) * nz.y_std + nz.y_mean
    y[:, 2] += shift_n
    return x, y


def standardised(x, y):
    n = BASE.normaliser
    return (x - n.x_mean) / n.x_std, (y - n.y_mean) / n.y_std


def anchor(settings: OnlineSettings) -> Anchor:
    session = OnlineSession(BASE, settings, MEMORY)
    return session._anchor


@pytest.mark.parametrize("method", NETWORK_METHODS)
def test_every_method_learns_a_shift_and_keeps_the_lipschitz_bound(method):
    x, y = standardised(*shifted_batch())
    w, b = tuple(BASE.weights), tuple(BASE.biases)
    # one update at the default learning rate: the penalties (default lambda 1) hold the
    # weights back, the rest follow
    settings = OnlineSettings(method=method)
    result = update(w, b, x, y, settings, anchor(settings))
    assert result.loss_after < (0.95 if method in ("constraint", "margin") else 0.8) * (
        result.loss_before
    )
    # large steps push the norms: the bounds still hold after the update
    settings = OnlineSettings(method=method, learning_rate=3e-2)
    result = update(w, b, x, y, settings, anchor(settings))
    norms = [np.linalg.norm(m, ord=2) for m in result.weights]
    assert max(norms) <= BASE.header["layer_bound"] + 1e-9
    columns = result.weights[0][:, list(CONTROL_COLUMNS)]
    assert np.linalg.norm(columns, ord=2) <= BASE.header["control_column_bound"] + 1e-9
    assert not np.array_equal(result.weights[-1], w[-1])


def test_the_protecting_penalties_hold_the_weights_near_the_offline_ones():
    x, y = standardised(*shifted_batch())
    w, b = tuple(BASE.weights), tuple(BASE.biases)

    fisher = anchor(OnlineSettings(method="ewc")).fisher_weights

    def moved(weigh: bool = False, **kw) -> float:
        s = OnlineSettings(learning_rate=1e-2, steps=40, **kw)
        r = update(w, b, x, y, s, anchor(s))
        f = fisher if weigh else [1.0] * len(w)
        return float(sum(np.sum(k * (n - o) ** 2) for k, n, o in zip(f, r.weights, w, strict=True)))

    naive = moved(method="naive")
    assert moved(method="constraint", penalty=100.0) < 0.3 * naive
    # ewc frees the weights the offline data does not care about: its own distance shrinks
    assert moved(True, method="ewc", penalty=100.0) < 0.3 * moved(True, method="naive")
    # a margin wider than any step: free like naive; a zero margin: the constraint
    assert moved(method="margin", penalty=100.0, margin=10.0) == pytest.approx(naive, rel=1e-6)
    assert moved(method="margin", penalty=100.0, margin=0.0) < 0.3 * naive


def test_updates_are_reproducible_to_the_bit_one_by_one_or_in_blocks():
    """The same samples give the same weights on every run, and in blocks (as the learner
    process takes them) the same as one by one (as a deterministic flight does)."""
    x, y = shifted_batch(300)
    y[::37, 2] = 5.0  # outliers, dropped in both paths
    t = np.arange(len(x)) * 0.01

    def run(method: str, block: int = 1):
        s = OnlineSession(BASE, OnlineSettings(method=method), MEMORY)
        for k in range(0, len(x), block):
            if block == 1:
                s.add(x[k], y[k], t[k])
            else:
                s.add_many(x[k : k + block], y[k : k + block], t[k : k + block])
        return s

    for method in ("naive", "replay", "rls"):
        a, b, c = run(method), run(method), run(method, block=16)
        assert a.snapshot.version == b.snapshot.version == c.snapshot.version > 0
        assert a.counts == c.counts and a.counts["outliers"] == 9
        for other in (b, c):
            pairs = zip(a.snapshot.net.weights, other.snapshot.net.weights, strict=True)
            assert all(np.array_equal(p, q) for p, q in pairs)


def test_guards_reject_non_finite_and_worse_updates_and_keep_the_snapshot():
    s = OnlineSettings()
    x, y = standardised(*shifted_batch())
    old = (tuple(BASE.weights), tuple(BASE.biases))
    broken = (tuple(w * np.nan for w in BASE.weights), old[1])
    assert check_update(old, broken, x, x, y, 0.026, s).reason == "non-finite weights"
    rng = np.random.default_rng(1)
    noise = (tuple(w + rng.normal(0, 1, w.shape) for w in BASE.weights), old[1])
    verdict = check_update(old, noise, x, x[:16], y[:16], 0.026, s)
    assert not verdict.accepted and "held-back RMSE" in verdict.reason
    # in a session: an absurd learning rate overfits pure noise; the guard keeps the weights
    strict = OnlineSettings(learning_rate=0.3, steps=20, guard_ratio=1.0, guard_slack_n=0.0)
    session = OnlineSession(BASE, strict, MEMORY)
    xs, _ = shifted_batch(600, shift_n=0.0)
    ys = np.random.default_rng(4).uniform(0.0, 1.0, (600, 3))
    for k in range(len(xs)):
        session.add(xs[k], ys[k], k * 0.01)
    assert session.counts["rejected"] > 0
    assert session.counts["accepted"] + session.counts["rejected"] == session.counts["updates"]
    assert session.snapshot.version == session.counts["accepted"]
    pred = forward_np(tuple(session.snapshot.net.weights), tuple(session.snapshot.net.biases), xs)
    assert np.all(np.isfinite(pred))


def test_the_learner_never_blocks_the_caller_drops_when_full_and_publishes_versions():
    """Asynchronous: the learner process updates while the caller goes on."""
    x, y = shifted_batch(2000, seed=2)
    learner = OnlineLearner(
        BASE, OnlineSettings(steps=50), MEMORY, deterministic=False, queue_size=8
    )
    assert learner.wait_ready()
    worst = 0.0
    for k in range(len(x)):
        t0 = time.perf_counter()
        learner.submit(x[k], y[k], k * 0.01)
        worst = max(worst, time.perf_counter() - t0)
        if k % 16 == 0:
            time.sleep(0.002)  # the thread drains 16 samples in far less, an update takes longer
    # then at the learner's pace until it has published an update (on a busy machine the
    # burst may have reached it too thinly for one): each chunk once it took the last one
    sent, deadline = len(x), time.monotonic() + 120.0
    while learner.snapshot.version == 0 and time.monotonic() < deadline:
        while learner._taken.value < learner._sent and time.monotonic() < deadline:
            time.sleep(0.001)  # a state waited for, the learner's count of samples taken
        for _ in range(8):  # one chunk (queue_size 8)
            learner.submit(x[sent % len(x)], y[sent % len(x)], sent * 0.01)
            sent += 1
    learner.close()
    summary = learner.summary()
    assert summary["online_dropped"] > 0  # an update takes far longer than 8 submissions
    assert (
        summary["online_samples"] + summary["online_dropped"] + summary["online_outliers"] == sent
    )
    assert learner.snapshot.version == summary["online_accepted"] > 0
    assert not learner.snapshot.net.weights[0].flags.writeable  # immutable snapshot
    assert worst < 0.05  # no waiting on the learner (generous: a loaded machine)
    assert learner.errors == [] and not learner._process.is_alive()  # stopped, cleanly


def test_pause_and_reset_return_to_the_offline_weights():
    x, y = shifted_batch(400, seed=3)
    learner = OnlineLearner(BASE, OnlineSettings(), MEMORY, deterministic=True)
    for k in range(200):
        learner.submit(x[k], y[k], k * 0.01)
    adapted = learner.snapshot
    assert adapted.version > 0 and adapted.net is not BASE
    learner.pause(True)
    for k in range(200, 400):
        learner.submit(x[k], y[k], k * 0.01)
    assert learner.snapshot is adapted and learner.ignored_paused == 200
    learner.reset(4.0)
    assert learner.snapshot.net is BASE and learner.snapshot.version == adapted.version + 1


def test_the_learner_process_resets_in_order_and_a_second_flight_holds_on_to_the_offline_weights(
    tmp_path,
):
    """Asynchronous reset lands between the samples before and after it; the saved model
    keeps the offline weights beside it, and a session started from it anchors on those (the
    protecting methods protect what was learnt offline, not what the last flight left)."""
    from autopilot.online.online_control import find_offline

    x, y = shifted_batch(1000, seed=4)
    learner = OnlineLearner(BASE, OnlineSettings(), MEMORY, deterministic=False, queue_size=1000)
    assert learner.wait_ready()
    for k in range(400):
        learner.submit(x[k], y[k], k * 0.01)
    learner.reset(4.0)
    for k in range(400, 1000):
        learner.submit(x[k], y[k], k * 0.01)
    learner.close()
    summary = learner.summary()
    assert summary["online_resets"] == 1 and summary["online_dropped"] == 0
    assert summary["online_samples"] + summary["online_outliers"] == 1000
    # 6 batches of 56 trained samples before the reset, 10 after: all accepted on this shift
    assert summary["online_accepted"] == learner.snapshot.version - 1 > 8
    saved = learner.save(tmp_path / "adapted.npz")
    adapted = load_model(saved)
    assert "online" in adapted.header
    assert not np.array_equal(adapted.weights[0], BASE.weights[0])
    offline = find_offline(saved, 1.0, adapted)
    assert all(np.array_equal(a, b) for a, b in zip(offline.weights, BASE.weights, strict=True))
    assert find_offline("rho1", 1.0, BASE) is None  # an offline model is its own anchor
    session = OnlineSession(adapted, OnlineSettings(method="constraint"), MEMORY, offline)
    assert np.array_equal(session._anchor.weights[0], BASE.weights[0])
    assert session.reset(0.0).net is offline
    (tmp_path / "adapted.offline.npz").unlink()
    with pytest.raises(ConfigError, match=r"adapted\.offline\.npz is missing"):
        find_offline(saved, 1.0, adapted)


def test_online_parameters_have_ranges_and_the_options_clear_errors(tmp_path):
    assert "GFX_OL_FORGET: 1.5 is outside the allowed range [0.5, 1]" in (
        check_value("GFX_OL_FORGET", 1.5) or ""
    )
    assert check_value("GFX_OL_METHOD", 8) is not None  # 7: composite, the last
    store = ParamStore(None, {"GFX_OL_METHOD": 6, "GFX_OL_FORGET": 0.9})
    settings = store.online_settings()
    assert settings.method == "rls" and settings.forgetting == pytest.approx(0.9)
    with pytest.raises(ConfigError, match="online steps: 0 is outside the allowed range"):
        dataclasses.replace(OnlineSettings(), steps=0)
    with pytest.raises(ConfigError, match="unknown method 'sgd'"):
        OnlineSettings(method="sgd")
    r = run_groundfx("fly", "mission/examples/hover.yaml", "--model", "analytic", "--online", "rls")
    assert r.returncode == 2 and "--online rls: needs --model neural" in r.stderr

    def refusal(network: str, method: str) -> str:
        """What the autopilot says when it refuses to start (exit code 2)."""
        r = run_groundfx(
            "autopilot",
            "--sim",
            "tcp:127.0.0.1:9",
            "--model",
            "neural",
            "--network",
            network,
            "--online",
            method,
            "--no-gcs",
            "--params-file",
            "none",
        )
        assert r.returncode == 2, r.stderr
        return r.stderr

    assert "--online ewc: needs stored offline samples" in refusal("rho2", "ewc")
    assert "--online composite: needs a model trained over several grounds" in refusal(
        "rho1", "composite"
    )
    adapted = OnlineLearner(BASE, OnlineSettings()).save(tmp_path / "adapted.npz")
    (tmp_path / "adapted.offline.npz").unlink()
    assert "adapted.offline.npz is missing" in refusal(str(adapted), "constraint")


def test_a_ground_station_tunes_the_settings_the_learner_uses_within_their_declared_ranges():
    names = sorted(n for n in ORDER if n.startswith("GFX_OL_"))
    assert names == [
        "GFX_OL_CONF", "GFX_OL_FORGET", "GFX_OL_HOLD_V", "GFX_OL_LAMBDA", "GFX_OL_LR",
        "GFX_OL_MARGIN", "GFX_OL_METHOD", "GFX_OL_MIN_CHG", "GFX_OL_PAUSE", "GFX_OL_RESET",
        "GFX_OL_RLS_P0", "GFX_OL_RLS_SC", "GFX_OL_SETTLE", "GFX_OL_TRACK",
    ]  # fmt: skip
    assert ParamStore(None).online_settings() is None  # GFX_OL_METHOD 0: off
    numbered = range(int(SPECS["GFX_OL_METHOD"].hi) + 1)
    assert [method_of_number(k) for k in numbered] == [None, *METHODS]
    for method in METHODS:  # what `--online METHOD` sets is what the learner runs
        store = ParamStore(None, {"GFX_OL_METHOD": method_number(method)})
        assert store.online_settings().method == method
    tuned = [f for f in dataclasses.fields(OnlineSettings) if "mavlink" in f.metadata]
    assert len(tuned) == len(names) - 3  # all but the method, pause and reset
    for f in tuned:
        spec = SPECS[f.metadata["mavlink"]]
        assert (spec.default, spec.lo, spec.hi) == (f.default, f.metadata["lo"], f.metadata["hi"])
        assert getattr(ParamStore(None, {"GFX_OL_METHOD": 1}).online_settings(), f.name) == (
            float32(f.default)
        )
        for value in (spec.lo, spec.hi):  # either end of the range reaches the learner
            store = ParamStore(None, {"GFX_OL_METHOD": 1})
            assert store.set(spec.name, value) is None
            assert getattr(store.online_settings(), f.name) == float32(value)
        below = spec.lo / 2 if spec.lo > 0 else -1.0
        assert "outside the allowed range" in (check_value(spec.name, below) or "")
        assert "outside the allowed range" in (check_value(spec.name, spec.hi * 2) or "")


def test_a_flight_adapts_in_lockstep_reproducibly_saves_the_model_and_can_be_paused(tmp_path):
    import yaml

    from learner.flightlogs.recording import read_recording
    from mission.campaigns.trials import landing_trial
    from mission.fly import fly
    from mission.recordings import logs_dir

    data, start = landing_trial(0)
    data["waypoints"][-1]["hold_s"] = 3.0
    mission = tmp_path / "landing.yaml"
    mission.write_text(yaml.safe_dump(data))

    def flight(*extra: str, record: bool | Path = False) -> dict:
        return fly(
            mission,
            "rho2",
            "neural",
            network="rho1",
            start=start,
            via_gcs=False,
            record=record,
            autopilot_options=extra,
        )

    saved, rrd = tmp_path / "adapted.npz", tmp_path / "a.rrd"
    a = flight("--online", "rls", "--save-model", str(saved), record=rrd)
    b = flight("--online", "rls", record=True)  # into the logs folder, named by its method
    assert sorted(logs_dir().glob(f"*-{mission.stem}-neural-online-rls.rrd"))
    assert a["landed"] and a["online_mode"] == "deterministic"
    assert a["online_version"] == a["online_accepted"] > 3
    assert a["online_accepted"] + a["online_rejected"] == a["online_updates"]
    assert a["online_dropped"] == 0
    # deterministic: updates at the same simulated times, so the same flight to the bit. A
    # process starved at its start (a loaded machine) can arm while the simulator still holds
    # the vehicle on its stand, which changes the flight: then a third flight decides.
    shas = {a["trajectory_sha256"], b["trajectory_sha256"]}
    if len(shas) > 1:
        assert flight("--online", "rls")["trajectory_sha256"] in shas
    adapted = load_model(saved)
    assert adapted.header["online"]["settings"]["method"] == "rls"
    assert adapted.header["online"]["version"] == a["online_version"]
    assert not np.array_equal(adapted.weights[-1], BASE.weights[-1])
    assert np.array_equal(adapted.weights[0], BASE.weights[0])  # rls: the last layer only
    # the recording has the learner's loss and the version the controller used
    _, versions = read_recording(rrd).scalars("plots/learner/version")
    assert versions[-1, 0] == a["online_version"] and np.all(np.diff(versions[:, 0]) >= 0)
    assert len(read_recording(rrd).scalars("plots/learner/loss")[0]) == a["online_updates"]
    paused = flight("--online", "naive", "--param", "GFX_OL_PAUSE=1")
    assert paused["online_version"] == 0 and paused["online_ignored_paused"] > 100


def test_a_ground_station_flight_learns_in_the_learner_process():
    """Through a ground station (pymavlink uploads, arms, starts) the learner runs
    asynchronously in its own process: it learns during the lockstep flight at full speed,
    adapts the rho1 network in the rho 2 world, and stops with the flight."""
    from mission.campaigns.online_bench import BENCH_MISSION
    from mission.fly import fly

    summary = fly(
        BENCH_MISSION,
        "rho2",
        "neural",
        network="rho1",
        via_gcs=True,
        record=False,
        autopilot_options=("--online", "naive"),
    )
    assert summary["landed"] and summary["online_mode"] == "asynchronous", summary
    assert summary["online_errors"] == []
    assert summary["online_updates"] > 10 and summary["online_version"] > 0
    assert summary["online_accepted"] + summary["online_rejected"] == summary["online_updates"]
    # the queue drops what a starved learner cannot take (counted; a loaded machine), but
    # the learner took most, and learnt from every sample it took before it stopped
    assert summary["online_dropped"] < summary["online_samples"]
    assert summary["online_samples"] // 64 >= summary["online_updates"] > 10


def test_a_protecting_method_adapts_to_rho2_and_forgets_less_than_naive(tmp_path):
    """Experiments 4.3/4.4 at the smallest scale (seed 0, deterministic): the rho1 network
    adapted in a rho_sim = 2 world by `naive` and by `replay` predicts the ground effect near
    the ground there better than offline-only (judged along the offline network's own rho 2
    flight: the hold itself the position loop's integral flies out either way); carried back
    to rho = 1 (learning off), the one `replay` adapted has kept what the offline network
    knew far from the ground, where rho 1 and rho 2 agree, and the one `naive` adapted has
    lost it (judged along the offline network's own rho 1 flight)."""
    from mission.campaigns.online_eval import (
        far_error_n,
        hold_error,
        near_error_n,
        trial_file,
        world_file,
    )

    # the vertical loop as soft as the horizontal one (a0 = 6): its hold wanders over a few
    # millimetres of height to learn from. On the default's stiffer loop (36), which holds
    # within one, `replay` learnt too little (10 s hold) to beat the offline network near
    # the ground (77.7 against 75.3 mN; `naive` 51.8)
    soft = ("--param", "GFX_POS_Z_P=6", "--param", "GFX_POS_Z_D=6")
    mission, start = trial_file(tmp_path, 0, 6.0)
    rho2, rho1 = world_file(tmp_path, 2.0), world_file(tmp_path, 1.0)
    log2 = tmp_path / "offline_rho2.csv"
    hold_error(mission, start, rho2, "neural", 2.0, "rho1", *soft, flight_log=log2)
    offline_near = near_error_n(log2, "rho1", rho2, 2.0)
    log = tmp_path / "offline_rho1.csv"
    hold_error(mission, start, rho1, "neural", 1.0, "rho1", *soft, flight_log=log)
    offline_far = far_error_n(log, "rho1", rho1, 1.0)
    near, far = {}, {}
    for method in ("naive", "replay"):
        saved = tmp_path / f"{method}.npz"
        adapting = ("--online", method, "--save-model", str(saved))
        hold_error(mission, start, rho2, "neural", 2.0, "rho1", *soft, *adapting)
        near[method] = near_error_n(log2, saved, rho2, 2.0)
        far[method] = far_error_n(log, saved, rho1, 1.0)
    assert near["naive"] < offline_near and near["replay"] < offline_near, (offline_near, near)
    assert offline_far < 0.002, offline_far  # the offline network knows the far field
    assert far["replay"] < 0.5 * far["naive"], far


def test_samples_are_taken_on_a_fixed_grid_in_the_air_only():
    """100 Hz on 250 Hz steps: 100 samples a second, none on the ground; after a pause the
    grid starts again from the first sample."""
    from autopilot.online.sample_schedule import SampleSchedule

    schedule, taken = SampleSchedule(), 0
    for k in range(250):
        t = k * 0.004
        if schedule.due(t, 100.0, in_the_air=True):
            schedule, taken = schedule.after_sample(t, 100.0), taken + 1
    assert taken == 100
    assert not schedule.due(5.0, 100.0, in_the_air=False)
    assert not schedule.due(5.0, 0.0, in_the_air=True)  # sampling off
    assert schedule.after_sample(5.0, 100.0).next_s == pytest.approx(5.01)
