"""The failsafes as a pure function: each acts once, when its condition begins."""

from __future__ import annotations

from autopilot.commander import requests
from autopilot.commander.commander import CommanderState, Phase
from autopilot.commander.commander_params import CommanderParams
from autopilot.commander.failsafes import (
    ACTION_NONE,
    ACTION_RETURN,
    FailsafeParams,
    Failsafes,
    check_failsafes,
)
from autopilot.commander.mission_items import Geofence
from autopilot.types import FlightMode

HOME = (0.0, 0.0, 0.0126)


def flying() -> CommanderState:
    s, _ = requests.arm(CommanderState(), 0.0, HOME, None, False)
    return requests.dataclasses.replace(s, phase=Phase.HOLDING)


def step(fs: Failsafes, cmd: CommanderState, settings: FailsafeParams, wall_s: float, fence=None):
    return check_failsafes(
        fs, cmd, settings, fence or Geofence(), CommanderParams(), 10.0, wall_s,
        (3.0, 0.0, 1.0), HOME, None,
    )  # fmt: skip


def test_a_lost_ground_station_is_said_even_with_no_action_and_acted_on_once():
    fs = Failsafes(gcs_seen=True, gcs_heard_wall_s=0.0)
    quiet = FailsafeParams(gcs_loss_action=ACTION_NONE, gcs_loss_timeout_s=5.0)
    cmd, texts = step(fs, flying(), quiet, 6.0)
    assert cmd.mode == FlightMode.HOLD and "no failsafe action" in texts[0]
    fs = Failsafes(gcs_seen=True, gcs_heard_wall_s=0.0)
    settings = FailsafeParams(gcs_loss_action=ACTION_RETURN, gcs_loss_timeout_s=5.0)
    cmd, texts = step(fs, flying(), settings, 4.0)
    assert texts == [] and cmd.mode == FlightMode.HOLD
    cmd, texts = step(fs, cmd, settings, 6.0)
    assert cmd.mode == FlightMode.RETURN and texts == ["failsafe: ground station lost: return"]
    _, texts = step(fs, cmd, settings, 7.0)
    assert texts == []  # once


def test_the_fence_acts_only_when_set():
    settings = FailsafeParams()
    cmd, texts = step(Failsafes(), flying(), settings, 0.0)  # 3 m out, no fence: nothing
    assert texts == [] and cmd.mode == FlightMode.HOLD
    fence = Geofence(max_radius_m=2.0)
    cmd, texts = step(Failsafes(), flying(), settings, 0.0, fence)
    assert cmd.mode == FlightMode.RETURN and "beyond the maximum radius 2 m" in texts[0]
