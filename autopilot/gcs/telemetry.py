"""Telemetry for ground stations: what each message says about the vehicle, and when it is sent.

`Snapshot` is the vehicle as one control step sees it; the builders turn it into MAVLink
messages (NED and degE7 only here, at the edge). `Streams` schedules them on the simulated
clock, at default rates a ground station can change with SET_MESSAGE_INTERVAL or
REQUEST_DATA_STREAM.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from autopilot.commander.commander import AIRBORNE_PHASES, CommanderState, Phase
from autopilot.identity import Identity
from autopilot.types import FlightMode, FlightState
from simbridge.frames import (
    enu_to_ned,
    euler_from_quat,
    flu_to_frd,
    local_to_geodetic,
    quat_enu_flu_to_ned_frd,
)
from simbridge.hil import mavlink as mav

# gyro, accelerometer, magnetometer, GPS, pre-arm check (bits MAVSDK looks at)
SENSORS = (
    mav.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mav.MAV_SYS_STATUS_SENSOR_3D_MAG
    | mav.MAV_SYS_STATUS_SENSOR_GPS
)
PREARM = mav.MAV_SYS_STATUS_PREARM_CHECK
FENCE = mav.MAV_SYS_STATUS_GEOFENCE
CAPABILITIES = (
    mav.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mav.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2
)
FLIGHT_SW_VERSION = 0x01000000 | 0xFF  # 1.0.0, release


@dataclass(frozen=True)
class Snapshot:
    time_s: float
    state: FlightState  # local frame: x east, y north, z up
    origin: tuple[float, float, float]  # lat, lon, alt of the local frame's origin
    home_m: tuple[float, float, float] | None  # local
    phase: Phase
    mode: FlightMode
    armed: bool
    ready: bool  # pre-arm checks pass: arming would be accepted
    identity: Identity
    position_ok: bool = True  # the estimator has a position (MAVSDK: local and global OK)
    fence_on: bool = False  # a geofence limit is set
    fence_breached: bool = False


def _global(s: Snapshot, x: float, y: float) -> tuple[int, int]:
    lat, lon = local_to_geodetic(s.origin[0], s.origin[1], x, y)
    return round(lat * 1e7), round(lon * 1e7)


def heartbeat(s: Snapshot) -> Any:
    base = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    if s.armed:
        base |= mav.MAV_MODE_FLAG_SAFETY_ARMED
    if s.mode in (FlightMode.MISSION, FlightMode.RETURN, FlightMode.LAND, FlightMode.TAKEOFF):
        base |= mav.MAV_MODE_FLAG_AUTO_ENABLED
    base |= mav.MAV_MODE_FLAG_GUIDED_ENABLED | mav.MAV_MODE_FLAG_STABILIZE_ENABLED
    status = mav.MAV_STATE_ACTIVE if s.armed else mav.MAV_STATE_STANDBY
    return mav.MAVLink_heartbeat_message(
        mav.MAV_TYPE_QUADROTOR,
        s.identity.autopilot,
        base,
        s.identity.custom_mode(s.mode),
        status,
        3,
    )


def sys_status(s: Snapshot, drop_rate_percent: float, errors: int) -> Any:
    # The geofence bit is healthy unless breached, present or not, as ArduPilot sends it:
    # MAVProxy announces "fence breach" when it is clear.
    present = SENSORS | PREARM | (FENCE if s.fence_on else 0)
    # MAVSDK reads its position health from the GPS bit, QGroundControl "ready" from PREARM
    sensors = SENSORS if s.position_ok else SENSORS & ~mav.MAV_SYS_STATUS_SENSOR_GPS
    health = sensors | (PREARM if s.ready else 0) | (0 if s.fence_breached else FENCE)
    return mav.MAVLink_sys_status_message(
        present, present, health,
        100, 4100, -1, -1, min(int(drop_rate_percent * 100), 10000), min(errors, 65535),
        0, 0, 0, 0,
    )  # fmt: skip


def extended_sys_state(s: Snapshot) -> Any:
    landed = {
        Phase.TAKING_OFF: mav.MAV_LANDED_STATE_TAKEOFF,
        Phase.LANDING: mav.MAV_LANDED_STATE_LANDING,
    }.get(
        s.phase,
        mav.MAV_LANDED_STATE_IN_AIR
        if s.phase in AIRBORNE_PHASES
        else mav.MAV_LANDED_STATE_ON_GROUND,
    )
    return mav.MAVLink_extended_sys_state_message(mav.MAV_VTOL_STATE_MC, landed)


def time_boot_ms(s: Snapshot) -> int:
    return int(s.time_s * 1000) & 0xFFFFFFFF


def global_position_int(s: Snapshot) -> Any:
    p, v = s.state.position_m, s.state.velocity_m_s
    lat, lon = _global(s, p[0], p[1])
    home_z = s.home_m[2] if s.home_m is not None else 0.0
    vn = enu_to_ned(v)
    heading = math.degrees(euler_from_quat(quat_enu_flu_to_ned_frd(s.state.quaternion))[2]) % 360
    alt_mm, relative_mm = round((s.origin[2] + p[2]) * 1000), round((p[2] - home_z) * 1000)
    return mav.MAVLink_global_position_int_message(
        time_boot_ms(s), lat, lon, alt_mm, relative_mm,
        round(vn[0] * 100), round(vn[1] * 100), round(vn[2] * 100), round(heading * 100) % 36000,
    )  # fmt: skip


def local_position_ned(s: Snapshot) -> Any:
    p, v = enu_to_ned(s.state.position_m), enu_to_ned(s.state.velocity_m_s)
    return mav.MAVLink_local_position_ned_message(time_boot_ms(s), *p, *v)


def attitude(s: Snapshot) -> Any:
    roll, pitch, yaw = euler_from_quat(quat_enu_flu_to_ned_frd(s.state.quaternion))
    rates = flu_to_frd(s.state.angular_velocity_body_rad_s)
    return mav.MAVLink_attitude_message(time_boot_ms(s), roll, pitch, yaw, *rates)


def home_position(s: Snapshot) -> Any | None:
    if s.home_m is None:
        return None
    h = s.home_m
    lat, lon = _global(s, h[0], h[1])
    ned = enu_to_ned(h)
    return mav.MAVLink_home_position_message(
        lat, lon, round((s.origin[2] + h[2]) * 1000), *ned, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
        int(s.time_s * 1e6),
    )  # fmt: skip


def statustext(text: str, severity: int, text_id: int) -> list[Any]:
    """STATUSTEXT: a text over 50 bytes goes in chunks sharing `text_id` (MAVLink 2), one
    alone with id 0."""
    data = text.encode()[: 50 * 20]
    chunks = [data[i : i + 50] for i in range(0, len(data), 50)] or [b""]
    shared = text_id if len(chunks) > 1 else 0
    return [
        mav.MAVLink_statustext_message(severity, chunk, shared, seq)
        for seq, chunk in enumerate(chunks)
    ]


def mission_current(cmd: CommanderState, item_count: int) -> tuple[int, int, int]:
    """MISSION_CURRENT's seq, total and mission_state."""
    if not item_count:
        state = mav.MISSION_STATE_NO_MISSION
    elif cmd.mission_done:
        state = mav.MISSION_STATE_COMPLETE
    elif cmd.mode == FlightMode.MISSION and cmd.phase in AIRBORNE_PHASES:
        state = mav.MISSION_STATE_ACTIVE
    elif cmd.mode == FlightMode.MISSION:
        state = mav.MISSION_STATE_NOT_STARTED
    else:
        state = mav.MISSION_STATE_PAUSED if cmd.current > 0 else mav.MISSION_STATE_NOT_STARTED
    seq = cmd.plan[cmd.current].seq if cmd.plan and cmd.current < len(cmd.plan) else 0
    if cmd.mission_done:
        seq = item_count  # past the last item, as PX4 reports a finished mission
    return seq, item_count, state


def autopilot_version() -> Any:
    return mav.MAVLink_autopilot_version_message(
        CAPABILITIES, FLIGHT_SW_VERSION, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 1, [0] * 18
    )


# Default rates in Hz of simulated time; MAVSDK and MAVProxy ask for more if they want it.
DEFAULT_RATES_HZ = {
    "HEARTBEAT": 1.0,
    "SYS_STATUS": 1.0,
    "EXTENDED_SYS_STATE": 2.0,
    "GLOBAL_POSITION_INT": 10.0,
    "LOCAL_POSITION_NED": 10.0,
    "ATTITUDE": 20.0,
    "HOME_POSITION": 0.5,
    "MISSION_CURRENT": 1.0,
}
MAX_RATE_HZ = 250.0  # the control rate: nothing is new more often
# REQUEST_DATA_STREAM's stream ids (ArduPilot's grouping) -> the messages they carry
DATA_STREAMS = {
    mav.MAV_DATA_STREAM_EXTENDED_STATUS: ("SYS_STATUS", "EXTENDED_SYS_STATE", "MISSION_CURRENT"),
    mav.MAV_DATA_STREAM_POSITION: ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"),
    mav.MAV_DATA_STREAM_EXTRA1: ("ATTITUDE",),
}


class Streams:
    """Which messages are due at a simulated time, at their (changeable) rates."""

    def __init__(self) -> None:
        self.interval_s = {name: 1.0 / hz for name, hz in DEFAULT_RATES_HZ.items()}
        self.due_s = dict.fromkeys(self.interval_s, 0.0)

    def set_rate(self, name: str, hz: float | None) -> None:
        """`hz` None: the default; 0 or less: stop."""
        if hz is None:
            hz = DEFAULT_RATES_HZ.get(name, 0.0)
        if hz <= 0.0:
            self.interval_s.pop(name, None)
            self.due_s.pop(name, None)
            return
        self.interval_s[name] = 1.0 / min(hz, MAX_RATE_HZ)
        self.due_s.setdefault(name, 0.0)

    def due(self, time_s: float) -> list[str]:
        out = []
        for name, due in self.due_s.items():
            if time_s >= due:
                interval = self.interval_s[name]
                # stay on the grid, but never send a backlog after a pause
                self.due_s[name] = due + interval if time_s - due < interval else time_s + interval
                out.append(name)
        return out


# What REQUEST_MESSAGE may ask for, by message id
ONE_SHOT = {
    mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION: "AUTOPILOT_VERSION",
    mav.MAVLINK_MSG_ID_HOME_POSITION: "HOME_POSITION",
    mav.MAVLINK_MSG_ID_HEARTBEAT: "HEARTBEAT",
    mav.MAVLINK_MSG_ID_SYS_STATUS: "SYS_STATUS",
    mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: "EXTENDED_SYS_STATE",
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: "GLOBAL_POSITION_INT",
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: "LOCAL_POSITION_NED",
    mav.MAVLINK_MSG_ID_ATTITUDE: "ATTITUDE",
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: "MISSION_CURRENT",
}
