"""Rows the gap diagnosis leaves out or restates, counted: short stretches and contact with
any surface, a vehicle standing with its rotors stopped, rotor commands beyond the rotors'
maximum. Synthetic logs (`tests/test_gap_robust.py`'s), the real pipeline."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from learner.flightlogs.flightlog import FlightLog, write_log
from learner.gap.candidates import nominal_values, world_force
from learner.gap.flightdata import prepare
from mission.campaigns.gap_diagnosis import run_diagnosis
from simbridge.vehicle import GRAVITY_M_S2
from simbridge.world import load_world
from tests.test_gap_robust import DT_S, FEW, NANO, synthetic_log, world_file


def test_short_stretches_and_contact_with_any_surface_are_left_out_and_counted(
    tmp_path: Path,
) -> None:
    """A flight that starts on the ground, bounces at touchdown (a 1-row and a 7-row hop
    between contacts, and 15 rows after a logging gap) and ends resting on a box top: the
    old pipeline stopped with 'cannot reshape array of size 15 into shape (1,3)'."""
    box = {"kind": "box", "center_m": [5.0, 5.0, 0.05], "size_m": [0.4, 0.4, 0.1]}
    world = world_file(tmp_path / "world.yaml", obstacles=[box])
    rest_z = NANO.body_size_m[2] / 2.0
    logs = []
    for seed in (0, 1):
        log = synthetic_log(f"f{seed}", NANO, world, {}, seed, seconds=20.0)
        t0 = log.time_s[-1]

        def rows(z: float, k: int, at: tuple[float, float] = (0.0, 0.0)) -> dict:
            return {"p": np.tile([at[0], at[1], z], (k, 1)), "k": k}

        # on the ground, hop 1 row, ground, hop 7 rows, ground, (gap) 15 rows, on the box
        on_box = rows(0.1 + rest_z, 20, (5.0, 5.0))
        tail = [rows(rest_z, 30), rows(0.03, 1), rows(rest_z, 5), rows(0.03, 7),
                rows(rest_z, 10), None, rows(0.05, 15), on_box]  # fmt: skip
        # each part two periods after the last (a dropped row): the position smoothing of the
        # contact test stays within a part, as a real log's continuous motion would let it
        t, p, gap = [], [], 0.0
        for part in tail:
            if part is None:
                gap += 1.0  # a logging gap of a second
                continue
            gap += DT_S
            start = t0 + gap + DT_S * (1 + sum(len(x) for x in t))
            t.append(start + DT_S * np.arange(part["k"]))
            p.append(part["p"])
        t_all, p_all = np.concatenate(t), np.concatenate(p)
        k = len(t_all)
        level = np.tile([1.0, 0.0, 0.0, 0.0], (k, 1))
        log = FlightLog(
            log.name, np.concatenate([log.time_s, t_all]),
            np.vstack([log.position_m, p_all]), np.vstack([log.velocity_m_s, np.zeros((k, 3))]),
            np.vstack([log.quaternion, level]), np.zeros((len(log.time_s) + k, 3)),
            np.vstack([log.rotor_speeds_rad_s, np.full((k, 4), 20.0)]),
            np.vstack([log.acceleration_m_s2, np.zeros((k, 3))]),
        )  # fmt: skip
        logs.append(write_log(log, tmp_path / f"f{seed}.csv"))
    out = tmp_path / "out"
    run_diagnosis(logs, [], str(world), out, folds=2, replay=False, candidates=FEW)
    figures = json.loads((out / "gap.json").read_text())
    left = figures["left_out"]
    # per flight: contact 30 + 5 + 10 on the ground and 20 on the box; hops of 1 and 7 rows
    # and the 15 rows after the gap are stretches shorter than 0.2 s
    assert left["contact_rows"] == 2 * 65
    assert left["short_stretches"] == 2 * 3
    assert left["short_rows"] == 2 * 23
    summary = "left out: 6 stretches shorter than 0.2 s (46 rows), 130 rows in contact"
    assert left["summary"].startswith(summary)
    assert summary in (out / "report.md").read_text()


def test_standing_with_the_rotors_stopped_is_left_out_even_where_the_heights_miss_the_ground(
    tmp_path: Path,
) -> None:
    """A PX4 log's disarmed minutes before take-off, in a local frame that does not put the
    ground at zero (pyulog's sample logs): 20 s standing 0.5 m 'above the ground' with the
    rotors stopped, the estimated height wandering by 0.4 m at up to 0.8 m/s as an outdoor
    estimator's does on the ground (ArduCopter 3.3's log171 at CMAC), then the flight. Those
    rows carry a full weight of residual; before, the run stopped as 'implausible for a flying
    vehicle' (and with the wandering velocity, they were kept: the rule asked for rest). A
    rotor cut in the air (0.3 s of free fall, rotors stopped) is kept: it falls, nothing
    holds it."""
    world = world_file(tmp_path / "world.yaml")
    logs = []
    for seed in (0, 1):
        log = synthetic_log(f"f{seed}", NANO, world, {}, seed, seconds=10.0)
        k, j = 2000, 30  # standing rows, then free-fall rows
        t0 = log.time_s[0] - DT_S * (k + j)
        t = t0 + DT_S * np.arange(k + j)
        p = np.tile([0.0, 0.0, 0.5], (k + j, 1))
        v, a = np.zeros((k + j, 3)), np.zeros((k + j, 3))
        w = 2.0  # rad/s: the estimate wanders 0.4 m; the accelerometer reads the ground
        p[:k, 2] += (0.8 / w) * np.sin(w * (t[:k] - t0))
        v[:k, 2] = 0.8 * np.cos(w * (t[:k] - t0))
        tf = DT_S * np.arange(j)
        p[k:, 2] = 1.5 - 0.5 * GRAVITY_M_S2 * tf**2
        v[k:, 2], a[k:, 2] = -GRAVITY_M_S2 * tf, -GRAVITY_M_S2
        level = np.tile([1.0, 0.0, 0.0, 0.0], (k + j, 1))
        log = FlightLog(
            log.name, np.concatenate([t, log.time_s]), np.vstack([p, log.position_m]),
            np.vstack([v, log.velocity_m_s]), np.vstack([level, log.quaternion]),
            np.zeros((k + j + len(log.time_s), 3)),
            np.vstack([np.zeros((k + j, 4)), log.rotor_speeds_rad_s]),
            np.vstack([a, log.acceleration_m_s2]),
        )  # fmt: skip
        d = prepare(log, load_world(world), NANO)
        assert d.left_out["held_rows"] == k
        assert d.left_out["contact_rows"] == 0 and d.left_out["crash_rows"] == 0
        assert len(d.time_s) == len(log.time_s) - k  # the free fall and the flight kept
        logs.append(write_log(log, tmp_path / f"f{seed}.csv"))
    out = tmp_path / "out"
    run_diagnosis(logs, [], str(world), out, folds=2, replay=False, candidates=FEW)
    figures = json.loads((out / "gap.json").read_text())
    # all standing rows out (the diagnosis's ground level, set from the rows resting on the
    # ground, puts the lowest of them in contact)
    left = figures["left_out"]
    assert left["held_rows"] + left["contact_rows"] == 2 * 2000, left
    assert f"{left['held_rows']} rows standing with the rotors stopped" in left["summary"]
    present = [e for e, r in figures["effects"].items() if r["status"] == "present"]
    assert present == []  # the nominal world flew: nothing to name


def test_commands_beyond_the_rotors_maximum_are_clamped_as_the_simulator_clamps_them(
    tmp_path: Path,
) -> None:
    """A Crazyflie logs the force it asks of a rotor, up to 1.7 times what the rotor gives
    (Neural-Swarm's two-vehicle flights: a rotor at 98% of n_max in 12% of the rows). The
    vehicle flew the clamped command, as the simulator would: modelled unclamped, those rows
    read as a thrust deficit of a third of the weight and a thrust curve of 0.36."""
    world = world_file(tmp_path / "world.yaml")
    w = load_world(world)
    logs = []
    for seed in (0, 1):
        log = synthetic_log(f"f{seed}", NANO, world, {}, seed, seconds=10.0)
        n = log.rotor_speeds_rad_s.copy()
        burst = (np.arange(len(n)) % 200) < 20  # 10% of the rows: one rotor asked too much
        n[burst, 1] = 1.4 * NANO.max_rotor_speed_rad_s
        flown = dataclasses.replace(
            log, rotor_speeds_rad_s=np.minimum(n, NANO.max_rotor_speed_rad_s)
        )
        d = prepare(flown, w, NANO)
        acc = world_force(nominal_values(w.effects, NANO), d, NANO) / NANO.mass_kg
        acc[:, 2] -= GRAVITY_M_S2
        logged = dataclasses.replace(log, rotor_speeds_rad_s=n, acceleration_m_s2=acc)
        assert prepare(logged, w, NANO).left_out["clamped_rows"] == int(burst.sum())
        logs.append(write_log(logged, tmp_path / f"f{seed}.csv"))
    out = tmp_path / "out"
    run_diagnosis(logs[:1], logs[1:], str(world), out, folds=2, replay=False, candidates=FEW)
    figures = json.loads((out / "gap.json").read_text())
    present = [e for e, r in figures["effects"].items() if r["status"] == "present"]
    assert present == []
    assert figures["gap"]["force_rms_n"]["before"] < 1e-3  # the nominal world fits
    assert any("clamped there, as the simulator clamps them" in n for n in figures["notes"])
