"""The gap bench's cases and their scoring, on hand-written diagnosis results (no flight):
out-of-catalogue verdicts read the diagnosis defensively, catalogue cases are held to the
exact set and 10% parameter error, cases of too little data to a refusal."""

from __future__ import annotations

import dataclasses

from mission.campaigns.gap_bench import score, summarise, table
from mission.campaigns.gap_bench_cases import CASES, real_effects
from simbridge.effects import PARAMS_BY_NAME, UNCATALOGUED, parse_effects


def result(**extra) -> dict:
    base = {
        "effects": {"ground_effect": {"status": "absent"}, "rotor_drag": {"status": "absent"}},
        "gap": {"force_rms_n": {"before": 0.01, "after": 0.008, "shrink": 0.2}},
    }
    base.update(extra)
    return base


def test_the_new_cases_are_flown_in_valid_worlds():
    for name in ("far_ground_effect_lag", "three_effects", "ooc_ground_shape",
                 "ooc_thrust_decay", "ooc_weak_rotor", "ooc_outwash",
                 "thrust_curve_a", "thrust_curve_b", "thrust_curve_hover",
                 "ooc_ground_fading_with_speed", "ooc_landing_pad"):  # fmt: skip
        case = CASES[name]
        parse_effects([dict(e) for e in real_effects(case)], name)
        assert case.uncatalogued == name.startswith("ooc_")
        if case.uncatalogued:
            assert case.expected_regime and not case.truth
            assert {e["name"] for e in case.hidden} <= set(UNCATALOGUED)
        else:
            assert all(e in PARAMS_BY_NAME for e in case.truth)
    # the exponential shape replaces the nominal thesis law in the real world
    assert [e["name"] for e in real_effects(CASES["ooc_ground_shape"])] == [
        "ground_effect_exponential"
    ]


def test_an_out_of_catalogue_case_passes_when_located_unnamed_reported_and_learnt():
    case = CASES["ooc_outwash"]
    where = [{"variable": "height_r", "low": 0.5, "high": 1.0, "component": "world_x",
              "mean_share": 0.04}]  # fmt: skip
    learned = {"before": 0.01, "after": 0.003, "shrink": 0.7}
    r = result(unexplained={"share": 0.7, "where": where})
    r["gap"]["force_rms_n_learned"] = learned
    r["effects"]["rotor_drag"] = {"status": "present", "confident": False}
    s = score(case, r)
    v = s["uncatalogued"]
    assert v["passed"] and v["located"] and v["confident_catalogue"] == []
    assert s["exact"] is None and s["false_alarm"] is None
    r["effects"]["rotor_drag"]["confident"] = True
    assert not score(case, r)["uncatalogued"]["passed"]


def test_missing_diagnosis_fields_read_missing_and_do_not_pass():
    v = score(CASES["ooc_thrust_decay"], result())["uncatalogued"]
    assert v["located"] is None and v["unexplained_share"] is None
    assert v["learned_shrink"] is None and not v["passed"]
    trend = {"trend": {"significant": True, "slope_share_per_min": -0.18}}
    v = score(CASES["ooc_thrust_decay"], result(summaries=trend))["uncatalogued"]
    assert v["located"] is True


def test_a_weak_rotor_is_located_by_a_significant_negative_thrust_error_on_its_rotor():
    case = CASES["ooc_weak_rotor"]
    rotors = [{"rotor": i, "thrust_error": -0.1 if i == 2 else 0.0, "significant": i == 2}
              for i in range(4)]  # fmt: skip
    assert score(case, result(rotors=rotors))["uncatalogued"]["located"] is True
    nested = result(summaries={"rotors": {"rotors": rotors}})
    assert score(case, nested)["uncatalogued"]["located"] is True
    rotors[2]["thrust_error"] = 0.1
    assert score(case, result(rotors=rotors))["uncatalogued"]["located"] is False
    # a rotor stronger than modelled (a blind case: 8% more) is located by a positive one
    strong = dataclasses.replace(case, expected_regime=("rotor", 2, 1))
    assert score(strong, result(rotors=rotors))["uncatalogued"]["located"] is True


def test_a_catalogue_case_meets_its_target_with_the_exact_set_within_ten_percent():
    case = CASES["far_ground_effect_lag"]

    def fitted(rho: float) -> dict:
        return result(
            effects={
                "ground_effect": {"status": "present", "parameters": {
                    "rho": {"value": rho, "ci95": [rho - 0.2, rho + 0.2]}}},
                "motor_lag": {"status": "present", "parameters": {
                    "tau": {"value": 0.041, "ci95": [0.035, 0.045]}}},
            }
        )  # fmt: skip

    good, far = score(case, fitted(3.2)), score(case, fitted(3.5))
    assert good["exact"] and good["catalogue_target"]
    assert far["exact"] and not far["catalogue_target"]
    ooc = score(CASES["ooc_outwash"], result())
    scores = {"cases": [good, far, ooc], "summary": None}
    scores["summary"] = summarise(scores["cases"], [case, case, CASES["ooc_outwash"]])
    assert scores["summary"]["catalogue_target_rate"] == 0.5
    assert scores["summary"]["uncatalogued"]["cases"] == 1
    text = table(scores)
    assert "located missing" in text and "out of the catalogue (1 cases)" in text


def test_passes_run_along_x_when_fitting_and_along_y_when_held_out_and_pads_are_placed():
    from mission.campaigns.gap_flights import PAD_XY_M, PASS_SPEEDS_M_S, bench_mission

    def ends(kind: str, seed: int) -> list[list[float]]:
        return [wp["position_m"] for wp in bench_mission(kind, seed)["waypoints"]]

    along_x, along_y = ends("passes", 0), ends("passes", 100)
    assert all(abs(p[0]) == 1.5 and abs(p[1]) <= 0.2 for p in along_x)
    assert all(abs(p[1]) == 1.5 and abs(p[0]) <= 0.2 for p in along_y)
    speeds = [wp["speed_m_s"] for wp in bench_mission("passes", 0)["waypoints"]]
    assert tuple(speeds) == PASS_SPEEDS_M_S
    on, off = ends("pad", 100)[-1], ends("pad", 1)[-1]  # where each lands
    assert on[:2] == list(PAD_XY_M) and off[:2] == [-PAD_XY_M[0], PAD_XY_M[1]]


def test_a_torque_is_located_by_its_pattern_of_rotor_errors_and_asks_no_force_shrink():
    case = CASES["ooc_yaw_torque"]
    parse_effects([dict(e) for e in real_effects(case)], case.name)
    patterns = {"yaw": {"share": -0.03, "significant": True},
                "collective": {"share": 0.001, "significant": False}}  # fmt: skip
    r = result(unexplained={"share": 0.1, "where": []}, rotors={"patterns": patterns})
    v = score(case, r)["uncatalogued"]
    assert v["located"] is True and v["learned_shrink_ok"] and v["passed"]
    patterns["yaw"]["significant"] = False
    assert not score(case, r)["uncatalogued"]["passed"]


def test_logs_too_short_to_fit_must_be_refused_saying_what_is_missing():
    from mission.campaigns.gap_bench import refused

    case = CASES["short_fitting_logs"]
    assert case.refused and case.cut_s == (1.5, None)
    said = refused(case, "too little flight to fit: the fitting logs hold 2.90 s airborne "
                   "and usable (...); at least 4 s in all is needed")  # fmt: skip
    assert said["refusal"]["passed"]
    diagnosed = score(case, result())  # a diagnosis where a refusal was due
    assert diagnosed["refusal"] == {"expected": True, "message": None, "passed": False}
    scores = {"cases": [said, diagnosed], "summary": None}
    scores["summary"] = summarise(scores["cases"], [case, case])
    assert scores["summary"]["refused_as_expected"] == [True, False]
    text = table(scores)
    assert "PASS: refused: too little flight" in text and "fail: refused: not refused" in text


def test_a_log_is_cut_about_its_middle(tmp_path):
    import numpy as np

    from learner.flightlogs.flightlog import FlightLog, write_log
    from learner.flightlogs.readers import read_log
    from mission.campaigns.gap_flights import cut_log

    n = 1001  # 10 s at 100 Hz
    t = np.arange(n) * 0.01
    z = np.zeros((n, 3))
    up = np.tile([0.0, 0.0, 1.0], (n, 1))
    log = FlightLog("full", t, up, z, np.tile([1.0, 0, 0, 0], (n, 1)), z, np.full((n, 4), 2e3))
    cut = read_log(cut_log(write_log(log, tmp_path / "full.csv"), 1.5, tmp_path / "cut.csv"))
    assert abs(cut.time_s[0] - 4.25) < 0.011 and abs(cut.time_s[-1] - 5.75) < 0.011


def test_own_recordings_are_read_without_a_shift_or_a_trend_left():
    case = CASES["own_recordings_rho2"]
    assert case.logs == "recording" and case.truth == {"ground_effect": {"rho": 2.0}}
    trend = {"significant": True, "after_catalogue_share_per_min": -0.016,
             "floor_share_per_min": 0.43}  # fmt: skip
    own = score(case, result(summaries={"trend": trend}))["own_recordings"]
    assert own["passed"] and own["shifted"] == []
    shifted = score(case, result(summaries={"trend": trend}, z_offsets_m={"flight0": 0.0056}))
    assert not shifted["own_recordings"]["passed"]
    trend["after_catalogue_share_per_min"] = 0.5
    assert not score(case, result(summaries={"trend": trend}))["own_recordings"]["passed"]
