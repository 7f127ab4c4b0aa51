"""Defaults that follow the firmware an identity claims to be, and the firmware's own names.

A user who knows PX4 or ArduCopter expects their conventions from a vehicle that says it is
one: no geofence and no ground-station-loss failsafe until they turn them on, PX4's take-off
altitude, ArduCopter's take-off to the command's altitude and its Guided timeout. Where this
vehicle's own scale rules (a 56 g quadrotor: speeds, acceptance radius, return altitude),
the default is ours under both identities, and `FIRMWARE` says what the firmware has.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Equivalent:
    px4: str  # PX4's parameter and its default
    ardupilot: str  # ArduCopter's parameter and its default


# Our parameter -> its value under each identity, where it is not the dataclass default.
IDENTITY_DEFAULTS: dict[str, dict[str, float]] = {
    "px4": {
        "MIS_TAKEOFF_ALT": 2.5,
        "GF_ACTION": 2.0,  # hold
        "COM_DL_LOSS_T": 10.0,
        "COM_OF_LOSS_T": 1.0,
    },
    "ardupilot": {
        "GF_ACTION": 3.0,  # FENCE_ACTION 1: RTL
        "COM_DL_LOSS_T": 5.0,
        "COM_OF_LOSS_T": 3.0,  # GUID_TIMEOUT: velocity targets this old stop the vehicle
    },
}

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
    "NAV_ACC_RAD": Equivalent("NAV_ACC_RAD 10 m", "WPNAV_RADIUS 200 cm"),
    "RTL_RETURN_ALT": Equivalent("RTL_RETURN_ALT 60 m", "RTL_ALT 1500 cm"),
}


def identity_defaults(identity: str) -> dict[str, float]:
    """Our parameters' defaults under `identity` ("px4" or "ardupilot") that differ from the
    settings dataclasses' defaults."""
    return dict(IDENTITY_DEFAULTS[identity])
