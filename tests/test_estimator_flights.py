"""The autopilot on its own sensors: each sensor set flies, model errors are flown out by the
integral, a lost position source lands, the land detector declares touchdown on time.

Flights of real `groundfx sim` and `groundfx autopilot` processes (the reproducible path:
the autopilot arms by itself), with the simulator's realistic sensors; the figures are
judged against the simulator's truth, which the autopilot only records.
"""

from __future__ import annotations

import numpy as np
import pytest

from autopilot.control.controller import THESIS_GAINS
from mission.fly import fly
from tests.helpers import REPO

EXAMPLES = REPO / "mission" / "examples"
RHO2 = [{"name": "ground_effect", "rho": 2.0}]


def sensors(name: str) -> list[str]:
    from autopilot.estimation.sources import sensor_sets

    return [a for k, v in sensor_sets()[name].items() for a in ("--param", f"{k}={v}")]


@pytest.mark.parametrize(
    ("sensor_set", "landing_within_m"),
    [("mocap", 0.02), ("flow", 0.15), ("gps", 0.6)],  # flow drifts; GPS errs by 0.5 m
)
def test_each_sensor_set_flies_the_demo_mission_and_lands(sensor_set, landing_within_m):
    summary = fly(
        EXAMPLES / "demo.yaml",
        world="rho2",
        via_gcs=False,
        record=False,
        autopilot_options=sensors(sensor_set),
    )
    assert summary["landed"], summary.get("ended")
    assert summary["landing_error_m"] < landing_within_m
    # the land detector declares the touchdown within a second of the true contact
    assert abs(summary["touchdown_declared_s"] - summary["touchdown_time_s"]) < 1.0
    # nothing the estimator fused was refused wholesale, and its quality is reported
    assert summary["estimator_fused"] and summary["est_position_rms_m"] is not None
    if sensor_set == "mocap":
        assert summary["hold_z_rms_error_m"] < 0.003
        assert summary["est_position_rms_m"] < 0.002
    if sensor_set == "flow":  # over five sensor seeds the hold's RMS spans 1.3-2.8 mm (README)
        assert summary["hold_z_rms_error_m"] < 0.005
    if sensor_set == "gps":  # the range aids the barometer near the ground (EKF2_RNG_CTRL 1)
        assert summary["hold_z_rms_error_m"] < 0.01


@pytest.mark.parametrize(
    "effects",
    [
        [{"name": "mass_error", "scale": 1.1}],
        [{"name": "rotor_asymmetry", "scales": [1.0, 1.0, 0.85, 1.0]}],
        [
            {"name": "rotor_drag"},
            {"name": "body_drag"},
            {"name": "wind", "mean_m_s": [2.0, 0.0, 0.0]},
        ],
    ],
    ids=["10% heavier", "one rotor at 85%", "2 m/s wind"],
)
def test_a_model_error_is_flown_out_and_the_square_lands_within_5_cm(write_world, effects):
    world = write_world({"vehicle": "nano", "effects": RHO2 + effects})
    summary = fly(EXAMPLES / "square.yaml", world=str(world), via_gcs=False, record=False)
    assert summary["landed"], summary.get("ended")
    assert summary["landing_error_m"] < 0.05


def test_a_10_percent_heavier_vehicle_settles_within_a_centimetre_in_hover(write_world, tmp_path):
    heavier = [{"name": "ground_effect", "rho": 1.0}, {"name": "mass_error", "scale": 1.1}]
    world = write_world({"vehicle": "nano", "effects": heavier})
    track = tmp_path / "t.npz"
    summary = fly(
        EXAMPLES / "hover.yaml", world=str(world), via_gcs=False, record=False, trajectory=track
    )
    assert summary["landed"]
    log = np.load(track)["log"]
    t, z, mode = log[:, 0], log[:, 3], log[:, 9]
    holding = np.flatnonzero(mode == 4)
    settled = holding[t[holding] >= t[holding[0]] + 5.0]  # after 5 s of the 10 s hold
    assert settled.size > 500
    assert np.max(np.abs(z[settled] - 1.0)) < 0.01


def test_the_pd_of_the_thesis_alone_leaves_the_heavier_vehicle_sagging(write_world, tmp_path):
    """The integral is what flies the mass error out: without it (the thesis's gains) the
    same vehicle hangs below its setpoint."""
    heavier = [{"name": "ground_effect", "rho": 1.0}, {"name": "mass_error", "scale": 1.1}]
    world = write_world({"vehicle": "nano", "effects": heavier})
    track = tmp_path / "t.npz"
    thesis = [a for k, v in THESIS_GAINS.items() for a in ("--param", f"{k}={v:g}")]
    fly(
        EXAMPLES / "hover.yaml",
        world=str(world),
        via_gcs=False,
        record=False,
        trajectory=track,
        max_flight_s=12.0,
        autopilot_options=thesis,
    )
    log = np.load(track)["log"]
    t, z, mode = log[:, 0], log[:, 3], log[:, 9]
    holding = np.flatnonzero(mode == 4)
    late = holding[t[holding] >= t[holding[0]] + 3.0] if holding.size else holding
    assert late.size == 0 or np.mean(1.0 - z[late]) > 0.05  # never reaches the hold, or sags


def test_losing_motion_capture_in_flight_lands_on_the_remaining_sensors(write_world):
    world = write_world(
        {
            "vehicle": "nano",
            "effects": RHO2,
            "sensors": {"odometry_until_s": 6.0},  # tracking lost during the square
        }
    )
    summary = fly(EXAMPLES / "square.yaml", world=str(world), via_gcs=False, record=False)
    assert summary["landed"], summary.get("ended")
    assert len(summary["failsafes"]) == 1
    assert "motion capture lost in flight: land" in summary["failsafes"][0]
    # it came down from where it was: the failsafe at once, then 1 m at the landing speed
    failsafe_s = float(summary["failsafes"][0].split(" at ")[-1].split()[0])
    assert 6.0 <= failsafe_s < 6.0 + 0.5
    assert summary["touchdown_time_s"] - failsafe_s < 1.2 / 0.1 + 1.0
    assert summary["estimator_height_source"] != "vision"
