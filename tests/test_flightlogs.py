"""Real flight logs in: one known flight written the ways vehicles log it (actuator kinds,
accelerometer conventions, time units, '#' headers, list cells, Crazyflie microSD logs in both
formats) and read back to the same rotor speeds and acceleration; `groundfx gap convert`
through the command line; one test per refusal message."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from learner.flightlogs.flightlog import FlightLog, write_log
from learner.flightlogs.readers import read_log
from learner.flightlogs.tables import ColumnMapping, detect_time_unit, load_mapping
from simbridge.config import ConfigError
from simbridge.frames import quat_enu_flu_to_ned_frd, quat_from_euler, quat_to_matrices
from simbridge.vehicle import GRAVITY_M_S2, load_vehicle
from tests.helpers import run_groundfx

CF = load_vehicle("crazyflie2")
G_UP = np.array([0.0, 0.0, GRAVITY_M_S2])
STATE = ["time_s", "x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s", "qw", "qx", "qy", "qz",
         "p_rad_s", "q_rad_s", "r_rad_s"]  # fmt: skip


def known_flight(n: int = 300, rate_hz: float = 100.0) -> FlightLog:
    """A smooth flight with its exact velocity and acceleration, tilted and turning, rotor
    speeds about the Crazyflie's hover."""
    t = 5.0 + np.arange(n) / rate_hz
    w = 2 * math.pi * 0.5
    pos = np.column_stack(
        [0.2 * np.sin(w * t), 0.1 * np.cos(w * t), 0.5 + 0.05 * np.sin(2 * w * t)]
    )
    vel = np.column_stack([0.2 * w * np.cos(w * t), -0.1 * w * np.sin(w * t),
                           0.1 * w * np.cos(2 * w * t)])  # fmt: skip
    acc = np.column_stack([-0.2 * w * w * np.sin(w * t), -0.1 * w * w * np.cos(w * t),
                           -0.2 * w * w * np.sin(2 * w * t)])  # fmt: skip
    q = np.array([quat_from_euler(0.1 * np.sin(w * s), 0.08 * np.cos(w * s), 0.3 * s) for s in t])
    rates = np.column_stack([0.1 * np.cos(w * t), -0.08 * np.sin(w * t), np.full(n, 0.3)])
    hover = CF.hover_rotor_speed_rad_s
    rotors = hover * (1 + 0.05 * np.sin(w * t[:, None] + np.arange(4)))
    return FlightLog("known", t, pos, vel, q, rates, rotors, acc)


def state_columns(log: FlightLog) -> dict[str, np.ndarray]:
    cols = log.table()
    return {k: cols[k] for k in STATE}


def write_csv(path: Path, cols: dict[str, np.ndarray], header_prefix: str = "") -> Path:
    names = list(cols)
    data = np.column_stack([cols[n] for n in names])
    lines = [header_prefix + ",".join(names)] + [",".join(f"{v:.12g}" for v in r) for r in data]
    path.write_text("\n".join(lines) + "\n")
    return path


def mapping_file(path: Path, content: dict) -> Path:
    path.write_text(yaml.safe_dump(content))
    return path


def thrust_n(log: FlightLog) -> np.ndarray:
    return CF.thrust_coefficient_n_s2 * log.rotor_speeds_rad_s**2


# ---- actuator kinds -----------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["rotor_speed_rpm", "rotor_thrust_n", "rotor_thrust_gf", "pwm"])
def test_per_rotor_actuators_reproduce_the_rotor_speeds(tmp_path: Path, kind: str) -> None:
    log = known_flight()
    f = thrust_n(log)
    a, b, c = 0.3, 0.05, -0.002  # a PWM thrust curve, N = a u^2 + b u + c
    values, spec = {
        "rotor_speed_rpm": (log.rotor_speeds_rad_s * 60 / (2 * math.pi),
                            {"kind": "rotor_speed", "unit": "rpm"}),
        "rotor_thrust_n": (f, {"kind": "rotor_thrust", "unit": "N"}),
        "rotor_thrust_gf": (f * 1000 / GRAVITY_M_S2, {"kind": "rotor_thrust", "unit": "gf"}),
        "pwm": ((-b + np.sqrt(b * b - 4 * a * (c - f))) / (2 * a),
                {"kind": "pwm", "thrust_curve_n": [a, b, c]}),
    }[kind]  # fmt: skip
    # written in the Crazyflie's motor order M1 front-right .. M4 front-left
    cols = state_columns(log) | {f"M{i + 1}": values[:, 3 - i] for i in range(4)}
    path = write_csv(tmp_path / "theirs.csv", cols)
    spec = spec | {"columns": ["M4", "M3", "M2", "M1"]}
    got = read_log(path, load_mapping(mapping_file(tmp_path / "m.yaml", {"actuators": spec})), CF)
    assert got.rotor_speeds_rad_s == pytest.approx(log.rotor_speeds_rad_s, rel=1e-8)


def test_collective_thrust_shares_it_equally(tmp_path: Path) -> None:
    log = known_flight()
    total = thrust_n(log).sum(axis=1)
    path = write_csv(tmp_path / "t.csv", state_columns(log) | {"T": total})
    mapping = {"actuators": {"kind": "collective_thrust", "unit": "N", "columns": ["T"]}}
    got = read_log(path, load_mapping(mapping_file(tmp_path / "m.yaml", mapping)), CF)
    assert (CF.thrust_coefficient_n_s2 * got.rotor_speeds_rad_s**2).sum(1) == pytest.approx(total)
    assert np.ptp(got.rotor_speeds_rad_s, axis=1) == pytest.approx(0.0, abs=1e-9)
    assert "collective N" in got.meta["conversions"][-1]


@pytest.mark.parametrize("hover", ["value", "column"])
def test_throttle_over_the_hover_throttle_is_the_weight(tmp_path: Path, hover: str) -> None:
    log = known_flight()
    total = thrust_n(log).sum(axis=1)
    h = 0.45 + 0.01 * np.linspace(0, 1, len(log))  # sags with the battery
    h_used = h if hover == "column" else np.full(len(log), 0.47)
    throttle = total / CF.weight_n * h_used
    path = write_csv(tmp_path / "t.csv", state_columns(log) | {"u": throttle, "h": h})
    spec = {
        "kind": "throttle",
        "columns": ["u"],
        "hover_throttle": "h" if hover == "column" else 0.47,
    }
    got = read_log(path, load_mapping(mapping_file(tmp_path / "m.yaml", {"actuators": spec})), CF)
    assert (CF.thrust_coefficient_n_s2 * got.rotor_speeds_rad_s**2).sum(1) == pytest.approx(total)


# ---- accelerometer conventions and frames ---------------------------------------------------


@pytest.mark.parametrize("gravity", ["included", "removed"])
@pytest.mark.parametrize("frame", ["world", "body"])
def test_accelerometer_conventions_give_the_kinematic_acceleration(
    tmp_path: Path, gravity: str, frame: str
) -> None:
    log = known_flight()
    a = log.acceleration_m_s2 + (G_UP if gravity == "included" else 0.0)
    if frame == "body":
        a = np.einsum("nji,nj->ni", quat_to_matrices(log.quaternion), a)  # R^T a
    cols = state_columns(log) | {f"acc{i}": a[:, i] for i in range(3)}
    cols |= {f"n{i}_rad_s": log.rotor_speeds_rad_s[:, i] for i in range(4)}
    mapping = {"names": {"ax_m_s2": "acc0", "ay_m_s2": "acc1", "az_m_s2": "acc2"},
               "accelerometer": {"gravity": gravity, "frame": frame}}  # fmt: skip
    got = read_log(
        write_csv(tmp_path / "a.csv", cols),
        load_mapping(mapping_file(tmp_path / "m.yaml", mapping)),
    )
    assert got.acceleration_m_s2 == pytest.approx(log.acceleration_m_s2, abs=1e-9)


def test_ned_frd_log_with_a_body_accelerometer_in_mg(tmp_path: Path) -> None:
    """PX4's frames: world NED, body FRD, the accelerometer a body specific force, in mg."""
    log = known_flight()
    f_body = np.einsum("nji,nj->ni", quat_to_matrices(log.quaternion), log.acceleration_m_s2 + G_UP)
    ned = np.array([[1.0, 0, 0], [0, -1, 0], [0, 0, -1]])  # FLU <-> FRD
    swap = np.array([[0, 1.0, 0], [1, 0, 0], [0, 0, -1]])  # ENU <-> NED
    q_ned = np.array([quat_enu_flu_to_ned_frd(tuple(q)) for q in log.quaternion])
    theirs = {
        "t": log.time_s * 1000,
        **dict(zip(("N", "E", "D"), (log.position_m @ swap.T).T, strict=True)),
        **dict(zip(("vn", "ve", "vd"), (log.velocity_m_s @ swap.T).T, strict=True)),
        **dict(zip(("q0", "q1", "q2", "q3"), q_ned.T, strict=True)),
        **dict(zip(("p", "q", "r"), (log.body_rates_rad_s @ ned.T).T, strict=True)),
        **dict(zip(("fx", "fy", "fz"), (f_body @ ned.T).T / 9.81e-3, strict=True)),
        **{f"m{i}": log.rotor_speeds_rad_s[:, i] for i in range(4)},
    }
    names = dict(zip(STATE, list(theirs)[:14], strict=True))
    names |= {"ax_m_s2": "fx", "ay_m_s2": "fy", "az_m_s2": "fz"}
    names |= {f"n{i}_rad_s": f"m{i}" for i in range(4)}
    mapping = ColumnMapping(
        names=names, units={"ax_m_s2": "mg", "ay_m_s2": "mg", "az_m_s2": "mg"}, frame="ned_frd",
        time_unit="ms", accelerometer=("included", "body"),
    )  # fmt: skip
    got = read_log(write_csv(tmp_path / "ned.csv", theirs), mapping)
    assert got.position_m == pytest.approx(log.position_m, abs=1e-9)
    assert got.body_rates_rad_s == pytest.approx(log.body_rates_rad_s, abs=1e-9)
    assert got.acceleration_m_s2 == pytest.approx(log.acceleration_m_s2, abs=1e-6)
    assert np.abs(np.sum(got.quaternion * log.quaternion, axis=1)) == pytest.approx(1.0)


# ---- CSV shapes -----------------------------------------------------------------------------


def test_hash_header_and_comment_lines(tmp_path: Path) -> None:
    log = known_flight()
    cols = {"time[ms]": log.time_s * 1000} | {
        k: v for k, v in state_columns(log).items() if k != "time_s"
    }
    cols |= {f"n{i}_rad_s": log.rotor_speeds_rad_s[:, i] for i in range(4)}
    path = write_csv(tmp_path / "h.csv", cols, header_prefix="# ")
    path.write_text("# logged by a Crazyflie script\n" + path.read_text() + "# the end\n")
    got = read_log(path, ColumnMapping(names={"time_s": "time[ms]"}, time_unit="ms"))
    assert got.time_s == pytest.approx(log.time_s)
    assert got.rotor_speeds_rad_s == pytest.approx(log.rotor_speeds_rad_s)


def test_rows_written_twice_out_of_order_or_with_a_gap_in_a_cell_are_dropped_and_said(
    tmp_path: Path,
) -> None:
    """A user's CSV as loggers write it: a row written twice, two rows swapped, an empty
    cell. The repeated stamp once made a zero time step (numpy's divide-by-zero warnings,
    then NaN in the diagnosis's derivatives)."""
    log = known_flight()
    cols = state_columns(log) | {f"n{i}_rad_s": log.rotor_speeds_rad_s[:, i] for i in range(4)}
    rows = np.column_stack(list(cols.values()))
    rows = np.insert(rows, 50, rows[50], axis=0)  # written twice
    rows[[100, 101]] = rows[[101, 100]]  # swapped
    rows[200, 3] = np.nan  # z missing
    path = write_csv(tmp_path / "u.csv", dict(zip(cols, rows.T, strict=True)))
    got = read_log(path)
    keep = np.ones(len(log.time_s), bool)
    keep[199] = False  # the swap and the copy moved the empty cell's row one place
    assert got.time_s == pytest.approx(log.time_s[keep])
    assert np.all(np.diff(got.time_s) > 0.0)
    assert np.all(np.isfinite(got.position_m))
    notes = got.meta["conversions"]
    assert "rows: 1 row with a missing or non-finite value dropped" in notes
    assert "rows: 1 row repeating an earlier time stamp dropped" in notes


def test_list_cells_and_the_neural_fly_mapping(tmp_path: Path) -> None:
    """Neural-Fly's layout: a pandas index, lists as text, q as (x, y, z, w), throttle over a
    per-row hover throttle; read with the packaged mapping on a 2.69 kg vehicle."""
    log = known_flight(n=200, rate_hz=50.0)
    quad = load_vehicle("quad_2_7kg")
    h = np.full(len(log), 0.48)
    t_sp = h * (1.0 + 0.1 * np.sin(log.time_s))
    lines = [",t,p,v,q,w,T_sp,hover_throttle"]
    for k in range(len(log)):
        q = log.quaternion[k]
        cells = [str(k), repr(float(log.time_s[k] - log.time_s[0])),
                 str(log.position_m[k].tolist()), str(log.velocity_m_s[k].tolist()),
                 str(q[[1, 2, 3, 0]].tolist()), str(log.body_rates_rad_s[k].tolist()),
                 f"[{float(t_sp[k])!r}]", f"[{float(h[k])!r}]"]  # fmt: skip
        lines.append(",".join(f'"{c}"' if "," in c else c for c in cells))
    path = tmp_path / "custom_figure8.csv"
    path.write_text("\n".join(lines) + "\n")
    got = read_log(path, load_mapping("neural_fly"), quad)
    assert got.position_m == pytest.approx(log.position_m)
    assert got.quaternion == pytest.approx(log.quaternion)
    thrust = quad.thrust_coefficient_n_s2 * (got.rotor_speeds_rad_s**2).sum(1)
    assert thrust == pytest.approx(quad.weight_n * t_sp / h)
    assert got.acceleration_m_s2 is None


def test_the_neural_swarm_csv_export_is_read_with_its_packaged_mapping(tmp_path: Path) -> None:
    """Neural-Swarm's CSV layout: a '#' header with units in the names, time in
    microseconds under `time[ms]`, world acceleration with +g, (x, y, z, w) quaternion,
    per-rotor thrust in the Crazyflie's motor order M1 front-right .. M4 front-left."""
    log = known_flight()
    f = thrust_n(log)
    q = log.quaternion
    cols = {
        "time[ms]": log.time_s * 1e6,
        **{f"{a}[m]": log.position_m[:, i] for i, a in enumerate("xyz")},
        **{f"v{a}[m/s]": log.velocity_m_s[:, i] for i, a in enumerate("xyz")},
        **{f"a{a}[m/s^2]": (log.acceleration_m_s2 + G_UP)[:, i] for i, a in enumerate("xyz")},
        "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3], "qw": q[:, 0],
        **{f"u{i + 1}[N]": f[:, 3 - i] for i in range(4)},
        "Vbat[V]": np.full(len(log), 3.9),
        **{f"w{a}[rad/s]": log.body_rates_rad_s[:, i] for i, a in enumerate("xyz")},
    }  # fmt: skip
    path = write_csv(tmp_path / "cf50_00.csv", cols, header_prefix="# ")
    got = read_log(path, load_mapping("neural_swarm"), CF)
    assert got.time_s == pytest.approx(log.time_s)
    assert got.position_m == pytest.approx(log.position_m)
    assert got.quaternion == pytest.approx(log.quaternion)
    assert got.acceleration_m_s2 == pytest.approx(log.acceleration_m_s2, abs=1e-9)
    assert got.rotor_speeds_rad_s == pytest.approx(log.rotor_speeds_rad_s, rel=1e-8)
    assert got.battery_v == pytest.approx(3.9)


# ---- time units -----------------------------------------------------------------------------


@pytest.mark.parametrize(("raw_step", "unit"), [(0.01, "s"), (10.0, "ms"), (9870.0, "us"),
                                                (4e6, "ns"), (0.3, "s")])  # fmt: skip
def test_time_unit_is_detected_where_unambiguous(raw_step: float, unit: str) -> None:
    assert detect_time_unit(raw_step * np.arange(300), "t")[0] == unit


def test_time_unit_detection_refuses_an_ambiguous_clock() -> None:
    # a step of 0.3 over 10,000 rows: 3.3 Hz for 50 min, or 3.3 kHz for 3 s
    with pytest.raises(ConfigError, match=r"it could be s or ms\); set time_unit"):
        detect_time_unit(0.3 * np.arange(10000), "log.csv: time column 't'")


def test_time_unit_detection_refuses_a_clock_without_steps() -> None:
    with pytest.raises(ConfigError, match=r"too few distinct times"):
        detect_time_unit(np.zeros(50), "t")


def test_auto_time_unit_end_to_end(tmp_path: Path) -> None:
    log = known_flight()
    cols = state_columns(log) | {"tick": log.time_s * 1e6}
    cols.pop("time_s")
    cols |= {f"n{i}_rad_s": log.rotor_speeds_rad_s[:, i] for i in range(4)}
    got = read_log(write_csv(tmp_path / "t.csv", cols), ColumnMapping(names={"time_s": "tick"}))
    assert got.time_s == pytest.approx(log.time_s)
    assert "time: us -> s (detected" in got.meta["conversions"][0]


# ---- groundfx gap convert, through the command line -----------------------------------------


def test_gap_convert_refuses_an_output_that_is_not_our_format(tmp_path: Path) -> None:
    src = write_log(known_flight(), tmp_path / "ours.csv")
    r = run_groundfx("gap", "convert", str(src), str(tmp_path / "out.txt"))
    assert r.returncode == 2
    assert "out.txt: our format is written as .csv or .parquet" in r.stderr


# ---- one test per refusal -------------------------------------------------------------------


def ours_csv(tmp_path: Path) -> Path:
    return write_log(known_flight(n=60), tmp_path / "ours.csv")


def refuses(tmp_path: Path, mapping: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        load_mapping(mapping_file(tmp_path / "bad.yaml", mapping))


def test_refuses_an_unknown_mapping_key(tmp_path: Path) -> None:
    refuses(tmp_path, {"colums": {}}, r"bad\.yaml: unknown key 'colums'; known keys: names")


def test_refuses_a_quaternion_order_beside_named_quaternion_columns(tmp_path: Path) -> None:
    """Both would reorder the components: the quaternion flipped twice, every row read as the
    body upside down."""
    names = {"qw": "q.w", "qx": "q.x", "qy": "q.y", "qz": "q.z"}
    refuses(tmp_path, {"names": names, "quaternion_order": "xyzw"},
            r"quaternion_order xyzw beside names for qw, qx, qy, qz: give one of them")  # fmt: skip


def test_refuses_an_unknown_actuator_kind(tmp_path: Path) -> None:
    refuses(tmp_path, {"actuators": {"kind": "rpm", "columns": ["a"] * 4}},
            r"bad\.yaml: actuators\.kind: 'rpm' is not one of rotor_speed, rotor_")  # fmt: skip


def test_refuses_the_wrong_number_of_actuator_columns(tmp_path: Path) -> None:
    refuses(tmp_path, {"actuators": {"kind": "rotor_thrust", "columns": ["a", "b"]}},
            r"actuators\.columns: kind rotor_thrust needs 4 column name\(s\)")  # fmt: skip


def test_refuses_rotor_columns_mapped_twice(tmp_path: Path) -> None:
    refuses(tmp_path, {"names": {"n0_rad_s": "m0"}, "actuators": {"columns": ["a"] * 4}},
            r"n0_rad_s is mapped in names/units and by actuators\.columns")  # fmt: skip


def test_refuses_throttle_without_a_hover_throttle(tmp_path: Path) -> None:
    refuses(tmp_path, {"actuators": {"kind": "throttle", "columns": ["u"]}},
            r"actuators\.hover_throttle: kind throttle needs a value in \(0, 1\]")  # fmt: skip


def test_refuses_an_unknown_accelerometer_convention(tmp_path: Path) -> None:
    refuses(tmp_path, {"accelerometer": {"gravity": "yes"}},
            r"accelerometer\.gravity: 'yes' is not one of removed, included")  # fmt: skip


def test_refuses_an_unknown_time_unit(tmp_path: Path) -> None:
    refuses(tmp_path, {"time_unit": "min"}, r"time_unit: 'min' is not one of s, ms, us, ns, auto")


def test_refuses_a_time_unit_that_contradicts_the_units(tmp_path: Path) -> None:
    refuses(tmp_path, {"time_unit": "ms", "units": {"time_s": "us"}},
            r"time_unit: ms contradicts units\.time_s: us")  # fmt: skip


def test_refuses_a_column_name_that_is_not_text(tmp_path: Path) -> None:
    refuses(tmp_path, {"names": {"x_m": 3}}, r"names\.x_m: expected a column name \(text\), got 3")


def test_refuses_an_unknown_packaged_mapping() -> None:
    with pytest.raises(ConfigError, match=r"column mapping 'px4': no such file or packaged"):
        load_mapping("px4")


def test_refuses_a_missing_accelerometer_the_mapping_promises(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"missing column 'ax_m_s2' \(ax_m_s2"):
        log = known_flight(n=60)
        path = write_log(dataclasses.replace(log, acceleration_m_s2=None), tmp_path / "o.csv")
        read_log(path, ColumnMapping(accelerometer=("included", "body")))


def test_refuses_a_list_column_addressed_whole(tmp_path: Path) -> None:
    path = tmp_path / "l.csv"
    path.write_text('t,p\n0,"[1.0, 2.0, 3.0]"\n1,"[1.0, 2.0, 3.0]"\n')
    with pytest.raises(
        ConfigError,
        match=r"column 'p' \(x_m\) holds lists; address its elements as p\[0\], p\[1\], p\[2\]",
    ):
        read_log(path, ColumnMapping(names={"time_s": "t", "x_m": "p"}, time_unit="s"))


def test_refuses_a_ragged_list_column(tmp_path: Path) -> None:
    path = tmp_path / "l.csv"
    path.write_text('t,p\n0,"[1.0, 2.0]"\n1,"[1.0]"\n')
    with pytest.raises(ConfigError, match=r"l\.csv: line 3, column 'p': a list of shape \(1,\)"):
        read_log(path)


def test_refuses_a_cell_that_is_not_a_number(tmp_path: Path) -> None:
    path = ours_csv(tmp_path)
    lines = path.read_text().splitlines()
    cells = lines[5].split(",")
    lines[5] = ",".join([cells[0], "abc", *cells[2:]])
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(
        ConfigError, match=r"ours\.csv: line 6, column 'x_m': 'abc' is not a number"
    ):
        read_log(path)


def test_refuses_a_row_with_a_field_too_many(tmp_path: Path) -> None:
    path = ours_csv(tmp_path)
    path.write_text(path.read_text() + "1,2\n")
    with pytest.raises(ConfigError, match=r"ours\.csv: line 63: 2 fields, the header names 21"):
        read_log(path)


def test_refuses_a_hash_header_that_does_not_name_every_field(tmp_path: Path) -> None:
    path = tmp_path / "h.csv"
    path.write_text("# time[ms],x\n1,2,3\n2,3,4\n")
    with pytest.raises(ConfigError, match=r"the first row has 3 fields but the '#' header line"):
        read_log(path)


def test_refuses_a_file_of_no_known_format(tmp_path: Path) -> None:
    path = tmp_path / "flight.dat"
    path.write_bytes(bytes(range(256)))
    with pytest.raises(
        ConfigError, match=r"flight\.dat: not a flight log format we know \(suffix \.dat\)"
    ):
        read_log(path)


def test_summary_warns_of_gravity_left_in_the_acceleration() -> None:
    from learner.flightlogs.summary import summarize

    log = known_flight()
    biased = dataclasses.replace(log, acceleration_m_s2=log.acceleration_m_s2 + G_UP)
    warnings = summarize(biased, CF)["warnings"]
    assert any(
        "mean vertical acceleration is 9.81 m/s^2: is gravity included" in w for w in warnings
    )


def test_summary_warns_of_a_biased_accelerometer() -> None:
    from learner.flightlogs.summary import summarize

    log = known_flight()
    biased = dataclasses.replace(
        log, acceleration_m_s2=log.acceleration_m_s2 + np.array([0.4, 0, 0])
    )
    (warning,) = summarize(biased, CF)["warnings"]
    assert "departs from the velocity's change by [0.40, " in warning
    assert "force of 13 mN" in warning
