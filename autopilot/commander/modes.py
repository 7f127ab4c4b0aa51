"""Flight modes and how each autopilot identity encodes them in HEARTBEAT.custom_mode.

PX4 (the default identity): custom_mode = main << 16 | sub << 24. ArduCopter: a number per
mode. MAV_AUTOPILOT_GENERIC is not offered: MAVSDK would decode PX4 modes, MAVProxy
ArduCopter modes (MAVLINK.md).
"""

from __future__ import annotations

from enum import StrEnum

from simbridge.hil import mavlink as mav


class FlightMode(StrEnum):
    HOLD = "hold"  # hold position (on the ground: wait)
    MISSION = "mission"
    TAKEOFF = "takeoff"
    LAND = "land"
    RETURN = "return"
    OFFBOARD = "offboard"
    GUIDED = "guided"  # go to a target, then hold there (ArduCopter's Guided; PX4's reposition)


PX4_MAIN_AUTO, PX4_MAIN_POSCTL, PX4_MAIN_OFFBOARD = 4, 3, 6
PX4_SUB = {
    FlightMode.TAKEOFF: 2,
    FlightMode.HOLD: 3,  # AUTO.LOITER
    FlightMode.MISSION: 4,
    FlightMode.RETURN: 5,
    FlightMode.LAND: 6,
}
ARDUCOPTER_MODES = {
    FlightMode.MISSION: 3,  # Auto
    FlightMode.GUIDED: 4,
    FlightMode.HOLD: 5,  # Loiter
    FlightMode.RETURN: 6,  # RTL
    FlightMode.LAND: 9,
}
# ArduCopter has no take-off or offboard mode: both are flown in Guided. PX4 flies a
# reposition (go-to) in AUTO.LOITER.
# PosHold, AltHold, Brake (MAVSDK 4.1's "hold" under ArduCopter): held in Loiter
ARDUCOPTER_ALIASES = {16: FlightMode.HOLD, 2: FlightMode.HOLD, 17: FlightMode.HOLD}

IDENTITIES = {"px4": mav.MAV_AUTOPILOT_PX4, "ardupilot": mav.MAV_AUTOPILOT_ARDUPILOTMEGA}


def custom_mode(mode: FlightMode, identity: str) -> int:
    """HEARTBEAT.custom_mode for `mode` under `identity` ("px4" or "ardupilot")."""
    if identity == "ardupilot":
        return ARDUCOPTER_MODES.get(mode, ARDUCOPTER_MODES[FlightMode.GUIDED])
    if mode == FlightMode.GUIDED:
        mode = FlightMode.HOLD
    if mode == FlightMode.OFFBOARD:
        return PX4_MAIN_OFFBOARD << 16
    return PX4_MAIN_AUTO << 16 | PX4_SUB[mode] << 24


def decode_mode(identity: str, custom: int, sub: int | None = None) -> FlightMode | None:
    """The mode a DO_SET_MODE / SET_MODE asks for, or None if this vehicle has no such mode.

    PX4: `custom` is the main mode (DO_SET_MODE p2) and `sub` the sub mode (p3); SET_MODE
    carries the packed custom_mode, which is unpacked when `sub` is None.
    """
    if identity == "ardupilot":
        for mode, number in ARDUCOPTER_MODES.items():
            if number == custom:
                return mode
        return ARDUCOPTER_ALIASES.get(custom)
    if sub is None:
        custom, sub = (custom >> 16) & 0xFF, (custom >> 24) & 0xFF
    if custom == PX4_MAIN_OFFBOARD:
        return FlightMode.OFFBOARD
    if custom == PX4_MAIN_POSCTL:
        return FlightMode.HOLD  # position control without sticks: hold
    if custom == PX4_MAIN_AUTO:
        for mode, number in PX4_SUB.items():
            if number == sub:
                return mode
        if sub == 1:  # AUTO.READY
            return FlightMode.HOLD
    return None
