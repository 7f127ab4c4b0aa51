"""The firmware the vehicle says it is (PX4 or ArduCopter): one `Identity` per firmware, chosen
by name (`--identity px4|ardupilot`), with its MAVLink autopilot type, how it encodes flight
modes, its parameter defaults and the behaviours a user of that firmware expects.

A user who knows PX4 or ArduCopter expects their conventions from a vehicle that says it is
one: no geofence and no ground-station-loss failsafe until they turn them on, PX4's take-off
altitude, ArduCopter's take-off to the command's altitude and its Guided timeout. Where this
vehicle's own scale rules (a 56 g quadrotor: speeds, acceptance radius, return altitude),
the default is ours under both identities, and `FIRMWARE` says what the firmware has.

Modes in HEARTBEAT.custom_mode: PX4 packs main << 16 | sub << 24, ArduCopter numbers each
mode. MAV_AUTOPILOT_GENERIC is not offered: MAVSDK would decode PX4 modes, MAVProxy
ArduCopter modes (MAVLINK.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from autopilot.types import FlightMode
from simbridge.hil import mavlink as mav


@dataclass(frozen=True, eq=False)  # one object per firmware: compared and hashed as itself
class Identity:
    name: str  # as configuration and `--identity` spell it
    autopilot: int  # HEARTBEAT.autopilot (MAV_AUTOPILOT_*)
    defaults: Mapping[str, float]  # our parameters' defaults that differ from the dataclasses'
    custom_mode: Callable[[FlightMode], int]  # HEARTBEAT.custom_mode of a mode
    # the mode SET_MODE's custom_mode (sub None) or DO_SET_MODE's p2 and p3 ask for; None:
    # this vehicle has no such mode
    decode_mode: Callable[[int, int | None], FlightMode | None]
    sub_mode_in_param3: bool  # DO_SET_MODE: p2 main mode, p3 sub mode (else p2 alone)
    # where a take-off, a go-to or stopped offboard setpoints leave the vehicle
    hold_mode: FlightMode
    # modes shown as one Guided mode, the only modes that take go-tos and setpoints (empty:
    # each request switches to its own mode)
    guided_modes: frozenset[FlightMode]
    takeoff_to_command_altitude: bool  # NAV_TAKEOFF p7 is the altitude, and must be given
    reposition_yaw: bool  # DO_REPOSITION p4 is a yaw in radians (else ignored)
    home_is_item_0: bool  # mission item 0 is home, not a place to fly to
    legacy_mission_request: bool  # answers MISSION_REQUEST (not only MISSION_REQUEST_INT)

    def mode_from_command(self, p2: float, p3: float) -> tuple[FlightMode | None, str]:
        """The mode DO_SET_MODE asks for, and how to name what it asked for."""
        if self.sub_mode_in_param3:
            sub = int(p3) if math.isfinite(p3) else 0
            return self.decode_mode(int(p2), sub), f"main mode {int(p2)} sub {sub}"
        return self.decode_mode(int(p2), 0), f"custom mode {int(p2)}"


PX4_MAIN_AUTO, PX4_MAIN_POSCTL, PX4_MAIN_OFFBOARD = 4, 3, 6
PX4_AUTO_READY = 1
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
# PosHold, AltHold, Brake (MAVSDK 4.1's "hold" under ArduCopter): held in Loiter
ARDUCOPTER_ALIASES = {16: FlightMode.HOLD, 2: FlightMode.HOLD, 17: FlightMode.HOLD}


def _px4_custom_mode(mode: FlightMode) -> int:
    if mode == FlightMode.GUIDED:
        mode = FlightMode.HOLD  # PX4 flies a reposition (go-to) in AUTO.LOITER
    if mode == FlightMode.OFFBOARD:
        return PX4_MAIN_OFFBOARD << 16
    return PX4_MAIN_AUTO << 16 | PX4_SUB[mode] << 24


def _px4_decode_mode(custom: int, sub: int | None = None) -> FlightMode | None:
    """`custom` the main mode and `sub` the sub mode; or, with `sub` None, both packed."""
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
        if sub == PX4_AUTO_READY:
            return FlightMode.HOLD
    return None


def _arducopter_custom_mode(mode: FlightMode) -> int:
    # ArduCopter has no take-off or offboard mode: both are flown in Guided
    return ARDUCOPTER_MODES.get(mode, ARDUCOPTER_MODES[FlightMode.GUIDED])


def _arducopter_decode_mode(custom: int, sub: int | None = None) -> FlightMode | None:
    for mode, number in ARDUCOPTER_MODES.items():
        if number == custom:
            return mode
    return ARDUCOPTER_ALIASES.get(custom)


PX4 = Identity(
    name="px4",
    autopilot=mav.MAV_AUTOPILOT_PX4,
    defaults={
        "MIS_TAKEOFF_ALT": 2.5,
        "GF_ACTION": 2.0,  # hold
        "COM_DL_LOSS_T": 10.0,
        "COM_OF_LOSS_T": 1.0,
    },
    custom_mode=_px4_custom_mode,
    decode_mode=_px4_decode_mode,
    sub_mode_in_param3=True,
    hold_mode=FlightMode.HOLD,
    guided_modes=frozenset(),
    takeoff_to_command_altitude=False,
    reposition_yaw=True,
    home_is_item_0=False,
    legacy_mission_request=False,
)
ARDUPILOT = Identity(
    name="ardupilot",
    autopilot=mav.MAV_AUTOPILOT_ARDUPILOTMEGA,
    defaults={
        "GF_ACTION": 3.0,  # FENCE_ACTION 1: RTL
        "COM_DL_LOSS_T": 5.0,
        "COM_OF_LOSS_T": 3.0,  # GUID_TIMEOUT: velocity targets this old stop the vehicle
    },
    custom_mode=_arducopter_custom_mode,
    decode_mode=_arducopter_decode_mode,
    sub_mode_in_param3=False,
    hold_mode=FlightMode.GUIDED,  # ArduCopter holds in Guided after a guided take-off
    guided_modes=frozenset(
        {FlightMode.GUIDED, FlightMode.TAKEOFF, FlightMode.OFFBOARD}  # custom mode 4 for all
    ),
    takeoff_to_command_altitude=True,
    reposition_yaw=False,
    home_is_item_0=True,
    legacy_mission_request=True,
)
IDENTITIES: dict[str, Identity] = {i.name: i for i in (PX4, ARDUPILOT)}


def identity_named(name: str) -> Identity:
    """The identity configuration names; a KeyError names the ones there are."""
    try:
        return IDENTITIES[name]
    except KeyError:
        raise KeyError(f"no identity {name!r}: one of {sorted(IDENTITIES)}") from None


def identity_defaults(name: str) -> dict[str, float]:
    """Our parameters' defaults under the identity `name` that differ from the settings
    dataclasses' defaults."""
    return dict(identity_named(name).defaults)


@dataclass(frozen=True)
class Equivalent:
    px4: str  # PX4's parameter and its default
    ardupilot: str  # ArduCopter's parameter and its default


# Our parameter -> the firmware's name and default, for the README's table.
FIRMWARE: dict[str, Equivalent] = {
    "GF_MAX_HOR_DIST": Equivalent("GF_MAX_HOR_DIST 0 (off)", "FENCE_ENABLE 0, FENCE_RADIUS 300 m"),
    "GF_MAX_VER_DIST": Equivalent("GF_MAX_VER_DIST 0 (off)", "FENCE_ENABLE 0, FENCE_ALT_MAX 100 m"),
    "GF_ACTION": Equivalent("GF_ACTION 2 (hold)", "FENCE_ACTION 1 (RTL)"),
    "NAV_DLL_ACT": Equivalent("NAV_DLL_ACT 0 (off)", "FS_GCS_ENABLE 0 (off)"),
    "COM_DL_LOSS_T": Equivalent("COM_DL_LOSS_T 10 s", "FS_GCS_TIMEOUT 5 s"),
    "COM_OF_LOSS_T": Equivalent("COM_OF_LOSS_T 1 s", "GUID_TIMEOUT 3 s"),
    "MIS_TAKEOFF_ALT": Equivalent("MIS_TAKEOFF_ALT 2.5 m", "the command's param 7"),
    "MPC_XY_CRUISE": Equivalent("MPC_XY_CRUISE 5 m/s", "WPNAV_SPEED 1000 cm/s"),
    "MPC_Z_V_AUTO_UP": Equivalent("MPC_Z_V_AUTO_UP 3 m/s", "WPNAV_SPEED_UP 250 cm/s"),
    "MPC_Z_V_AUTO_DN": Equivalent("MPC_Z_V_AUTO_DN 1.5 m/s", "WPNAV_SPEED_DN 150 cm/s"),
    "MPC_LAND_SPEED": Equivalent("MPC_LAND_SPEED 0.7 m/s", "LAND_SPEED 50 cm/s"),
    "MPC_LAND_ALT1": Equivalent("MPC_LAND_ALT1 10 m", "LAND_ALT_LOW 1000 cm (one step)"),
    "MPC_LAND_ALT2": Equivalent("MPC_LAND_ALT2 5 m", "LAND_ALT_LOW 1000 cm"),
    "NAV_ACC_RAD": Equivalent("NAV_ACC_RAD 10 m", "WPNAV_RADIUS 200 cm"),
    "RTL_RETURN_ALT": Equivalent("RTL_RETURN_ALT 60 m", "RTL_ALT 1500 cm"),
}
