"""The simulator's truth, for the flight's figures, the recording and the flight log only:
nothing in the control path reads it (the autopilot flies on its estimator)."""

from __future__ import annotations

from autopilot.types import FlightState, Step
from simbridge.frames import frd_to_flu, geodetic_to_local, ned_to_enu, quat_ned_frd_to_enu_flu


def true_state(step: Step, origin: tuple[float, float, float]) -> FlightState | None:
    """Ground truth from HIL_STATE_QUATERNION in the local frame (x east, y north, z up):
    for the flight log, the recording and the estimator's error, never for control."""
    if "HIL_STATE_QUATERNION" not in step.latest:
        return None
    s = step.latest["HIL_STATE_QUATERNION"]
    local = step.latest.get("LOCAL_POSITION_NED") if "LOCAL_POSITION_NED" in step.new else None
    if local is not None:  # the same truth in floats
        position = ned_to_enu((local["x"], local["y"], local["z"]))
        velocity = ned_to_enu((local["vx"], local["vy"], local["vz"]))
    else:
        east, north = geodetic_to_local(origin[0], origin[1], s["lat"] * 1e-7, s["lon"] * 1e-7)
        position = (east, north, s["alt"] * 1e-3 - origin[2])
        velocity = ned_to_enu((s["vx"] * 0.01, s["vy"] * 0.01, s["vz"] * 0.01))
    return FlightState(
        position_m=position,
        velocity_m_s=velocity,
        quaternion=quat_ned_frd_to_enu_flu(tuple(s["attitude_quaternion"])),
        angular_velocity_body_rad_s=frd_to_flu((s["rollspeed"], s["pitchspeed"], s["yawspeed"])),
    )


def true_height_m(step: Step, truth: FlightState, terrain_m: float) -> float:
    """The true height of the centre of mass above the surface below (the simulator's
    ALTITUDE.bottom_clearance); without it, the true altitude over the terrain found."""
    altitude = step.latest.get("ALTITUDE")
    return altitude["bottom_clearance"] if altitude is not None else truth.position_m[2] - terrain_m
