"""The ground where the logs' frame has it. A motion-capture frame's z = 0 need not be the
world's floor (the neural-swarm Crazyflies rest at a logged 49-61 mm, where the simulator's
box rests at 14.5 mm): a flight that rests on the ground says where it is, and the diagnosis
puts every log's z on the world's ground before it looks at heights. Synthetic logs of a
ground effect (the diagnosis's own force model, as in test_gap_robust) in a frame 35 mm off,
through the real pipeline (`run_diagnosis`, the CLI)."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest

from learner.flightlogs.flightlog import FlightLog, write_log
from learner.flightlogs.readers import read_log
from learner.flightlogs.summary import summarize, summary_lines
from mission.campaigns.gap_diagnosis import run_diagnosis
from tests.test_gap_robust import NANO, cli, synthetic_log, world_file

FRAME_OFFSET_M = 0.035  # the logs' z of the world's floor
RHO = 3.0


def logged_in_offset_frame(name: str, world: Path, seed: int, rests: bool, folder: Path) -> Path:
    """A ground-effect flight along a Lissajous down to 8 cm, after (if `rests`) 0.5 s on
    the ground with the rotors off and a second without logging (the take-off), every z
    logged FRAME_OFFSET_M higher than the world has it."""
    log = synthetic_log(name, NANO, world, {"ground_effect": np.array([RHO])}, seed,
                        seconds=20.0, low_m=0.08)  # fmt: skip
    if rests:
        rng = np.random.default_rng(seed)
        k = 50
        t = log.time_s[0] - 1.5 + 0.01 * np.arange(k)
        p = np.tile([log.position_m[0, 0], log.position_m[0, 1], NANO.body_size_m[2] / 2], (k, 1))
        p += rng.normal(0.0, 0.001, p.shape)  # the motion capture's noise
        still = np.zeros((k, 3))
        log = FlightLog(
            log.name, np.concatenate([t, log.time_s]), np.vstack([p, log.position_m]),
            np.vstack([still, log.velocity_m_s]),
            np.vstack([np.tile([1.0, 0.0, 0.0, 0.0], (k, 1)), log.quaternion]),
            np.vstack([still, log.body_rates_rad_s]),
            np.vstack([np.zeros((k, 4)), log.rotor_speeds_rad_s]),
            np.vstack([still, log.acceleration_m_s2]),
        )  # fmt: skip
    position = log.position_m.copy()
    position[:, 2] += FRAME_OFFSET_M
    return write_log(dataclasses.replace(log, position_m=position), folder / f"{name}.csv")


@pytest.fixture(scope="module")
def flights(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The world, two fitting flights that rest on the ground first, a held-out flight that
    never does (logged from the air), and their diagnosis (`run_diagnosis`, as the CLI)."""
    folder = tmp_path_factory.mktemp("ground_level")
    world = world_file(folder / "world.yaml")
    fit = [logged_in_offset_frame(f"f{s}", world, s, True, folder) for s in (0, 1)]
    held = logged_in_offset_frame("f2", world, 2, False, folder)
    out = folder / "out"
    figures = run_diagnosis(fit, [held], str(world), out, folds=2, replay=False)
    return {"world": world, "fit": fit, "held": held, "out": out, "figures": figures}


def test_the_ground_is_found_where_the_vehicle_rests_and_the_ground_effect_with_it(
    flights: dict,
) -> None:
    figures = flights["figures"]
    # each resting flight by its own rest, the one that never rests by theirs
    assert figures["z_offsets_m"] == pytest.approx(
        {"f0": FRAME_OFFSET_M, "f1": FRAME_OFFSET_M, "f2": FRAME_OFFSET_M}, abs=0.001
    )
    ge = figures["effects"]["ground_effect"]
    assert ge["status"] == "present"
    assert ge["parameters"]["rho"]["value"] == pytest.approx(RHO, rel=0.1)
    assert figures["left_out"]["contact_rows"] == 2 * 50  # the rests: contact, left out
    assert figures["gap"]["force_rms_n"]["shrink"] >= 0.8
    said = re.compile(
        r"z shifted: f0 -3[45]\.\d mm \(where it rests\), f1 -3[45]\.\d mm \(where it "
        r"rests\), f2 -3[45]\.\d mm \(the median of the flights that rest\)"
    )
    assert any(said.search(note) for note in figures["notes"])
    assert said.search((flights["out"] / "report.md").read_text())


def test_read_as_if_its_zero_were_the_floor_the_same_logs_mislead(
    flights: dict, tmp_path: Path
) -> None:
    """`--z-offset 0`, the old reading: the rests look like a hover 35 mm up with the
    rotors off (nothing left out as contact), the ground effect's rho comes out wrong and
    the held-out gap stays larger than with the ground found."""
    out = tmp_path / "zero"
    done = cli(*map(str, flights["fit"]), "--holdout", str(flights["held"]), "--world",
               str(flights["world"]), "--folds", "2", "--no-replay", "--z-offset", "0",
               "--out", str(out))  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "note: every log's z is shifted by +0.0 mm (--z-offset)" in done.stdout
    wrong = json.loads((out / "gap.json").read_text())
    assert wrong["left_out"]["contact_rows"] == 0
    rho = wrong["effects"]["ground_effect"].get("parameters", {}).get("rho", {}).get("value")
    assert rho is None or abs(rho - RHO) > 0.3 * RHO
    right = flights["figures"]["gap"]["force_rms_n"]["after"]
    assert right < wrong["gap"]["force_rms_n"]["after"]


def test_convert_says_where_a_flight_rests(flights: dict) -> None:
    lines = summary_lines(summarize(read_log(flights["fit"][0]), NANO), NANO)
    assert any(line.startswith("rests on a surface in 50 rows at z 0.04") and "+35" in line
               for line in lines)  # fmt: skip
    assert not any("rests on" in line for line in
                   summary_lines(summarize(read_log(flights["held"]), NANO), NANO))  # fmt: skip


def test_a_log_in_the_worlds_own_frame_is_left_where_it_is(flights: dict) -> None:
    """groundfx's recordings and flight logs say their frame is the world's: a flight that
    seems to rest off the ground (a landing floating millimetres over a strong ground effect
    reads as one) is not moved, and the others are levelled as before."""
    from learner.gap.ground_level import level_logs
    from simbridge.world import load_world

    ours, theirs = (read_log(p) for p in flights["fit"])
    ours = dataclasses.replace(ours, meta={**ours.meta, "frame": "world"})
    world = load_world(flights["world"])
    leveled, notes, applied = level_logs([ours, theirs], world, NANO)
    assert leveled[0] is ours and ours.name not in applied
    assert applied[theirs.name] == pytest.approx(FRAME_OFFSET_M, abs=0.001)
    assert ours.name not in " ".join(notes)
