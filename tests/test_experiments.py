"""`groundfx experiment`: definitions, statistics, reports, and tiny real campaigns (process
pool, resume, Ray) whose flights are simulator and autopilot processes in lockstep."""

from __future__ import annotations

import importlib.util
import json
import os
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from scipy import stats

from learner.dataset import load_dataset
from learner.stats import compare, hedges_g, verdict
from mission.campaigns.experiments import campaign, definitions, report
from mission.campaigns.experiments.definitions import EXPERIMENTS, Flight, Trial, plan
from mission.campaigns.experiments.missions import OBSTACLE_TARGETS, make_mission
from simbridge.world import resolve_world_path
from tests.helpers import stop_process, wait_for


def test_every_experiment_is_defined_with_sound_expectations() -> None:
    assert list(EXPERIMENTS) == ["4.1", "4.2", "4.3", "4.4", "4.5", "4.6", "4.7"]
    for e in EXPERIMENTS.values():
        names = [c.name for c in e.conditions]
        assert len(set(names)) == len(names)
        for x in e.expectations:
            assert x.a in names and x.b in names and x.relation in ("lower", "similar")
        trials = plan(e)
        assert len({t.id for t in trials}) == len(trials)
    # the online experiments carry what the online branch needs, all six methods in 4.5
    assert {f.online for c in EXPERIMENTS["4.5"].conditions for f in c.flights} == {
        None,
        *definitions.ONLINE_METHODS,
    }
    adapted = [c for c in EXPERIMENTS["4.4"].conditions if len(c.flights) == 2]
    assert all(c.flights[0].rho_sim == 2 and c.flights[1].carry_network for c in adapted)
    assert EXPERIMENTS["4.2"].needs_multi and not EXPERIMENTS["4.1"].needs_online


def test_plan_shares_seeds_and_a_changed_definition_is_a_new_trial() -> None:
    e = EXPERIMENTS["4.1"]
    trials = plan(e, trials=3, first_seed=10)
    assert {t.seed for t in trials} == {10, 11, 12}
    assert len(trials) == 3 * len(e.conditions)
    t = trials[0]
    assert Trial.from_dict(json.loads(json.dumps(t.to_dict()))).id == t.id
    changed = Trial(t.experiment, t.condition, t.seed, (Flight(model="none", rho_sim=3.0),))
    assert changed.id != t.id and changed.id.startswith(f"4.1/{t.condition}/{t.seed}/")
    with pytest.raises(KeyError, match=r"choose all or one of 4\.1"):
        definitions.select("4.9")


def test_obstacle_missions_hold_3_cm_above_the_surface_of_the_world_file() -> None:
    world = yaml.safe_load(resolve_world_path("obstacles").read_text())
    box = next(o for o in world["obstacles"] if o["kind"] == "box")
    step = next(o for o in world["obstacles"] if o["kind"] == "step")
    box_top = box["center_m"][2] + box["size_m"][2] / 2
    for kind, top, inside in (
        ("box", box_top, lambda x, y: abs(x - box["center_m"][0]) < box["size_m"][0] / 2),
        ("step", step["height_m"], lambda x, y: step["min_xy_m"][0] < x < step["max_xy_m"][0]),
    ):
        assert OBSTACLE_TARGETS[kind][2] == pytest.approx(top)
        for seed in range(5):
            mission, _ = make_mission(kind, seed)
            x, y, z = mission["waypoints"][-1]["position_m"]
            assert inside(x, y) and z == pytest.approx(top + 0.03)
    mission, _ = make_mission("flight_test", 1)
    low = [w["position_m"][2] for w in mission["waypoints"] if w["position_m"][2] <= 0.1]
    assert low == [0.1, 0.03] * 3


def test_hedges_g_welch_and_verdicts() -> None:
    a, b = np.array([1.0, 2.0, 3.0, 4.0]), np.array([3.0, 4.0, 5.0, 6.0, 7.0])
    pooled = np.sqrt((3 * a.var(ddof=1) + 4 * b.var(ddof=1)) / 7)
    assert hedges_g(a, b) == pytest.approx((a.mean() - b.mean()) / pooled * (1 - 3 / (4 * 9 - 9)))
    c = compare(a, b)
    assert c["p"] == pytest.approx(stats.ttest_ind(a, b, equal_var=False).pvalue)
    assert verdict("lower", c) == "supported"  # p = 0.035
    assert verdict("lower", compare(a, b - 1)) == "not shown"  # p = 0.16
    far = compare(a, b + 10)
    assert verdict("lower", far) == "supported" and verdict("similar", far) == "contradicted"
    assert verdict("lower", compare(b + 10, a)) == "contradicted"
    # deterministic conditions without spread: equal or not, never a nan verdict
    same = compare(np.array([2.0, 2.0]), np.array([2.0, 2.0]))
    assert same["p"] == 1.0 and verdict("similar", same) == "supported"
    # ... and two that agree to rounding (both sat down: 16.99 mm) are not "lower" at p = 0
    sat = compare(np.array([0.01699, 0.01699]), np.array([0.01699 + 1e-17, 0.01699]))
    assert sat["p"] == 1.0 and verdict("lower", sat) == "not shown"
    assert verdict("lower", compare(np.array([1.0, 1.0]), np.array([2.0, 2.0]))) == "supported"
    assert verdict("lower", compare(np.array([1.0]), np.array([2.0]))) == "not shown"


def test_report_tables_comparisons_conclusions_and_plot(tmp_path: Path) -> None:
    e = EXPERIMENTS["4.1"]
    trials = plan(e, trials=4)
    rng = np.random.default_rng(0)
    centre = {"none": 0.120, "analytic": 0.0003, "neural": 0.005}
    results = {}
    for t in trials[:-1]:  # the last trial unfinished
        hold = centre[t.condition] + rng.normal(0, 0.0005)
        metrics = dict.fromkeys(definitions.MEASURES, 0.1) | {"hold_z_rms_error_m": hold}
        results[t.id] = {"id": t.id, "metrics": metrics}
    path, values, rows = report.experiment_report(e, trials, results, tmp_path / "4.1")
    text = path.read_text()
    assert len(values["neural"]["hold_z_rms_error_m"]) == 3
    assert [r["verdict"] for r in rows] == ["supported", "supported"]
    assert "| `none` | no model | 4 |" in text and "Unfinished or failed trials (1)" in text
    assert "The data support it: expected `neural` lower than `none`" in text
    assert (tmp_path / "4.1" / "errors.png").stat().st_size > 10_000


def test_results_file_skips_a_torn_line_and_failed_trials(tmp_path: Path) -> None:
    path = tmp_path / campaign.RESULTS_FILE
    campaign.append_result(path, {"id": "a", "metrics": {}})
    campaign.append_result(path, {"id": "b", "error": "RuntimeError: boom"})
    with path.open("a") as f:
        f.write('{"id": "c", "metr')  # killed while writing
    assert list(campaign.load_results(path)) == ["a"]


def test_bad_arguments_name_the_option() -> None:
    for argv, words in (
        (["experiment", "all", "--trials", "0", "--out", "x"], "--trials: expected"),
        (["experiment", "9", "--out", "x"], "choose all or one of"),
    ):
        done = subprocess.run(
            [sys.executable, "-m", "mission.cli", *argv], capture_output=True, text=True
        )
        assert done.returncode == 2 and words in done.stderr, done.stderr


TINY = [Trial("t", "analytic", seed, (Flight(world="rho2", model="analytic"),)) for seed in (0, 1)]


def _deterministic(record: dict) -> tuple:
    return (record["metrics"], record["flights"][-1]["trajectory_sha256"])


@pytest.fixture(scope="module")
def pool_results(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict]:
    out = tmp_path_factory.mktemp("pool")
    results = campaign.run_trials(TINY, out, {}, workers=2, progress=False)
    assert sorted(results) == sorted(t.id for t in TINY)
    assert all(r["flights"][-1]["landed"] for r in results.values())
    return results


@pytest.mark.xdist_group("test_experiments.py")  # the pool's results computed once
def test_a_killed_campaign_resumes_where_it_stopped(
    tmp_path: Path, pool_results: dict[str, dict]
) -> None:
    path = tmp_path / campaign.RESULTS_FILE
    first = pool_results[TINY[0].id]
    campaign.append_result(path, first)
    with path.open("a") as f:
        f.write('{"id": "' + TINY[1].id + '", "fli')  # the second trial was being written
    results = campaign.run_trials(
        TINY, tmp_path, {}, workers=1, keep_recordings=True, progress=False
    )
    lines = path.read_text().splitlines()
    assert len(lines) == 3  # only the torn trial was flown again, on a line of its own
    assert json.loads(lines[-1])["id"] == TINY[1].id
    assert sorted(campaign.load_results(path)) == sorted(t.id for t in TINY)
    # flights are deterministic, recorded or not: the resumed trial gives the pool's result
    assert _deterministic(results[TINY[1].id]) == _deterministic(pool_results[TINY[1].id])
    recordings = list((tmp_path / "recordings").glob("*.rrd"))
    assert [r.name for r in recordings] == [TINY[1].id.replace("/", "_") + "_0.rrd"]
    from learner.flightlogs.recording import read_recording

    z = read_recording(recordings[0]).trajectory()
    assert len(z) > 1000


def _free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def ray_cluster(tmp_path: Path) -> Iterator[str]:
    """A Ray cluster of two nodes on this machine: a head and one worker, one CPU each
    (`ray start --block`: ending the process ends its node). Token authentication off:
    both nodes are ours, on loopback."""
    import ray

    port = _free_tcp_port()
    address = f"127.0.0.1:{port}"
    os.environ["RAY_AUTH_MODE"] = "disabled"  # for the nodes and this driver alike
    # Ray runs its workers at nice 15: beside other work (the suite's other worker, a busy
    # machine) a flight's processes would wait behind everything else
    os.environ["RAY_worker_niceness"] = "0"  # noqa: SIM112 (Ray's own spelling)
    head = ["--head", "--port", str(port), "--include-dashboard", "false"]
    nodes = [_ray_node(head, tmp_path / "head.log")]
    try:
        nodes.append(_ray_node(["--address", address], tmp_path / "worker.log"))
        wait_for(lambda: _connected(ray, address), "the head to take a driver", nodes[0], 120)
        wait_for(lambda: sum(n["Alive"] for n in ray.nodes()) == 2, "two nodes", nodes[1], 120)
        yield address
    finally:
        ray.shutdown()
        os.environ.pop("RAY_AUTH_MODE", None)
        os.environ.pop("RAY_worker_niceness", None)
        for node in reversed(nodes):
            stop_process(node, 30.0)


def _ray_node(args: list[str], log: Path) -> subprocess.Popen:
    ray_cli = Path(sys.executable).with_name("ray")
    # no log monitor: the driver takes no worker logs (`log_to_driver=False`)
    common = ["--block", "--node-ip-address", "127.0.0.1", "--num-cpus", "1",
              "--include-log-monitor", "false"]  # fmt: skip
    with log.open("w") as out:
        return subprocess.Popen(
            [str(ray_cli), "start", *args, *common, "--disable-usage-stats"],
            stdout=out,
            stderr=subprocess.STDOUT,
        )


def _connected(ray: Any, address: str) -> bool:
    try:
        ray.init(address=address, log_to_driver=False)
    except ConnectionError:
        return False
    return True


@pytest.mark.xdist_group("test_experiments.py")  # the pool's results computed once
@pytest.mark.skipif(
    importlib.util.find_spec("ray") is None,
    reason="ray is not installed (the `ray` extra: pip install -c constraints.txt -e '.[ray]')",
)
def test_a_two_node_ray_cluster_gives_the_local_results_of_a_bench_a_gather_and_trials(
    ray_cluster: str, tmp_path: Path, pool_results: dict[str, dict]
) -> None:
    """An experiment trial, a small gap bench and a small gather run as tasks on a cluster
    of two nodes, then here: the same metrics and trajectory, the same scores, the same
    samples to the bit; what the tasks wrote is here."""
    import shutil

    one = TINY[1:]  # the pool's second trial: a trial's record and recording come back
    trials = campaign.run_trials(one, tmp_path / "experiments", {}, ray_address=ray_cluster,
                                 keep_recordings=True, progress=False)  # fmt: skip
    assert sorted(trials) == [t.id for t in one]
    for trial_id, record in trials.items():
        assert _deterministic(record) == _deterministic(pool_results[trial_id])
    recordings = sorted(p.name for p in (tmp_path / "experiments" / "recordings").glob("*.rrd"))
    assert recordings == [t.id.replace("/", "_") + "_0.rrd" for t in one]

    from mission.campaigns.gap_bench import RESULTS_FILE, run_bench
    from mission.campaigns.gap_bench_cases import CASES
    from mission.campaigns.gather import gather_flights

    case = CASES["null_hover"]
    remote = run_bench([case], tmp_path / "cluster", ray_address=ray_cluster)["cases"][0]
    gathered = gather_flights(2.0, 300, 3, tmp_path / "cluster.npz", flights=2,
                              ray_address=ray_cluster, progress=False)  # fmt: skip
    # the tasks ran in private folders; their flights and reports were written here
    folder = tmp_path / "cluster" / case.name
    assert sorted(folder.glob("flight*.csv")) and (folder / "diagnosis" / "gap.json").exists()
    assert sorted(p.name for p in (tmp_path / "cluster.parts").glob("*.npz")) == [
        "flight0.npz", "flight1.npz"]  # fmt: skip
    # here: the bench's flights are the cluster's (cached), its diagnosis runs again
    shutil.copytree(tmp_path / "cluster", tmp_path / "local")
    (tmp_path / "local" / RESULTS_FILE).unlink()
    local = run_bench([case], tmp_path / "local", workers=1)["cases"][0]
    for key in ("reported", "false_alarm", "force_shrink", "effects"):
        assert remote[key] == local[key], key
    here = gather_flights(2.0, 300, 3, tmp_path / "local.npz", flights=2, workers=2,
                          progress=False)  # fmt: skip
    a, b = load_dataset(gathered), load_dataset(here)
    assert len(a) == 300 and all(np.array_equal(a.columns[c], b.columns[c]) for c in a.columns)
