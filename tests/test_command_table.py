"""A MAVLink command is added through the ground station's command table alone: a handler
registered for a command the vehicle does not support answers a real pymavlink client over
UDP on loopback, and the state it returns is the commander's next state."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from typing import Any

import pytest
from pymavlink import mavutil

from autopilot.commander import requests
from autopilot.commander.commander import CommanderState
from autopilot.gcs.ground_station import GroundStation, Handled, StepInput
from autopilot.gcs.link import GcsLink
from autopilot.identity import PX4
from autopilot.params import ParamStore
from autopilot.types import FlightState

mav = mavutil.mavlink
ORIGIN = (59.35, 18.07, 10.0)
HERE = (0.3, -0.2, 0.0126)  # resting on the ground
ON_THE_GROUND = StepInput(
    time_s=1.0,
    wall_s=1.0,
    state=FlightState(HERE, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    height_m=0.0126,
    resting_height_m=0.0126,
)
HEARD = ["COMMAND_ACK", "STATUSTEXT"]
MAX_STEPS = 400  # control steps before the ack is given up on (each waits up to 50 ms)


@pytest.fixture
def station() -> Iterator[GroundStation]:
    link = GcsLink(["udpin:127.0.0.1:0"])
    yield GroundStation(link, ParamStore(None), PX4, ORIGIN)
    link.close()


@pytest.fixture
def client(station: GroundStation) -> Iterator[Any]:
    port = station.link.endpoints[0].local_port
    conn = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{port}", source_system=255, source_component=190
    )
    yield conn
    conn.close()


def ask(
    station: GroundStation, client: Any, command: int, *params: float
) -> tuple[Any, CommanderState, list[str]]:
    """COMMAND_LONG from the client; the station steps until the client has its COMMAND_ACK.
    Returns the ack, the commander state after the step that answered and the texts heard."""
    client.mav.command_long_send(1, 1, command, 0, *params)
    texts: list[str] = []
    for _ in range(MAX_STEPS):
        cmd = station.before_step(CommanderState(), ON_THE_GROUND)
        m = client.recv_match(type=HEARD, blocking=True, timeout=0.05)
        while m is not None:
            if m.get_type() == "STATUSTEXT":
                texts.append(m.text)
            elif m.command == command:
                return m, cmd, texts
            m = client.recv_match(type=HEARD)
    raise AssertionError(f"no COMMAND_ACK for command {command}")


def set_home_here(station: GroundStation, m: Any, cmd: CommanderState, inp: StepInput) -> Handled:
    """A toy MAV_CMD_DO_SET_HOME: param1 1 sets home where the vehicle is, nothing else."""
    if m.param1 != 1.0:
        return cmd, requests.Verdict(mav.MAV_RESULT_DENIED, "set home: only here (param1 1)")
    return dataclasses.replace(cmd, home_m=inp.state.position_m), requests.OK


def test_a_command_registered_in_the_table_answers_a_real_client(station, client):
    ack, cmd, _ = ask(station, client, mav.MAV_CMD_DO_SET_HOME, 1, 0, 0, 0, 0, 0, 0)
    assert ack.result == mav.MAV_RESULT_UNSUPPORTED and cmd.home_m is None  # not there today

    station.commands[mav.MAV_CMD_DO_SET_HOME] = set_home_here
    ack, cmd, _ = ask(station, client, mav.MAV_CMD_DO_SET_HOME, 1, 0, 0, 0, 0, 0, 0)
    assert ack.result == mav.MAV_RESULT_ACCEPTED
    assert (ack.target_system, ack.target_component) == (255, 190)
    assert cmd.home_m == HERE  # the handler's state is the commander's

    ack, cmd, texts = ask(station, client, mav.MAV_CMD_DO_SET_HOME, 0, 0, 0, 0, 0, 0, 0)
    assert ack.result == mav.MAV_RESULT_DENIED and cmd.home_m is None
    assert any("only here" in text for text in texts)  # the reason, before the ack

    other = GroundStation(GcsLink([]), ParamStore(None), PX4, ORIGIN)
    assert mav.MAV_CMD_DO_SET_HOME not in other.commands  # one station's table is its own


@pytest.mark.parametrize(
    ("time_s", "position_lost", "height_m"),
    [(0.1, None, 0.0126), (1.0, None, 0.0126), (1.0, "motion capture lost", 0.0126),
     (1.0, None, 0.5)],
)  # fmt: skip
def test_health_says_armable_exactly_when_arming_is_accepted(
    station, time_s, position_lost, height_m
):
    """SYS_STATUS as MAVSDK reads it: the GPS bit is its local and global position health,
    PREARM_CHECK its is_armable (and QGroundControl's ready state)."""
    from autopilot.gcs import telemetry

    inp = dataclasses.replace(
        ON_THE_GROUND, time_s=time_s, position_lost=position_lost, height_m=height_m
    )
    status = telemetry.sys_status(station._snapshot(CommanderState(), inp), 0.0, 0)
    armable = bool(status.onboard_control_sensors_health & mav.MAV_SYS_STATUS_PREARM_CHECK)
    position_ok = bool(status.onboard_control_sensors_health & mav.MAV_SYS_STATUS_SENSOR_GPS)
    _, verdict = requests.arm(CommanderState(), time_s, HERE, inp.not_ready(), False)
    assert armable == verdict.accepted
    assert position_ok == (time_s >= requests.SENSORS_SETTLE_S and position_lost is None)
    if not armable:
        assert verdict.reason  # and the refusal says why
