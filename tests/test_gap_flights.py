"""The gap bench's missions as experiment design: vertical legs that excite the rotor drag's
vertical coefficient, holds by the wall and under the ceiling that excite their effects, and
cached flights dropped when the missions change (no flight is flown here)."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import pytest

from autopilot.commander.commander import CommanderParams
from autopilot.params import NAMES
from mission.campaigns.gap_bench import _drop_stale_flights
from mission.campaigns.gap_flights import (
    AUTOPILOT_PARAMS,
    CEILING_HOLD_RADII,
    REFERENCE_ROTOR_RADIUS_M,
    WALL_HOLD_RADII,
    bench_mission,
)
from simbridge.vehicle import load_vehicle


def heights(mission: dict) -> list[float]:
    return [wp["position_m"][2] for wp in mission["waypoints"]]


@pytest.mark.parametrize("kind", ["mixed", "aggressive"])
def test_cruising_flights_climb_and_descend_a_metre_twice_at_one_spot(kind: str) -> None:
    wps = bench_mission(kind, 0)["waypoints"]
    legs = [wp for wp in wps if wp["acceptance_radius_m"] == 0.15]
    assert len(legs) == 4
    z = [wp["position_m"][2] for wp in legs]
    assert all(abs(b - a) >= 1.0 for a, b in itertools.pairwise(z))
    assert len({tuple(wp["position_m"][:2]) for wp in legs}) == 1
    assert max(z) < 1.5 and min(z) > 0.2  # far from the ground and a 3 m ceiling
    # the low pass still ends the mission
    assert wps[-1]["position_m"][2] == 0.04


def test_a_large_frame_flies_the_bench_missions_clear_of_the_ground() -> None:
    """The bench's heights were the nano's: a 4 cm hold lay below the 2.7 kg quadrotor's
    10 cm resting height and 0.25 m legs flown at 30 deg put its 0.6 m frame's corner in
    the ground (a blind case tipped onto a corner; another's flights were a fifth ground
    contact). Heights now rise where a vehicle's body needs it; the nano's and the
    Crazyflies' missions are unchanged."""
    big = load_vehicle("quad_2_7kg")
    half_h, half_diag = big.body_size_m[2] / 2, math.hypot(*big.body_size_m[:2]) / 2
    for kind in ("mixed", "hover", "aggressive", "wall"):
        for seed in (0, 1, 100):
            for wp in bench_mission(kind, seed, vehicle=big)["waypoints"]:
                z = wp["position_m"][2]
                assert z >= half_h + 0.02  # level: above its resting height
                if wp.get("acceptance_radius_m", 1.0) > 0.03 and not wp.get("hold_s"):  # legs
                    assert z - half_h * math.cos(math.pi / 6) - half_diag * 0.5 >= 0.05 - 1e-9
            for name in ("nano", "crazyflie2", "crazyflie2_large"):
                small = bench_mission(kind, seed, vehicle=load_vehicle(name))
                assert small == bench_mission(kind, seed)  # the nano's own


def test_vertical_speed_limits_let_a_metre_step_be_the_loops_plain_step() -> None:
    names = dict(p.split("=") for p in AUTOPILOT_PARAMS)
    assert {"MPC_Z_V_AUTO_UP", "MPC_Z_V_AUTO_DN"} <= set(names) <= set(NAMES)
    defaults = CommanderParams()
    for value in names.values():
        assert float(value) >= 1.0 > defaults.climb_speed_m_s


def test_hover_and_wall_flights_have_no_vertical_legs() -> None:
    for kind in ("hover", "wall"):
        assert max(heights(bench_mission(kind, 1))) <= 0.8


def test_wall_flights_hold_two_rotor_radii_from_the_wall() -> None:
    wps = bench_mission("wall", 100)["waypoints"]
    held = [wp for wp in wps if wp["hold_s"] >= 3.0]
    assert len(held) == 1
    gap_m = 0.6 - held[0]["position_m"][1]
    assert gap_m == pytest.approx(WALL_HOLD_RADII * REFERENCE_ROTOR_RADIUS_M)
    assert 0.08 < gap_m < 0.15  # clear of the body's 4 cm half-width and its contact margin


def test_ceiling_flights_hold_under_the_ceiling_and_stay_below_the_hold() -> None:
    with pytest.raises(ValueError, match="ceiling_m"):
        bench_mission("ceiling", 0)
    m = bench_mission("ceiling", 0, ceiling_m=0.85)
    hold = 0.85 - CEILING_HOLD_RADII * REFERENCE_ROTOR_RADIUS_M
    held = [wp for wp in m["waypoints"] if wp["hold_s"] >= 3.0]
    assert [wp["position_m"][2] for wp in held] == [pytest.approx(hold)]
    assert max(heights(m)) == pytest.approx(hold)
    # the same seed gives the same mission; another seed another
    assert bench_mission("ceiling", 0, ceiling_m=0.85) == m
    assert bench_mission("ceiling", 1, ceiling_m=0.85) != m


def test_cached_flights_are_dropped_when_the_missions_change(tmp_path: Path) -> None:
    _drop_stale_flights(tmp_path, "world" + repr(bench_mission("mixed", 0)))
    (tmp_path / "flight0.csv").write_text("cached")
    _drop_stale_flights(tmp_path, "world" + repr(bench_mission("mixed", 0)))
    assert (tmp_path / "flight0.csv").exists()
    _drop_stale_flights(tmp_path, "world" + repr(bench_mission("mixed", 1)))
    assert not (tmp_path / "flight0.csv").exists()
