"""Flight recordings: written by the autopilot, read back with
`learner.flightlogs.recording`, reviewed."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from autopilot.commander.mission_items import Home, plan_steps
from autopilot.recording.flight_recorder import FlightRecorder
from autopilot.recording.record_options import RecordOptions
from autopilot.recording.scene import LABEL_LIFT_M
from autopilot.summary import MODES
from learner.flightlogs.blueprint_reader import read_views
from learner.flightlogs.recording import (
    ENTITY_PATHS,
    FLIGHT_MODE_STATE,
    LEARNER_UPDATES,
    MISSION_LABELS,
    MISSION_PATH,
    MODEL_STATE,
    OBSTACLES,
    PHASE_STATE,
    REVIEW,
    STATES,
    TRAJECTORY,
    WAYPOINTS,
    read_recording,
)
from mission.fly import autopilot_command
from mission.plans.formats import load_mission_file
from mission.recordings import LOGS_ENV
from simbridge.launch import finish, start_sim
from simbridge.vehicle import load_vehicle
from tests.helpers import REPO, recorded_s, run_groundfx, wait_for

EXAMPLES = REPO / "mission" / "examples"


@pytest.fixture(scope="module")
def flown(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, np.ndarray]:
    """`groundfx fly` onto the box of the obstacles world, recording to the default place."""
    tmp = tmp_path_factory.mktemp("flown")
    trajectory = tmp / "t.npz"
    result = run_groundfx(
        "fly",
        str(EXAMPLES / "land_on_box.yaml"),
        "--world",
        "obstacles",
        "--trajectory",
        str(trajectory),
        "--json",
    )
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout.strip().splitlines()[-1])
    return summary, np.load(trajectory)["log"]


def test_fly_records_to_the_logs_folder_by_default(flown):
    summary, _ = flown
    path = Path(summary["recording"])
    assert path.parent == Path(os.environ[LOGS_ENV]) and path.suffix == ".rrd"
    assert "land_on_box-analytic" in path.name and path.stat().st_size > 100_000


def test_the_recording_holds_the_trajectory_the_autopilot_flew(flown):
    summary, log = flown
    recording = read_recording(summary["recording"])
    assert recording.complete
    flown_again = recording.trajectory()
    assert flown_again.shape == log.shape == (summary["steps"], 10)
    np.testing.assert_allclose(flown_again[:, 0], log[:, 0], rtol=0, atol=1e-9)
    assert np.array_equal(flown_again[:, 1:], log[:, 1:], equal_nan=True)  # bit for bit
    assert recording.meta["model"] == "analytic" and recording.meta["modes"] == MODES
    # what was flown, though a ground station uploaded the mission: file, network, learning
    meta = recording.meta
    assert meta["mission"].endswith("land_on_box.yaml") and meta["network"] is None
    assert meta["online"] == "off" and meta["groundfx_version"] and meta["parameters"]
    # the flight's summary travels in the file too
    written = json.loads(recording.static("summary", "TextDocument:text"))
    assert written["landed"] and written["steps"] == summary["steps"]
    translation = recording.values("world/drone", "Transform3D:translation")  # 50 Hz, float32
    at = np.searchsorted(log[:, 0], recording.times("world/drone") - 1e-9)
    assert len(at) > summary["sim_s"] * 49
    np.testing.assert_allclose(translation, log[at, 1:4], atol=1e-6)


def test_every_entity_of_the_layout_is_there_with_increasing_times(flown):
    recording = read_recording(flown[0]["recording"])
    paths = set(recording.entity_paths())
    assert set(ENTITY_PATHS) | {OBSTACLES} <= paths
    assert any(p.startswith(TRAJECTORY + "/") for p in paths)
    for path in paths:
        steps = np.diff(recording.times(path))
        assert np.all(steps >= 0 if path == "events" else steps > 0), path
    events = [text for _, _, text in recording.texts()]
    assert events[0] == "mode disarmed (start)" and "armed" in events and "disarmed" in events
    assert events[-1] == "flight ended: landed"
    received, dropped, rejected = recording.scalars("plots/mavlink/sim")[1][-1]
    assert received > 3 * flown[0]["steps"] and dropped == rejected == 0
    # `groundfx fly` flew it through a ground station: its link, upload and progress
    received, dropped, rejected = recording.scalars("plots/mavlink/gcs")[1][-1]
    assert received == flown[0]["gcs"]["received"] > 5 and dropped == rejected == 0
    assert "mission of 4 items" in events and "mission item 2 reached" in events


def test_the_default_blueprint_shows_what_is_recorded(flown):
    import rerun.chunk as rc

    recording = read_recording(flown[0]["recording"])
    reader = rc.RrdReader(flown[0]["recording"])
    views: dict[str, dict[str, list[str]]] = {}
    for chunk in reader.stream(store=reader.blueprints()[0]):
        batch = chunk.to_record_batch()
        for name in ("ViewBlueprint:display_name", "ViewBlueprint:space_origin"):
            if name in batch.schema.names:
                views.setdefault(chunk.entity_path, {})[name] = batch.column(name).to_pylist()[0]
    origins = {
        v["ViewBlueprint:display_name"][0]: v["ViewBlueprint:space_origin"][0]
        for v in views.values()
    }
    assert len(reader.blueprints()) == 1  # the final layout only: the viewer has no choice
    assert {
        "the landing (3-D)",
        "near the ground: z - setpoint (mm)",
        "ground-effect model: predicted - true, vertical (mN)",
        "events",
    } <= set(origins)
    for name, origin in origins.items():  # every view looks at something in the recording
        assert any(p == origin or p.startswith(origin + "/") for p in recording.entities), name


def test_true_and_predicted_ground_effect_are_both_recorded(flown):
    recording = read_recording(flown[0]["recording"])
    t_true, true_z = recording.scalars("plots/ground_effect/z/true")
    t_pred, predicted_z = recording.scalars("plots/ground_effect/z/predicted")
    assert len(t_true) > 0.9 * len(t_pred) > 1000
    _, mode = recording.scalars("plots/mode")
    holding = np.flatnonzero(mode[:, 0] == MODES.index("holding"))
    low = t_pred[holding[-1]]  # the end of the hold 3 cm above the box
    # its last 2 s: the prediction is made at the estimated height, and at 3 cm a millimetre
    # of the estimator's error is 7% of the force (the error is slow: averaged, it is ~0.3 mm)
    true_mean = true_z[(t_true > low - 2.0) & (t_true <= low), 0].mean()
    predicted_mean = predicted_z[(t_pred > low - 2.0) & (t_pred <= low), 0].mean()
    assert true_mean > 0.05  # the box's ground effect, in newtons
    assert predicted_mean == pytest.approx(true_mean, rel=0.05)  # the analytic expert
    arrows = recording.values("world/ground_effect/true", "Arrows3D:vectors")
    assert arrows[:, 2].max() > 0.05


def test_the_estimators_error_against_the_truth_and_its_test_ratios_are_recorded(flown):
    """The summary's RMS figures come from the same errors the recording holds."""
    summary, _ = flown
    recording = read_recording(summary["recording"])
    t, position = recording.scalars("plots/estimator/position_error_m")
    _, attitude = recording.scalars("plots/estimator/attitude_error_deg")
    assert len(t) > 1000 and np.all(np.diff(t) > 0)
    assert np.median(position[:, 0]) < 0.005  # motion capture: millimetres
    assert np.max(attitude[:, 0]) < 2.0
    assert summary["est_position_rms_m"] < 0.005
    _, ratio = recording.scalars("plots/estimator/test_ratio/motion_capture")
    assert len(ratio) > 100 and np.all(ratio[:, 0] < 1.0)  # nothing rejected in a calm flight


def test_a_recording_cut_in_the_middle_of_a_message_reads_up_to_the_cut(flown, tmp_path):
    whole = Path(flown[0]["recording"]).read_bytes()
    cut = tmp_path / "cut.rrd"
    cut.write_bytes(whole[: len(whole) * 2 // 3 + 7])  # no footer, half a message at the end
    recording = read_recording(cut)
    assert not recording.complete
    # what it holds is the flight as flown, as far as it goes (the finished file is written
    # in one chunk per entity: the cut may fall after all the trajectory's rows)
    got = recording.trajectory()
    assert 0 < len(got) <= flown[0]["steps"]
    assert np.array_equal(got[:, 1:], flown[1][: len(got), 1:], equal_nan=True)


def test_a_killed_autopilot_leaves_a_recording_up_to_shortly_before_the_kill(tmp_path):
    sim, port = start_sim("default", speedup="1")
    path = tmp_path / "killed.rrd"
    autopilot = subprocess.Popen(
        autopilot_command(port, EXAMPLES / "hover.yaml", "--record", str(path)),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    try:
        wait_for(lambda: recorded_s(path) >= 1.5, "1.5 s of flight recorded", autopilot)
        autopilot.send_signal(signal.SIGKILL)
        autopilot.communicate(timeout=10)
        line = finish(sim)  # the simulator's account: how far the flight got
    finally:
        if sim.poll() is None:
            sim.kill()
            sim.communicate(timeout=10)
    flown_s = float(re.search(r"([0-9.]+) s simulated", line).group(1))
    recording = read_recording(path)
    assert not recording.complete
    t = recording.trajectory()[:, 0]
    assert flown_s > 1.0 and np.all(np.diff(t) > 0)
    # flushed every 0.5 wall seconds in a real-time flight
    assert flown_s - 1.0 < t[-1] <= flown_s
    assert "flight ended" not in " ".join(text for _, _, text in recording.texts())


def test_the_recorder_takes_learner_reports_and_events_from_the_loop(tmp_path):
    from autopilot.types import FlightState, Setpoint, Step

    home = Home(59.0, 18.0, 0.0)
    plan = plan_steps(load_mission_file(EXAMPLES / "square.yaml", home).items, home, 0.0)
    path = tmp_path / "unit.rrd"
    info = {"model": "neural", "online": "rls"}
    recorder = FlightRecorder(RecordOptions(path, info=info), load_vehicle(), MODES)
    recorder.mission(plan, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0)
    recorder.watch_counters("gcs", lambda: (7, 1, 2))
    msgs = Step({"time_usec": 0}, {}, set())
    for k in range(600):
        t = k * 0.004
        state = FlightState((0.0, 0.0, t), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        mode = "flying" if k >= 300 else "holding"
        speeds = (70.0, 70.0, 70.0, 70.0)
        recorder.step(t, msgs, state, t, mode, True, Setpoint((0, 0, 1)), (0, 0, 0), speeds, None)
        if k == 400:  # an update the guards turned down: the weights stay at version 0
            recorder.learner(t, loss=0.5, version=0, note="rejected: holdout RMSE rose 40%")
        if k == 500:
            recorder.learner(t, loss=0.25, version=1, note="accepted")
            recorder.event("failsafe: link lost", "WARN")
    recorder.close("landed")
    recording = read_recording(path)
    t_version, version = recording.scalars("plots/learner/version")
    assert version[:, 0].tolist() == [0.0, 0.0, 1.0] and t_version[2] == pytest.approx(2.0)
    assert recording.scalars("plots/learner/loss")[1][:, 0].tolist() == [0.5, 0.25]
    assert recording.scalars("plots/learner/log10_loss")[1][:, 0] == pytest.approx(
        [-0.30103, -0.60206]
    )
    # each update's fate with its reason; the model in use as a named state, as it changes
    updates = recording.texts(LEARNER_UPDATES)
    assert [(level, text) for _, level, text in updates] == [
        ("WARN", "rejected: holdout RMSE rose 40% (loss 0.5, weights v0)"),
        ("INFO", "accepted (loss 0.25, weights v1)"),
    ]
    models = [str(s) for s in recording.values(MODEL_STATE, "StateChange:state")]
    assert models == ["neural, offline weights", "neural, adapted online"]
    assert recording.times(MODEL_STATE)[-1] == pytest.approx(2.0)
    assert (pytest.approx(2.0), "WARN", "failsafe: link lost") in recording.texts()
    assert recording.scalars("plots/mavlink/gcs")[1][-1].tolist() == [7.0, 1.0, 2.0]
    assert len(recording.times("plots/rotors/actual")) == 0  # no ESC telemetry came
    _, mode = recording.scalars("plots/mode")
    assert mode[0, 0] == MODES.index("holding") and mode[-1, 0] == MODES.index("flying")
    drawn = recording.values(WAYPOINTS, "Points3D:positions")[-1].reshape(-1, 3)
    corners = [s.position_m for s in plan if s.kind == "waypoint"]
    # every corner drawn (items at one place share one point and one label)
    gaps = [np.min(np.abs(drawn - np.asarray(c)).max(axis=1)) for c in corners]
    assert max(gaps) < 1e-5 and len(drawn) <= len(plan)
    # their labels above them, where they do not cover a vehicle standing on a point
    labelled = recording.values(MISSION_LABELS, "Points3D:positions")[-1].reshape(-1, 3)
    lift = labelled - drawn
    assert np.allclose(lift[:, :2], 0.0) and np.all(lift[:, 2] >= LABEL_LIFT_M)
    assert len(recording.values(MISSION_PATH, "LineStrips3D:strips")) > 0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _serve_web(recording: str, web: int, data: int) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    command = [sys.executable, "-m", "mission.cli", "review", recording, "--web"]
    return subprocess.Popen(
        [*command, "--web-port", str(web), "--data-port", str(data)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=REPO,
    )


def _wait_for_page(web: int, review: subprocess.Popen, timeout_s: float = 30.0) -> str:
    page, deadline = "", time.monotonic() + timeout_s
    while time.monotonic() < deadline and review.poll() is None:
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{web}/", timeout=2) as response:
                return response.read().decode("utf-8", "replace")
        except OSError:
            time.sleep(0.2)
    assert review.poll() is None, review.communicate()
    return page


def _viewer_address(review: subprocess.Popen) -> str:
    """The address `groundfx review --web` prints for a browser to open."""
    assert review.stdout is not None
    for line in review.stdout:
        if "web viewer at " in line:
            return line.split("web viewer at ", 1)[1].split()[0]
    raise AssertionError(f"no address printed: {review.communicate()}")


def _stop_review(review: subprocess.Popen) -> str:
    review.send_signal(signal.SIGINT)  # Ctrl-C: the viewer's server ignores SIGTERM
    try:
        out, _ = review.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        review.kill()
        out, _ = review.communicate()
    return out


def test_review_web_serves_the_viewer_on_a_headless_machine(flown):
    web, data = _free_port(), _free_port()
    review = _serve_web(flown[0]["recording"], web, data)
    try:
        page = _wait_for_page(web, review)
        assert review.poll() is None, review.communicate()
        assert "<html" in page.lower()
    finally:
        out = _stop_review(review)
    assert "groundfx review:" in out and f"127.0.0.1:{web}" in out


def test_the_trail_is_drawn_in_segments_that_join_up():
    from autopilot.recording.trail import Trail

    trail = Trail(spacing_m=0.01, period_s=0.25, segment_s=10.0)
    t = np.arange(0, 25.0, 0.004)
    p = np.column_stack((0.05 * t, np.sin(t), np.zeros_like(t)))  # 25 s of flight
    last: dict[int, np.ndarray] = {}
    last_t = 0.0
    for i in range(0, len(t), 500):  # flushes of 2 s
        for segment, (times, strips) in trail.update(t[i : i + 500], p[i : i + 500]).items():
            assert np.all(np.diff(times) > 0) and all(s.shape[1] == 3 for s in strips)
            last[segment], last_t = strips[-1], times[-1]
    assert sorted(last) == [0, 1, 2] and last_t == pytest.approx(24.75, abs=0.005)
    np.testing.assert_allclose(last[0][0], p[0])  # from the start
    np.testing.assert_allclose(last[2][-1], p[t <= last_t][-1])  # to the drone
    for k in (0, 1):  # each segment's final drawing ends where the next one begins
        np.testing.assert_allclose(last[k][-1], last[k + 1][0], atol=0.011)
    drawn = sum(np.linalg.norm(np.diff(s, axis=0), axis=1).sum() for s in last.values())
    flown = np.linalg.norm(np.diff(p[t <= last_t], axis=0), axis=1).sum()
    assert drawn == pytest.approx(flown, rel=1e-3)


def _view_entities(view, paths: list[str]) -> list[str]:
    if view.query == ("$origin/**",):
        return [p for p in paths if p == view.origin or p.startswith(view.origin + "/")]
    return [p for p in view.query if p in paths]


def test_the_layout_shows_data_in_every_view_and_tells_its_series_apart(flown):
    """The viewer's layout as the recording carries it: every view has data, no two series
    in one view share a name or a colour, and the z view's range holds the flight (a
    setpoint running away below the ground would stay outside it)."""
    summary, log = flown
    recording = read_recording(summary["recording"])
    views = read_views(summary["recording"])
    paths = recording.entity_paths()
    assert {"the landing (3-D)", "events", "z and its setpoint (m)", "n0 cmd-ESC"} <= {
        v.name for v in views
    }
    assert not any(v.origin.startswith("plots/learner") for v in views)  # nothing learnt
    for view in views:
        shown = [p for p in _view_entities(view, paths) if recording.entities[p].chunks]
        assert shown, f"the view {view.name!r} has no data"
        if view.kind != "TimeSeries":
            continue
        names, colors = [], []
        for p in shown:
            names += np.atleast_1d(recording.static(p, "SeriesLines:names")).tolist()
            colors += np.atleast_1d(recording.static(p, "SeriesLines:colors")).tolist()
        assert len(set(names)) == len(names), f"{view.name}: {names}"
        assert len(set(colors)) == len(colors), f"{view.name}: {colors}"
    # flight mode, phase and model as named states, in the order the flight went through them
    states = next(v for v in views if v.kind == "StateTimeline")
    assert states.origin == STATES
    phases = [str(s) for s in recording.values(PHASE_STATE, "StateChange:state")]
    assert phases[0] == "disarmed" and phases[-2:] == ["landing", "landed"]
    assert "mission" in [str(s) for s in recording.values(FLIGHT_MODE_STATE, "StateChange:state")]
    assert [str(s) for s in recording.values(MODEL_STATE, "StateChange:state")] == ["analytic"]
    z_view = next(v for v in views if v.name.startswith("z and"))
    low, high = z_view.y_range
    assert -0.2 < low <= log[:, 3].min() and log[:, 3].max() <= high < 2.0
    # the landing in words, as the flight's summary has it
    review = recording.static(REVIEW, "TextDocument:text")
    error_mm = summary["landing_error_m"] * 1e3
    assert f"landed {error_mm:.1f} mm from the landing point" in review
    assert f"at {summary['touchdown_speed_m_s']:.2f} m/s" in review


def _view_series(recording, view, paths):
    """The series a time-series view draws: (path, column) -> (times, values)."""
    out = {}
    for p in _view_entities(view, paths):
        if p in recording.entities and len(recording.times(p, "Scalars:scalars")):
            t, values = recording.scalars(p)
            out.update({(p, i): (t, values[:, i]) for i in range(values.shape[1])})
    return out


def test_the_review_views_read_at_a_glance(flown):
    """At the view height viewer_checks assumes (250 px): every value axis labels at least
    three ticks over what it shows, and no two series of a view lie within a few pixels of
    each other for most of the flight unless the layout shows their difference."""
    from learner.flightlogs.recording import DIFFERENCES
    from tests.viewer_checks import labelled_ticks, share_on_top, shown_range

    recording = read_recording(flown[0]["recording"])
    views = [v for v in read_views(flown[0]["recording"]) if v.kind == "TimeSeries"]
    paths = recording.entity_paths()
    shown = {p for v in views for p in _view_entities(v, paths)}
    told_apart = {frozenset(pair) for d, pair in DIFFERENCES.items() if d in shown}
    for path in ("plots/height_error_mm", "plots/model_error_mn"):  # in millimetres, millinewtons
        view = next(v for v in views if v.origin == path)
        assert view.y_range is not None and len(labelled_ticks(*view.y_range)) >= 3, view
    for view in views:
        series = _view_series(recording, view, paths)
        y_range = shown_range([v for _, v in series.values()], view.y_range)
        ticks = labelled_ticks(*y_range)
        assert len(ticks) >= 3, f"{view.name}: {y_range} labels only {ticks}"
        keys = sorted(series)
        for i, a in enumerate(keys):
            for b in keys[i + 1 :]:
                together = share_on_top(series[a], series[b], y_range)
                if together > 0.5:
                    assert frozenset((a, b)) in told_apart, f"{view.name}: {a} on {b}"
    # the hold is read to the millimetre: a tick a millimetre apart or finer
    hold = next(v for v in views if v.origin == "plots/height_error_mm")
    ticks = labelled_ticks(*hold.y_range)
    assert ticks[1] - ticks[0] <= 1.0 + 1e-9


def test_the_web_viewer_shows_the_hold_and_the_model_error_without_a_click(flown):
    """Debian's Chromium, headless with software WebGL, on `groundfx review REC --web`: once
    the flight has loaded, the height error and the model error are drawn across the upper
    right of the page, one above the other, with no click."""
    from autopilot.recording.series_style import HOLD_COLOR, MODEL_ERROR_COLOR
    from tests.chromium import Chromium, find_chromium
    from tests.viewer_checks import drawn

    binary = find_chromium()
    if binary is None:
        pytest.skip("no Chromium to drive (Debian: apt-get install chromium)")
    web, data = _free_port(), _free_port()
    review = _serve_web(flown[0]["recording"], web, data)
    width, height = 1280, 720  # a small laptop screen: the software renderer draws fewer pixels
    upper_right = (width // 2, 0, width, int(height * 0.6))
    seen: dict[str, dict] = {}

    def both_drawn() -> bool:
        image = np.asarray(browser.screenshot(box=upper_right))  # the part to look at only
        whole = (0, 0, image.shape[1], image.shape[0])
        seen["hold"] = drawn(image, HOLD_COLOR, whole)
        seen["model"] = drawn(image, MODEL_ERROR_COLOR, whole)
        # across the page's right half: the flight's whole time span (the hold's line leaves
        # its view during the take-off, a metre off its setpoint)
        return all(s["extent"] > 0.6 for s in seen.values())

    try:
        _wait_for_page(web, review)
        with Chromium(binary, width, height) as browser:
            browser.open(_viewer_address(review))  # as printed
            try:
                # a screenshot a second: each one has the software renderer draw the page
                wait_for(both_drawn, "the hold and the model error drawn", review, 240, 1.0)
            except AssertionError as err:
                raise AssertionError(f"{err}; last seen: {seen}") from None
    finally:
        _stop_review(review)
    assert seen["hold"]["row"] < seen["model"]["row"]  # the hold above the model's error
