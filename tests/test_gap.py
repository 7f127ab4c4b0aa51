"""The gap diagnosis end to end on real flights (simulator and autopilot processes): a withheld
rotor drag is found with its parameters, a null world raises no false alarm, `groundfx gap
diagnose` reads another vehicle's CSV through a column mapping and our own rerun recordings,
and a bench that stopped resumes with the cases it lacks. The rotor-drag flights are flown
once for the module (5 flights: 2 fitting, 1 held out, its mission replayed in the nominal and
the corrected world)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from learner.flightlogs.readers import read_log
from mission.campaigns.gap_bench import RESULTS_FILE, run_bench, run_case
from mission.campaigns.gap_bench_cases import CASES
from mission.campaigns.gap_flights import AUTOPILOT_PARAMS, replay_params
from mission.cli.main import main


@pytest.fixture(scope="module")
def bench_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("gap_bench")


@pytest.fixture(scope="module")
def drag(bench_dir: Path) -> dict[str, Any]:
    """The rotor-drag case, its clean flights also recorded."""
    return run_case(CASES["rotor_drag_b"], bench_dir, record=True)


def test_withheld_rotor_drag_is_found_within_10_percent(bench_dir: Path, drag: dict) -> None:
    result = drag
    assert result["reported"] == ["rotor_drag"]
    drag = result["effects"]["rotor_drag"]
    assert drag["relative_errors"][0] <= 0.10  # kxy: the horizontal drag flown
    assert result["force_shrink"] >= 0.8
    assert result["effects"]["ceiling_effect"]["status"] == "not identifiable"  # no ceiling
    assert result["closed_loop"]["shrink"] > 0.0  # the corrected world flies closer to the log
    corrected = yaml.safe_load(
        (bench_dir / "rotor_drag_b/diagnosis/corrected_world.yaml").read_text()
    )
    assert "rotor_drag" in [e["name"] for e in corrected["effects"]]
    report = (bench_dir / "rotor_drag_b/diagnosis/report.md").read_text()
    assert "| rotor_drag | present |" in report
    assert (bench_dir / "rotor_drag_b/diagnosis/residuals.rrd").stat().st_size > 0


def test_null_world_raises_no_false_alarm(bench_dir: Path) -> None:
    """Through `gap bench`'s runner: the case is a task of a local process pool."""
    scores = run_bench([CASES["null_hover"]], bench_dir, workers=1)
    (result,) = scores["cases"]
    assert result["case"] == "null_hover" and result["reported"] == []
    assert result["false_alarm"] is False


def test_diagnose_reads_renamed_columns(
    bench_dir: Path, drag: dict, tmp_path: Path, capsys
) -> None:
    """The bench's logs rewritten with other names and units, diagnosed through a mapping."""
    import csv

    src = sorted((bench_dir / "rotor_drag_b").glob("flight[0-9].csv"))
    renamed = []
    for path in src:
        rows = list(csv.reader(ln for ln in path.open() if not ln.startswith("#")))
        header = ["T_ms" if h == "time_s" else f"their_{h}" for h in rows[0]]
        it = rows[0].index("time_s")
        body = [[str(float(v) * 1000) if i == it else v for i, v in enumerate(r)] for r in rows[1:]]
        out = tmp_path / path.name
        with out.open("w", newline="") as f:
            csv.writer(f).writerows([header, *body])
        renamed.append(out)
    mapping = tmp_path / "columns.yaml"
    names = {h: f"their_{h}" for h in rows[0] if h != "time_s"} | {"time_s": "T_ms"}
    mapping.write_text(yaml.safe_dump({"names": names, "units": {"time_s": "ms"}}))
    world = bench_dir / "rotor_drag_b/nominal_world.yaml"
    code = main(
        ["gap", "diagnose", *map(str, renamed), "--world", str(world), "--columns", str(mapping),
         "--folds", "2", "--no-replay", "--out", str(tmp_path / "out"),
         "--candidates", "rotor_drag,body_drag,thrust_mass,ground_effect"]
    )  # fmt: skip
    assert code == 0
    figures = json.loads((tmp_path / "out/gap.json").read_text())
    assert figures["effects"]["rotor_drag"]["status"] == "present"
    # the search kept to --candidates, the others said so
    assert figures["effects"]["wind"]["status"] == "not tried"
    added = {name for step in figures["search"][1:] for name in step["set"]}
    assert added <= {"rotor_drag", "body_drag", "thrust_mass", "ground_effect"}
    out = capsys.readouterr().out
    assert "rotor_drag" in out
    # it ends with the gaps before and after, what is left, and where the report is
    last = out.strip().splitlines()[-3:]
    assert last[0].startswith("force gap: ") and " mN -> " in last[0] and "shrink" in last[0]
    assert last[1].startswith("left unexplained by the catalogue: ")
    assert last[2] == f"report: {tmp_path / 'out' / 'report.md'}"
    assert "nan" not in out and "-%" not in out
    # a bad mapping names the column
    mapping.write_text(yaml.safe_dump({"names": {"time_s": "nope"}}))
    assert main(["gap", "diagnose", str(renamed[0]), "--world", str(world), "--columns",
                 str(mapping), "--no-replay", "--out", str(tmp_path / "bad")]) == 2  # fmt: skip
    assert "missing column 'nope'" in capsys.readouterr().err
    # an unknown candidate is refused before any log is read, naming the known ones
    assert main(["gap", "diagnose", str(renamed[0]), "--world", str(world), "--candidates",
                 "rotor_drag,rotor_dreg", "--out", str(tmp_path / "bad")]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "unknown candidate 'rotor_dreg'" in err and "ground_effect" in err


def test_diagnose_reads_recordings(bench_dir: Path, drag: dict, tmp_path: Path) -> None:
    """A flight's rerun recording gives the rows of its --flight-log CSV; the diagnosis on
    recordings finds the withheld rotor drag."""
    folder = bench_dir / "rotor_drag_b"
    csv_log, rec_log = (
        read_log(folder / "flight0.truth.csv"),
        read_log(folder / "flight0.truth.rrd"),
    )
    assert len(rec_log) == len(csv_log) > 1000
    np.testing.assert_allclose(rec_log.time_s, csv_log.time_s, atol=1e-9)
    for field in ("position_m", "quaternion", "rotor_speeds_rad_s", "acceleration_m_s2"):
        np.testing.assert_allclose(getattr(rec_log, field), getattr(csv_log, field), atol=1e-6)
    # a replay of a recorded flight flies the parameters that flight set (the bench's among
    # them), not the ground model's or online learning's
    flown = dict(p.split("=") for p in replay_params(rec_log.meta))
    for name, value in (p.split("=") for p in AUTOPILOT_PARAMS):
        assert float(flown[name]) == float(value), name
    assert not any(name.startswith("GFX_GE_") for name in flown)
    assert replay_params(csv_log.meta) == AUTOPILOT_PARAMS  # a log that carries none
    assert replay_params({"parameters": {"GFX_GE_RHO": 2.0, "MPC_XY_CRUISE": 0.7}}) == (
        # a recording from before the landing's two heights landed slowly from any height;
        # the ground model is the replay's own
        "MPC_LAND_ALT1=100",
        "MPC_LAND_ALT2=100",
        "MPC_XY_CRUISE=0.7",
    )
    assert "MPC_LAND_ALT1" not in flown  # a recording that carries it, at its default
    recordings = [str(folder / f"flight{s}.truth.rrd") for s in (0, 1, 100)]
    world = str(folder / "nominal_world.yaml")
    code = main(["gap", "diagnose", *recordings[:2], "--holdout", recordings[2], "--world", world,
                 "--folds", "2", "--no-replay", "--out", str(tmp_path / "out"),
                 "--candidates", "rotor_drag,body_drag,wind,thrust_mass"])  # fmt: skip
    assert code == 0
    figures = json.loads((tmp_path / "out/gap.json").read_text())
    drag_fit = figures["effects"]["rotor_drag"]
    assert drag_fit["status"] == "present"
    truth = CASES["rotor_drag_b"].truth["rotor_drag"]
    assert drag_fit["parameters"]["kxy"]["value"] == pytest.approx(truth["kxy"], rel=0.10)


def test_torque_residual_vanishes_on_a_clean_flight_with_the_true_world(
    bench_dir: Path, drag: dict
) -> None:
    """Equation 3.6 and the ground effect's hub torques explain a clean flight's rotational
    dynamics; leaving the ground effect out leaves its torque."""
    from learner.gap.candidates import nominal_values
    from learner.gap.flightdata import prepare
    from learner.gap.torque import torque_gap, torque_residual_n_m
    from simbridge.vehicle import load_vehicle
    from simbridge.world import load_world

    folder = bench_dir / "rotor_drag_b"
    vehicle, world = load_vehicle("nano"), load_world(folder / "real_world.yaml")
    d = prepare(read_log(folder / "flight0.truth.csv"), world, vehicle)
    true = nominal_values(world.effects)
    residual = torque_residual_n_m(d, true, vehicle)
    assert np.sqrt(np.mean(residual**2)) < 1e-6  # rotor moments: about 1e-4 N m
    without_ge = {k: v for k, v in true.items() if k != "ground_effect"}
    gap = torque_gap([d], without_ge, true, vehicle)
    assert gap["shrink"] > 0.9


def test_a_stopped_bench_resumes_with_the_cases_it_lacks(bench_dir: Path, drag: dict) -> None:
    """The null case's scores are on file (a bench that stopped after it): a bench of both
    cases runs only the rotor-drag case, whose flights are cached, and scores it as an
    uninterrupted run did (the fixture's, with replays, beside the same diagnosis)."""
    run_bench([CASES["null_hover"]], bench_dir, workers=1)  # on file already: not run again
    before = (bench_dir / RESULTS_FILE).read_text().splitlines()
    assert [json.loads(line)["id"] for line in before] == ["null_hover"]
    scores = run_bench([CASES["null_hover"], CASES["rotor_drag_b"]], bench_dir, workers=2)
    after = (bench_dir / RESULTS_FILE).read_text().splitlines()
    assert after[:1] == before and [json.loads(line)["id"] for line in after[1:]] == [
        "rotor_drag_b"
    ]
    null, resumed = scores["cases"]
    assert null["reported"] == [] and null["false_alarm"] is False
    for key in ("reported", "exact", "force_shrink"):
        assert resumed[key] == drag[key], key
    assert resumed["effects"]["rotor_drag"] == drag["effects"]["rotor_drag"]
