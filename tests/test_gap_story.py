"""One story per diagnosis: the status table, the terminal summary, gap.json and the corrected
world say the same thing. Only effects named present go into the corrected world, a group
through one member the report names, never a sensor effect; "no structure" is said only
where the learnt residual fails on flights it was not trained on, else the inputs that
carry the structure are named; the learnt world is offered only where it shrinks what the
catalogue leaves; no figure is printed as nan. The logs are synthetic (tests/test_gap_robust.py)
and diagnosed in process without replays."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from learner.flightlogs.flightlog import FlightLog, write_log
from learner.gap.corrected import corrected_members, world_column
from learner.gap.flightdata import prepare
from learner.gap.numbers import fig, json_safe, pct
from learner.gap.structure import STRUCTURE_GAIN, has_structure, sentence
from mission.cli.main import main
from simbridge.world import load_world
from tests.test_gap_robust import FEW, NANO, synthetic_log, world_file


def _status_table(report: str) -> dict[str, dict[str, str]]:
    """The report's "Which" table: effect -> status, corrected world."""
    rows = {}
    for line in report.split("## Which", 1)[1].splitlines()[4:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        rows[cells[0]] = {"status": cells[1], "world": cells[3]}
    return rows


def _one_story(out: Path, summary: str) -> dict[str, Any]:
    """gap.json, corrected_world.yaml, the status table and the terminal summary agree on what
    the corrected world holds; no figure anywhere is nan. gap.json's figures."""
    figures = json.loads((out / "gap.json").read_text())  # strict JSON: no NaN
    report = (out / "report.md").read_text()
    world = yaml.safe_load((out / "corrected_world.yaml").read_text())
    written = figures["corrected_world"]["effects"]
    assert world["effects"] == written  # the nominal worlds here hold no effect
    table = _status_table(report)
    in_world = {e["name"] for e in written}
    assert {e for e, r in table.items() if r["world"] == "written"} == in_world
    for name in in_world:
        assert table[name]["status"] in ("present", "not identifiable"), table[name]
    for m in figures["corrected_world"]["written"]:
        assert f"corrected world: in: {m['why']}" in summary
        assert f"- written: {m['why']}" in report
    for m in figures["corrected_world"]["kept_out"]:
        assert f"corrected world: out: {m['why']}" in summary
        assert f"- kept out: {m['why']}" in report
    u = figures["unexplained"]
    assert u["explained"] is (not u["structure"])
    assert u["sentence"] in report and u["sentence"] in summary
    assert ("structure outside the catalogue" in u["sentence"]) is u["structure"]
    assert ("no structure" in u["sentence"]) is (not u["structure"])
    learned_world = (out / "corrected_world_learned.yaml").exists()
    assert learned_world is u["learned_world"]["offered"] is u["structure"]
    assert (out / "learned_residual.npz").exists() is learned_world
    assert u["learned_world"]["why"] in report and u["learned_world"]["why"] in summary
    for text in (report, summary, (out / "gap.json").read_text()):
        assert "nan" not in text.lower().replace("nano", ""), text
    return figures


def _diagnose(logs: list[Path], world: Path, out: Path, capsys: Any, candidates: list[str]) -> str:
    """`groundfx gap diagnose` in process, without replays: its terminal summary."""
    capsys.readouterr()
    code = main(["gap", "diagnose", *map(str, logs[:2]), "--holdout", str(logs[2]), "--world",
                 str(world), "--folds", "2", "--no-replay", "--candidates", ",".join(candidates),
                 "--out", str(out)])  # fmt: skip
    assert code == 0
    return capsys.readouterr().out


def _flights(folder: Path, world: Path, true: dict, seconds: float, extra=None) -> list[Path]:
    logs = []
    for s in (0, 1, 2):
        log = synthetic_log(f"f{s}", NANO, world, true, s, seconds=seconds)
        if extra is not None:
            log = extra(log)
        logs.append(write_log(log, folder / f"f{s}.csv"))
    return logs


def test_a_sensor_bias_beside_a_force_leaves_the_force_alone_in_the_corrected_world(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """A rotor drag and an accelerometer bias: the search fits both, the bias (grouped with a
    thrust scale by its z part) is the logs' sensors', and only the drag is written."""
    world = world_file(tmp_path / "world.yaml")
    true = {"rotor_drag": np.array([8.8e-5, 4.0e-5]), "sensor_bias": np.array([0.3, -0.2, 0.0])}
    logs = _flights(tmp_path, world, true, 15.0)
    out = tmp_path / "out"
    summary = _diagnose(logs, world, out, capsys, [*FEW, "sensor_bias"])
    figures = _one_story(out, summary)
    assert set(figures["chosen"]) == {"rotor_drag", "sensor_bias"}
    assert [e["name"] for e in figures["corrected_world"]["effects"]] == ["rotor_drag"]
    kept = figures["corrected_world"]["kept_out"]
    assert [m["candidate"] for m in kept] == ["sensor_bias"]
    assert "a property of the logs' sensors" in kept[0]["why"]
    table = _status_table((out / "report.md").read_text())
    assert table["rotor_drag"] == {"status": "present", "world": "written"}
    assert table["sensor_bias"]["world"] == "no: the logs' sensors'"


def _crossflow(world: Path, gain: float):
    """A sideways force no catalogue effect has: gain x weight x tanh(vx / 0.5 m/s) along
    world y (a flow across the vehicle that grows with its speed along x)."""

    def add(log: FlightLog) -> FlightLog:
        d = prepare(log, load_world(world), NANO)
        extra = np.zeros_like(log.acceleration_m_s2)
        extra[:, 1] = gain * 9.81 * np.tanh(d.velocity_m_s[:, 0] / 0.5)
        return dataclasses.replace(log, acceleration_m_s2=log.acceleration_m_s2 + extra)

    return add


def test_a_force_outside_the_catalogue_that_a_residual_learns_is_structure_named_by_its_inputs(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    world = world_file(tmp_path / "world.yaml")
    logs = _flights(tmp_path, world, {}, 20.0, _crossflow(world, 0.05))
    out = tmp_path / "out"
    summary = _diagnose(logs, world, out, capsys, FEW)
    u = _one_story(out, summary)["unexplained"]
    assert u["structure"] and u["learnt_gain"] >= STRUCTURE_GAIN, u["sentence"]
    # its sign is the direction of travel's, its size the speed's
    assert "direction of travel relative to the body" in u["carried_by"], u["inputs"]
    assert set(u["carried_by"]) <= {"direction of travel relative to the body",
                                    "horizontal speed"}, u["inputs"]  # fmt: skip
    assert "the inputs that carry it: direction of travel relative to the body" in u["sentence"]
    assert u["learned_world"]["offered"]


def _speed_fading_ground_force(world: Path):
    """A lift near the ground that fades with horizontal speed, none of the catalogue's:
    0.3 W exp(-h / 0.15 m) exp(-(v_h / 0.8 m/s)^2), h the centre's height above the floor."""

    def add(log: FlightLog) -> FlightLog:
        d = prepare(log, load_world(world), NANO)
        speed = np.hypot(d.velocity_m_s[:, 0], d.velocity_m_s[:, 1])
        h = np.where(np.isfinite(d.height_m), d.height_m, 10.0)
        extra = np.zeros_like(log.acceleration_m_s2)
        extra[:, 2] = 0.3 * 9.81 * np.exp(-h / 0.15) * np.exp(-((speed / 0.8) ** 2))
        return dataclasses.replace(log, acceleration_m_s2=log.acceleration_m_s2 + extra)

    return add


def test_what_is_learnt_on_passes_along_x_carries_over_to_passes_along_y(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """The residual's inputs are relative to the body (speed, direction of travel): a lift
    fading with speed, learnt on two flights passing along x, removes a share of the gap on
    a flight passing along y. On world-frame velocities the network never saw a y speed and
    left 218% more than the catalogue on that flight ("no structure")."""
    world = world_file(tmp_path / "world.yaml")
    add = _speed_fading_ground_force(world)
    logs = [
        write_log(
            add(synthetic_log(f"f{s}", NANO, world, {}, s, seconds=20.0, low_m=0.04, axes=axes)),
            tmp_path / f"f{s}.csv",
        )
        for s, axes in ((0, (2.0, 0.0)), (1, (2.0, 0.0)), (2, (0.0, 2.0)))
    ]
    out = tmp_path / "out"
    summary = _diagnose(logs, world, out, capsys, ["thrust_mass", "body_drag", "rotor_drag"])
    u = _one_story(out, summary)["unexplained"]
    assert u["structure"] and u["learnt_gain"] >= STRUCTURE_GAIN, u["sentence"]
    assert {"horizontal speed", "height above the surface"} <= set(u["carried_by"]), u["inputs"]


def test_flights_that_disagree_on_a_landing_pad_put_the_position_among_the_inputs(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """A pad (0.6 m around x = 1 m) lifts 0.3 W exp(-h / 0.1 m) where the floor around it
    does nothing: one fitting flight low over the pad, one beside it, the held-out flight over
    the pad. The flights disagree within a height regime, said so with where each flew, and
    the learnt residual, with the position among its inputs, removes more on the held-out
    flight than on the state alone (35% on this case)."""
    world = world_file(tmp_path / "world.yaml")

    def over(log: FlightLog, x_m: float) -> FlightLog:
        p = log.position_m + np.array([x_m, 0.0, 0.0])
        log = dataclasses.replace(log, position_m=p)
        d = prepare(log, load_world(world), NANO)
        on = np.hypot(d.position_m[:, 0] - 1.0, d.position_m[:, 1]) < 0.6
        h = np.where(np.isfinite(d.height_m), d.height_m, 10.0)
        extra = np.zeros_like(log.acceleration_m_s2)
        extra[:, 2] = np.where(on, 0.3 * 9.81 * np.exp(-h / 0.1), 0.0)
        return dataclasses.replace(log, acceleration_m_s2=log.acceleration_m_s2 + extra)

    logs = []
    for s, x_m in ((0, 1.0), (1, -1.0), (2, 1.0)):
        log = synthetic_log(f"f{s}", NANO, world, {}, s, seconds=20.0, low_m=0.04, axes=(0.3, 0.3))
        logs.append(write_log(over(log, x_m), tmp_path / f"f{s}.csv"))
    out = tmp_path / "out"
    summary = _diagnose(logs, world, out, capsys, ["thrust_mass", "body_drag", "rotor_drag"])
    figures = _one_story(out, summary)
    u = figures["unexplained"]
    said = u["disagreement"]
    assert said is not None and said["per_flight_share"]["f0"] > said["per_flight_share"]["f1"]
    # where each flew that height: the one that pushes harder over the pad at x = 1 m
    places = said["per_flight_position_m"]
    assert abs(places["f0"][0] - 1.0) < 0.3 and abs(places["f1"][0] + 1.0) < 0.3, places
    assert said["sentence"] in figures["rules"] and f"flights: {said['sentence']}" in summary
    assert u["structure"] and "position" in u["carried_by"], u["inputs"]
    assert u["learnt_gain"] >= 0.5


def test_a_null_case_has_no_structure_and_offers_no_learnt_world(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    world = world_file(tmp_path / "world.yaml")
    logs = _flights(tmp_path, world, {}, 15.0)
    out = tmp_path / "out"
    summary = _diagnose(logs, world, out, capsys, FEW)
    figures = _one_story(out, summary)
    u = figures["unexplained"]
    assert u["explained"] and not u["structure"] and u["carried_by"] == []
    assert figures["corrected_world"]["effects"] == []
    assert "corrected world: nothing added" in summary
    assert "learnt world: not written: the learnt residual does not shrink" in summary
    assert not (out / "unexplained.png").exists()


def _effects(**status: tuple[str, list[str]]) -> dict[str, dict[str, Any]]:
    return {e: {"status": s, "group": g} for e, (s, g) in status.items()}


def test_the_corrected_world_takes_present_effects_one_member_per_group_no_sensor() -> None:
    group = ["mass_error", "thrust_coefficient"]
    effects = _effects(
        rotor_drag=("present", []),
        thrust_coefficient=("not identifiable", group),
        mass_error=("not identifiable", group),
        wind=("not identifiable", ["sensor_bias", "wind"]),
        sensor_bias=("not identifiable", ["sensor_bias", "wind"]),
        sensor_latency=("present", []),
    )
    chosen = {
        "rotor_drag": np.array([8e-5, 4e-5]),
        "thrust_mass": np.array([-0.05]),
        "wind": np.array([1.0, 0.5]),
        "sensor_latency": np.array([0.01]),
    }
    m = corrected_members(effects, chosen, NANO)
    assert [w["as"] for w in m["written"]] == ["rotor_drag", "thrust_coefficient", "wind"]
    assert m["written"][1]["entries"] == [{"name": "thrust_coefficient", "scale": 0.95}]
    assert "goes in as thrust_coefficient" in m["written"][1]["why"]
    assert "sensor_bias would be the sensors'" in m["written"][2]["why"]
    assert [k["candidate"] for k in m["kept_out"]] == ["sensor_latency"]
    column = world_column(effects, m)
    assert column["mass_error"] == "in as thrust_coefficient"
    assert column["sensor_bias"] == "in as wind"
    assert column["sensor_latency"] == "no: the logs' sensors'"
    # the same group carried by the bias: nothing of it is written
    effects["sensor_bias"]["status"] = "not identifiable"
    m = corrected_members(effects, {"sensor_bias": np.array([0.3, 0.0, 0.0])}, NANO)
    assert m["written"] == [] and "the group is not written" in m["kept_out"][0]["why"]
    assert world_column(effects, m)["wind"] == "no: sensor_bias carries it"


def test_structure_needs_a_clear_gain_beyond_the_noise_else_no_structure_is_said() -> None:
    assert has_structure(0.5, removed=2e-6, margin=1e-6)
    assert not has_structure(0.5, removed=0.5e-6, margin=1e-6)  # within the noise
    assert not has_structure(STRUCTURE_GAIN - 0.01, removed=2e-6, margin=1e-6)
    assert not has_structure(None, removed=2e-6, margin=1e-6)
    assert not has_structure(float("nan"), removed=2e-6, margin=1e-6)
    carriers = [{"input": "height above the surface", "loss_share": 1.3},
                {"input": "tilt (the body's z axis)", "loss_share": 0.05}]  # fmt: skip
    text = sentence(0.6, 0.5, True, carriers, "the held-out flights")
    assert "structure outside the catalogue" in text and "height above the surface (100%)" in text
    assert "tilt" not in text
    for gain in (0.1, 0.3, -2.0, None, float("nan")):
        text = sentence(0.6, gain, False, None, "the held-out flights")
        assert "no structure" in text and "nan" not in text, text


def test_no_figure_is_printed_as_nan() -> None:
    assert fig(float("nan"), ".2f", 1000, "mN") == "n/a, because it could not be measured"
    assert pct(float("nan")).startswith("n/a, because ")
    assert pct(0.416) == "42%" and fig(0.01234, ".2f", 1000, "mN") == "12.34 mN"
    data = json_safe({"a": [np.float64("nan"), 1.0], "b": {"c": math.inf, "d": np.int64(3)}})
    assert data == {"a": [None, 1.0], "b": {"c": None, "d": 3}}
    json.dumps(data, allow_nan=False)


def test_the_summary_gives_the_replays_figure_and_warns_where_the_corrected_world_flies_worse():
    from mission.cli.gap import closed_loop_line

    flown = {"status": "flown", "flights": 1, "before_m": 0.0073, "after_m": 0.0050,
             "shrink": 0.31, "failed": []}  # fmt: skip
    line = closed_loop_line(flown)
    assert line is not None and "7.3 mm -> 5.0 mm, shrink 31%" in line
    assert "further from the logged flights" not in line
    worse = closed_loop_line({**flown, "after_m": 0.011, "shrink": -0.5})
    assert worse is not None and "shrink -50%" in worse
    assert "the corrected world flies further from the logged flights" in worse
    assert closed_loop_line({"status": "skipped", "why": "not asked for"}) is None


def test_a_force_gap_within_the_noise_floor_is_said_to_be_so_not_to_lack_structure():
    from learner.gap.diagnose import force_within_floor

    gap = {"force_rms_n": {"before": 0.00082},
           "force_rms_n_measured_floor": {"before": 0.0, "floor": 0.0022}}  # fmt: skip
    said = force_within_floor(gap)
    assert said is not None and "0.82 mN" in said and "2.20 mN" in said
    gap["force_rms_n_measured_floor"]["before"] = 0.0004
    assert force_within_floor(gap) is None
    assert force_within_floor({"force_rms_n": {"before": 0.01}}) is None  # no held-out flights
