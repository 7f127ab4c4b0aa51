"""Reviewing recordings without flying one: what is not a recording is refused, another
rerun program's file is read, and the one-page report's answers say what the learner did."""

from __future__ import annotations

import pytest

from learner.flightlogs.recording import TIMELINE, read_recording
from tests.helpers import run_groundfx


def test_review_refuses_what_is_not_a_recording(tmp_path):
    missing = run_groundfx("review", str(tmp_path / "nothing.rrd"))
    assert missing.returncode == 2 and "Traceback" not in missing.stderr
    assert "nothing.rrd: no such file" in missing.stderr
    junk = tmp_path / "junk.rrd"
    junk.write_bytes(b"not a recording at all" * 100)
    refused = run_groundfx("review", str(junk))
    assert refused.returncode == 2 and "Traceback" not in refused.stderr
    assert "junk.rrd: not a rerun recording" in refused.stderr


def test_a_recording_of_another_rerun_program_is_read(tmp_path):
    """Files written by any rerun program carry log_time (nanosecond timestamps) and
    log_tick; they are read, not a traceback."""
    import rerun as rr

    path = tmp_path / "other.rrd"
    rec = rr.RecordingStream("someone_else")
    rec.save(path)
    rec.set_time(TIMELINE, duration=1.5)
    rec.log("door", rr.StateChange(state="open"))
    rec.log("speed", rr.Scalars(2.0))
    rec.flush()
    recording = read_recording(path)
    assert recording.times("speed").tolist() == [1.5]
    assert recording.scalars("speed")[1][:, 0].tolist() == [2.0]


def test_the_report_says_what_the_learner_did_and_why_it_published_little():
    """A composite flight that held most updates back says so on its page; an offline one
    says it did not learn; no answer prints nan."""
    import numpy as np

    from mission.flight_report import Series, answers

    n = 200
    t = np.arange(n) * 0.004
    zeros = np.zeros(0)
    near = np.zeros(n, bool)
    near[100:] = True
    s = Series(t, np.full(n, 0.031), np.full(n, 0.03), np.full(n, 0.031), near, t,
               np.full(n, 0.002), zeros, np.zeros((0, 4)), zeros, zeros, zeros, zeros)  # fmt: skip
    summary = {"landed": True, "ended": "landed", "landing_error_m": 0.0012,
               "touchdown_speed_m_s": 0.08, "model": "neural", "online_method": "composite",
               "online_updates": 123, "online_accepted": 9, "online_rejected": 0,
               "online_held": 114, "online_version": 9, "online_ground": "learnt-1",
               "online_held_evidence": {"median": 0.24, "max": 29.97,
                                        "threshold": 30.0, "over_threshold": 3}}  # fmt: skip
    a = answers(summary, {"online": "composite"}, s)
    assert "123 updates, 9 accepted" in a["learner"]["text"]
    assert (
        "114 held: the evidence for a change under its confidence threshold (likelihood ratio "
        "median 0.24, largest 29.97, against 30), 3 of them over it while the estimate "
        "converged or for a change too small" in a["learner"]["text"]
    )
    assert a["hold"]["rms_mm"] == pytest.approx(1.0) and a["model"]["hold_rms_mn"] == 2.0
    offline = answers({"landed": False, "ended": "stopped"}, {"online": "off"}, s)
    assert (
        offline["learner"]["method"] is None
        and "did not land: stopped" in offline["landing"]["text"]
    )
    texts = " ".join(x["text"] for x in (*a.values(), *offline.values()))
    assert "nan" not in texts and "ESC" in offline["rotors"]["text"]
