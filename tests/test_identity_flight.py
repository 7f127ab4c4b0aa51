"""An ArduCopter-identity autopilot flies a mission file it was started with, on its own."""

from __future__ import annotations

import json

from tests.helpers import REPO, run_groundfx


def test_ardupilot_identity_flies_a_mission_file_without_a_ground_station() -> None:
    # the mission is loaded before the vehicle has a home: ArduPilot's item 0 is compared with
    # the home given (the local frame's origin)
    result = run_groundfx(
        "fly", str(REPO / "mission/examples/low_hover.yaml"),
        "--identity", "ardupilot", "--no-gcs", "--no-record", "--json",
        timeout=300.0,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout.strip().splitlines()[-1])
    assert summary["landed"], summary["ended"]
    assert summary["landing_error_m"] < 0.02
