"""Mission files: YAML (local metres), QGroundControl .plan and QGC WPL 110, read and written
through one model, with errors that name the file, the item and the field."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import random

import pytest
import yaml
from pymavlink import mavwp

from autopilot.commander.mission_items import (
    DO_CHANGE_SPEED,
    NAV_LAND,
    NAV_RETURN_TO_LAUNCH,
    NAV_TAKEOFF,
    NAV_WAYPOINT,
    Geofence,
    Home,
    MissionItem,
    item_at,
    local_offset,
    speed_item,
)
from mission.plans.doc import MissionDoc, default_home, dege7_to_deg
from mission.plans.formats import load_mission_file, save_mission_file
from mission.plans.yaml_plan import yaml_form
from simbridge.config import ConfigError
from simbridge.hil import mavlink as mav
from tests.helpers import REPO, run_groundfx

EXAMPLES = REPO / "mission" / "examples"
OLD_EXAMPLES = ("demo", "hover", "low_hover", "land_on_box")
HOME = Home(47.3977419, 8.5455938, 488.0)  # elsewhere than the default world, on purpose


def same_items(a: tuple[MissionItem, ...], b: tuple[MissionItem, ...]) -> bool:
    return len(a) == len(b) and all(x.same_as(y) for x, y in zip(a, b, strict=True))


def yaml_data(path) -> dict:
    """A YAML file's mapping without what the model does not keep (its name)."""
    data = yaml.safe_load(path.read_text())
    data.pop("name", None)
    return data


def varied_items(rng: random.Random) -> tuple[MissionItem, ...]:
    """Items in every frame the vehicle accepts, NaN yaws, float32-like parameters."""
    lat0, lon0 = round(HOME.lat_deg * 1e7), round(HOME.lon_deg * 1e7)
    items = [MissionItem(NAV_TAKEOFF, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, z=2.5, param4=30.0)]
    for frame in (0, 3, 5, 6, 10):
        items.append(
            MissionItem(
                NAV_WAYPOINT,
                frame,
                param1=rng.choice([0.0, 1.5, float(rng.random())]),
                param2=float(rng.random() * 3),
                param4=rng.choice([math.nan, -179.25, float(rng.uniform(-180, 180))]),
                x=lat0 + rng.randint(-900, 900),
                y=lon0 + rng.randint(-900, 900),
                z=HOME.alt_m + 3.0 if frame in (0, 5) else float(rng.uniform(0.05, 3)),
                autocontinue=rng.choice([0, 1]),
            )
        )
    items.append(dataclasses.replace(speed_item(0.75), param4=0.0))
    items.append(MissionItem(NAV_RETURN_TO_LAUNCH, mav.MAV_FRAME_MISSION))
    return tuple(items)


# --- YAML -----------------------------------------------------------------------------------


@pytest.mark.parametrize("name", OLD_EXAMPLES)
def test_the_old_yaml_examples_read_as_they_always_did(name):
    path = EXAMPLES / f"{name}.yaml"
    doc = load_mission_file(path)
    old = yaml.safe_load(path.read_text())
    assert doc.home == default_home()
    takeoff, *waypoints, land = doc.items
    assert takeoff.same_as(MissionItem(NAV_TAKEOFF, z=old["takeoff_altitude_m"]))  # where it stands
    assert len(waypoints) == len(old["waypoints"]) and old["land"] and land.command == NAV_LAND
    for item, wp in zip(waypoints, old["waypoints"], strict=True):
        assert item.command == NAV_WAYPOINT and item.frame == mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
        offset = local_offset(item, doc.home)
        assert math.dist(offset, wp["position_m"]) < 0.006  # the degE7 grid: about 1 cm
        assert item.z == wp["position_m"][2]  # altitudes are exact
        assert item.param1 == wp.get("hold_s", 0.0)
        assert item.param2 == wp.get("acceptance_radius_m", 0.05)
        assert math.isnan(item.param4)  # no yaw given: the vehicle's choice
    assert (land.x, land.y, land.z) == (waypoints[-1].x, waypoints[-1].y, 0.0)
    timeouts = [wp["timeout_s"] for wp in old["waypoints"] if wp.get("timeout_s") is not None]
    assert doc.waypoint_timeout_s == (max(timeouts) if timeouts else None)


def test_yaml_speed_return_home_and_yaw(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text(
        "home: {lat_deg: 47.3977419, lon_deg: 8.5455938, alt_m: 488.0}\n"
        "takeoff_altitude_m: 2.0\n"
        "waypoints:\n"
        "  - {position_m: [3.0, 4.0, 2.0], speed_m_s: 1.5, yaw_deg: 0.0}\n"  # east
        "  - {position_m: [0.0, 0.0, 2.0], yaw_deg: 90.0, timeout_s: 5.0}\n"  # north
        "  - {position_m: [0.0, 0.0, 1.0], yaw_deg: -90.0, timeout_s: 9.0}\n"  # south
        "return: true\n"
    )
    doc = load_mission_file(path)
    assert doc.home == HOME and doc.waypoint_timeout_s == 9.0
    commands = [item.command for item in doc.items]
    assert commands == [NAV_TAKEOFF, DO_CHANGE_SPEED, *[NAV_WAYPOINT] * 3, NAV_RETURN_TO_LAUNCH]
    assert doc.items[1] == speed_item(1.5)  # before the waypoint it belongs to
    assert [item.param4 for item in doc.items[2:5]] == [90.0, 0.0, 180.0]  # clockwise from north
    east, north, _ = local_offset(doc.items[2], HOME)
    assert east == pytest.approx(3.0, abs=0.006) and north == pytest.approx(4.0, abs=0.006)
    assert doc.items[2] == item_at(NAV_WAYPOINT, HOME, (3.0, 4.0, 2.0), 0.0, 0.05, 90.0)


def test_yaml_home_defaults_to_the_origin_given(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("waypoints:\n  - {position_m: [1.0, 0.0, 1.0]}\n")
    assert load_mission_file(path).home == default_home()
    assert load_mission_file(path, origin=HOME).home == HOME
    expected = item_at(NAV_WAYPOINT, HOME, (1.0, 0.0, 1.0), 0.0, 0.05)
    assert load_mission_file(path, origin=HOME).items[1].same_as(expected)


@pytest.mark.parametrize("name", [*OLD_EXAMPLES, "square"])
def test_yaml_to_plan_to_yaml_gives_the_same_file(tmp_path, name):
    source = EXAMPLES / f"{name}.yaml"
    save_mission_file(load_mission_file(source), tmp_path / "m.plan")
    save_mission_file(load_mission_file(tmp_path / "m.plan"), tmp_path / "m.yaml")
    assert yaml_data(tmp_path / "m.yaml") == yaml_data(source)  # 0.5 comes back as 0.5


def test_items_to_yaml_to_items_are_identical(tmp_path):
    """Positions on the degE7 grid (any MISSION_ITEM_INT's) and any float survive YAML."""
    rng = random.Random(1)
    lat0, lon0 = round(HOME.lat_deg * 1e7), round(HOME.lon_deg * 1e7)
    for trial in range(20):
        items = [MissionItem(NAV_TAKEOFF, z=round(rng.uniform(0.1, 5), 3))]
        for _ in range(rng.randint(1, 6)):
            if rng.random() < 0.3:
                items.append(speed_item(float(rng.choice([0.5, 2.0, rng.uniform(0.1, 20)]))))
            items.append(
                MissionItem(
                    NAV_WAYPOINT,
                    param1=float(rng.choice([0.0, 0.5, rng.uniform(0, 60)])),
                    param2=float(rng.choice([0.05, 0.0, rng.uniform(0, 5)])),
                    param4=rng.choice([math.nan, 0.0, 180.0, -90.0, rng.uniform(-180, 180)]),
                    x=lat0 + rng.randint(-9000, 9000),  # within 100 m
                    y=lon0 + rng.randint(-9000, 9000),
                    z=float(rng.choice([1.0, 0.03, rng.uniform(-5, 50)])),
                )
            )
        last = items[-1]
        if trial % 3 == 0:
            items.append(MissionItem(NAV_LAND, x=last.x, y=last.y))
        elif trial % 3 == 1:
            items.append(MissionItem(NAV_RETURN_TO_LAUNCH, frame=mav.MAV_FRAME_MISSION))
        doc = MissionDoc(tuple(items), HOME, rng.choice([None, 8.0]))
        save_mission_file(doc, tmp_path / "m.yaml")
        back = load_mission_file(tmp_path / "m.yaml")
        assert back.home == HOME and back.waypoint_timeout_s == doc.waypoint_timeout_s
        for want, got in zip(doc.items, back.items, strict=True):
            assert dataclasses.replace(got, param4=want.param4).same_as(want), (want, got)
            assert got.param4 == pytest.approx(want.param4, abs=1e-9, nan_ok=True)


def test_yaml_writes_what_it_cannot_hold_as_an_error_naming_item_and_field(tmp_path):
    takeoff_elsewhere = MissionItem(NAV_TAKEOFF, x=round(HOME.lat_deg * 1e7) + 100, y=0, z=1.0)
    wp = item_at(NAV_WAYPOINT, HOME, (1.0, 0.0, 1.0))
    for items, expected in [
        ((takeoff_elsewhere, wp), "item 0 (NAV_TAKEOFF): x: YAML cannot hold"),
        ((MissionItem(NAV_TAKEOFF, z=1.0), wp, dataclasses.replace(wp, param3=2.0)), "param3"),
        ((wp,), "item 0 (NAV_WAYPOINT): a YAML mission begins with NAV_TAKEOFF"),
        ((MissionItem(NAV_TAKEOFF, z=1.0), wp, MissionItem(NAV_LAND), wp), "item 3"),
    ]:
        with pytest.raises(ConfigError) as err:
            save_mission_file(MissionDoc(items, HOME), tmp_path / "m.yaml")
        assert str(err.value).startswith(f"{tmp_path / 'm.yaml'}: ") and expected in str(err.value)
        assert ".plan or .waypoints" in str(err.value)


def test_yaml_form_keeps_the_meaning_of_frames_and_home(tmp_path):
    lat0, lon0 = round(HOME.lat_deg * 1e7), round(HOME.lon_deg * 1e7)
    items = (
        MissionItem(NAV_TAKEOFF, mav.MAV_FRAME_GLOBAL, param1=15.0, x=lat0, y=lon0, z=490.5),
        MissionItem(NAV_WAYPOINT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, x=lat0 + 90, y=lon0, z=2.0),
        MissionItem(NAV_LAND, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT),  # where it is: below the last
    )
    doc = MissionDoc(items, HOME)
    save_mission_file(doc, tmp_path / "m.yaml")
    back = load_mission_file(tmp_path / "m.yaml")
    assert same_items(back.items, yaml_form(items, HOME))
    takeoff, wp, land = back.items
    assert (takeoff.x, takeoff.y, takeoff.z, takeoff.param1) == (0, 0, 2.5, 0.0)
    assert wp.frame == mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT and (wp.x, wp.z) == (lat0 + 90, 2.0)
    assert (land.x, land.y) == (wp.x, wp.y)


# --- QGroundControl .plan and QGC WPL 110 --------------------------------------------------


def test_plan_round_trip_loses_nothing(tmp_path):
    doc = MissionDoc(varied_items(random.Random(2)), HOME, 7.5)
    save_mission_file(doc, tmp_path / "m.plan")
    back = load_mission_file(tmp_path / "m.plan")
    assert same_items(back.items, doc.items) and back.home == HOME
    assert back.waypoint_timeout_s == 7.5
    plan = json.loads((tmp_path / "m.plan").read_text())
    assert plan["fileType"] == "Plan" and plan["version"] == 1
    mission = plan["mission"]
    assert (mission["version"], mission["firmwareType"], mission["vehicleType"]) == (2, 12, 2)
    assert mission["plannedHomePosition"] == [HOME.lat_deg, HOME.lon_deg, HOME.alt_m]
    assert plan["geoFence"]["polygons"] == [] and plan["rallyPoints"]["points"] == []
    first, waypoint = mission["items"][0], mission["items"][1]
    assert first["params"][3] == 30.0 and first["AltitudeMode"] == 1
    assert waypoint["frame"] == 0 and waypoint["AltitudeMode"] == 2  # above mean sea level
    assert all(len(i["params"]) == 7 and i["type"] == "SimpleItem" for i in mission["items"])
    assert [i["doJumpId"] for i in mission["items"]] == list(range(1, len(doc.items) + 1))
    speed = mission["items"][-2]
    assert speed["params"][:3] == [1.0, 0.75, -1.0] and "Altitude" not in speed
    assert "NaN" not in (tmp_path / "m.plan").read_text()  # NaN travels as null


def test_wpl_round_trip_loses_nothing_but_the_timeout(tmp_path):
    doc = MissionDoc(varied_items(random.Random(3)), HOME, 7.5)
    save_mission_file(doc, tmp_path / "m.waypoints")
    back = load_mission_file(tmp_path / "m.waypoints")
    assert same_items(back.items, doc.items) and back.home == HOME
    assert back.waypoint_timeout_s is None  # no place for it in the file
    lines = (tmp_path / "m.waypoints").read_text().splitlines()
    assert lines[0] == "QGC WPL 110" and len(lines) == len(doc.items) + 2
    assert all(len(line.split("\t")) == 12 for line in lines[1:])
    home_row = lines[1].split("\t")
    assert home_row[:4] == ["0", "1", "0", "16"] and float(home_row[10]) == HOME.alt_m
    assert [line.split("\t")[0] for line in lines[1:]] == [str(i) for i in range(len(lines) - 1)]


def test_degrees_survive_rounding_and_truncating_readers():
    """MAVProxy turns degrees into degE7 with int(), QGroundControl and MAVSDK round."""
    rng = random.Random(4)
    values = [rng.randint(-1_800_000_000, 1_800_000_000) for _ in range(5000)]
    for x in [1, -1, 593498000, -1_800_000_000, *values]:
        text = f"{dege7_to_deg(x):.8f}"
        assert float(text) == dege7_to_deg(x)  # 8 decimals say it all
        assert round(float(text) * 1e7) == x and int(float(text) * 1e7) == x


def test_mavproxy_loads_the_example_waypoints_as_the_plan_says():
    loader = mavwp.MAVWPLoader()
    loader.load(str(EXAMPLES / "square.waypoints"))
    plan = load_mission_file(EXAMPLES / "square.plan")
    assert loader.count() == len(plan.items) + 1  # row 0: home
    home = loader.wp(0)
    assert (home.x, home.y, home.z) == (plan.home.lat_deg, plan.home.lon_deg, plan.home.alt_m)
    for seq, item in enumerate(plan.items, start=1):
        wp = loader.wp(seq)
        assert (wp.command, wp.frame, wp.autocontinue) == (item.command, item.frame, 1)
        if item.command != DO_CHANGE_SPEED:  # MAVProxy's wp_to_mission_item_int, degrees to degE7
            assert (int(wp.x * 1.0e7), int(wp.y * 1.0e7)) == (item.x, item.y)
        params = (wp.param1, wp.param2, wp.param3, wp.param4, wp.z)
        expected = (item.param1, item.param2, item.param3, item.param4, item.z)
        assert params == pytest.approx(expected, nan_ok=True)


def test_reads_a_qgroundcontrol_plan():
    doc = load_mission_file(EXAMPLES / "square.plan")
    assert doc.home == Home(59.3498, 18.0707, 28.0) and doc.waypoint_timeout_s is None
    names = [item.name for item in doc.items]
    assert names == ["NAV_TAKEOFF", "DO_CHANGE_SPEED", "NAV_WAYPOINT", "NAV_WAYPOINT",
                     "DO_CHANGE_SPEED", "NAV_WAYPOINT", "NAV_WAYPOINT", "NAV_LAND"]  # fmt: skip
    assert [i.param2 for i in doc.items if i.command == DO_CHANGE_SPEED] == [0.5, 1.0]
    corners = [local_offset(i, doc.home) for i in doc.items if i.command == NAV_WAYPOINT]
    for corner, expected in zip(corners, [(1, 0, 1), (1, 1, 1), (0, 1, 1), (0, 0, 1)], strict=True):
        assert math.dist(corner, expected) < 0.006
        assert all(abs(c) <= 1.0 + 0.006 for c in corner)  # within 1 m of home
    takeoff, land = doc.items[0], doc.items[-1]
    assert local_offset(takeoff, doc.home) == pytest.approx((0, 0, 1), abs=1e-6)  # QGC: at home
    assert local_offset(land, doc.home) == pytest.approx((0, 0, 0), abs=1e-6)
    first = doc.items[2]
    assert math.isnan(first.param4) and first.frame == mav.MAV_FRAME_GLOBAL_RELATIVE_ALT


def test_the_square_examples_are_one_mission():
    plan = load_mission_file(EXAMPLES / "square.plan")
    wpl = load_mission_file(EXAMPLES / "square.waypoints")
    yml = load_mission_file(EXAMPLES / "square.yaml")
    assert same_items(wpl.items, plan.items) and wpl.home == plan.home == yml.home
    assert same_items(yaml_form(plan.items, plan.home), yml.items)


# --- errors -----------------------------------------------------------------------------------


def write_plan(tmp_path, edit) -> str:
    plan = json.loads((EXAMPLES / "square.plan").read_text())
    edit(plan["mission"]["items"])
    path = tmp_path / "bad.plan"
    path.write_text(json.dumps(plan))
    return str(path)


def error_of(path, **kwargs) -> str:
    with pytest.raises(ConfigError) as err:
        load_mission_file(path, **kwargs)
    return str(err.value)


def test_unknown_command_names_the_item_and_the_commands_flown(tmp_path):
    path = write_plan(tmp_path, lambda items: items[2].update(command=999))
    message = error_of(path)
    assert message.startswith(f"{path}: mission.items[2].command: item 2 (command 999): command:")
    assert "unsupported" in message and "NAV_WAYPOINT" in message and "DO_CHANGE_SPEED" in message


def test_local_ned_frame_names_the_line_column_and_allowed_frames(tmp_path):
    lines = (EXAMPLES / "square.waypoints").read_text().splitlines()
    row = lines[4].split("\t")
    row[2] = "1"  # MAV_FRAME_LOCAL_NED
    lines[4] = "\t".join(row)
    path = tmp_path / "bad.waypoints"
    path.write_text("\n".join(lines) + "\n")
    message = error_of(path)
    assert message.startswith(f"{path}: line 5, column 3 (FRAME): item 2 (NAV_WAYPOINT): frame: 1")
    assert "[0, 3, 5, 6, 10]" in message and "GLOBAL_RELATIVE_ALT" in message


def test_nan_altitude_is_refused_in_every_format(tmp_path):
    path = write_plan(tmp_path, lambda items: items[3]["params"].__setitem__(6, None))
    message = error_of(path)
    assert message.startswith(f"{path}: mission.items[3].params[6]: item 3 (NAV_WAYPOINT): z:")
    assert "nan is not a finite number" in message
    yaml_path = tmp_path / "bad.yaml"
    yaml_path.write_text("waypoints:\n  - {position_m: [0.0, 0.0, .nan]}\n")
    assert "waypoints[0].position_m[2]: nan is outside the allowed range" in error_of(yaml_path)


def test_outside_the_geofence_names_the_item_and_the_limit():
    fence = Geofence(max_altitude_m=0.0, max_radius_m=1.2)
    message = error_of(EXAMPLES / "square.yaml", fence=fence)
    assert "square.yaml: waypoints[1]: item 3 (NAV_WAYPOINT): x: outside the geofence" in message
    assert "beyond the maximum radius 1.2 m" in message
    message = error_of(EXAMPLES / "square.plan", fence=Geofence(max_altitude_m=0.5))
    assert "mission.items[0].params[6]: item 0 (NAV_TAKEOFF): z: outside the geofence" in message


def test_file_errors_are_one_line(tmp_path):
    missing = tmp_path / "none.plan"
    assert error_of(missing) == f"{missing}: cannot read (No such file or directory)"
    bad_json = tmp_path / "bad.plan"
    bad_json.write_text('{"fileType": "Plan",\n "version": 1,,}')
    assert error_of(bad_json).startswith(f"{bad_json}: not valid JSON at line 2, column")
    survey = write_plan(
        tmp_path, lambda items: items.append({"type": "ComplexItem", "complexItemType": "survey"})
    )
    assert "mission.items[8]: a ComplexItem (survey) is not supported" in error_of(survey)
    short = tmp_path / "short.waypoints"
    short.write_text("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t59.3\t18.0\t28\n")
    assert "line 2: expected 12 tab-separated fields" in error_of(short)
    binary = tmp_path / "m.yaml"
    binary.write_bytes(b"\xff\xfe\x00")
    assert "not a text file" in error_of(binary)
    both = tmp_path / "both.yaml"
    both.write_text("waypoints:\n  - {position_m: [0.0, 0.0, 1.0]}\nland: true\nreturn: true\n")
    assert "land and return: choose one" in error_of(both)
    unknown = tmp_path / "m.kml"
    unknown.write_text("<kml/>")
    assert "unknown mission format" in error_of(unknown)


# --- the command line ---------------------------------------------------------------------


def test_cli_converts_yaml_to_plan_to_wpl_to_yaml(tmp_path):
    steps = [EXAMPLES / "square.yaml", tmp_path / "s.plan", tmp_path / "s.waypoints",
             tmp_path / "s.yaml"]  # fmt: skip
    for source, target in itertools.pairwise(steps):
        result = run_groundfx("mission", "convert", str(source), str(target))
        assert result.returncode == 0, result.stderr
        assert f"wrote {target}" in result.stdout
    assert yaml_data(tmp_path / "s.yaml") == yaml_data(EXAMPLES / "square.yaml")
    assert same_items(load_mission_file(tmp_path / "s.waypoints").items,
                      load_mission_file(EXAMPLES / "square.yaml").items)  # fmt: skip


def test_cli_check_prints_one_line_per_item():
    result = run_groundfx("mission", "check", str(EXAMPLES / "square.plan"))
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    rows = [line.split() for line in lines if line[:4].strip().isdigit()]
    assert [r[0] for r in rows] == [str(i) for i in range(8)]
    assert [r[1] for r in rows][:3] == ["NAV_TAKEOFF", "DO_CHANGE_SPEED", "NAV_WAYPOINT"]
    first = next(line for line in lines if line.startswith("   2 NAV_WAYPOINT"))
    assert "east 1.00 north 0.00 m up 1.000 m, hold 0.5 s, radius 0.1 m, yaw free" in first
    assert "ok: 8 items the vehicle accepts" in lines


def test_cli_bad_files_exit_2_with_one_clear_line(tmp_path):
    bad = tmp_path / "bad.plan"
    bad.write_text("{not json")
    result = run_groundfx("mission", "convert", str(bad), str(tmp_path / "out.yaml"))
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert f"groundfx mission: error: {bad}: not valid JSON at line 1" in result.stderr
    assert not (tmp_path / "out.yaml").exists()
    result = run_groundfx("mission", "check", str(EXAMPLES / "square.yaml"), "--max-radius", "1")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "item 3 (NAV_WAYPOINT): x: outside the geofence" in result.stderr
    result = run_groundfx("mission", "convert", str(EXAMPLES / "square.yaml"), "out.kml")
    assert result.returncode == 2 and "unknown mission format '.kml'" in result.stderr
