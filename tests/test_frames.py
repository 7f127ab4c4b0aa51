"""Frame conversions, checked against pymavlink's independent implementations."""

from __future__ import annotations

import math

import pytest
from pymavlink import mavextra
from pymavlink.quaternion import Quaternion

from simbridge.frames import (
    enu_to_ned,
    euler_from_quat,
    flu_to_frd,
    geodetic_to_local,
    local_to_geodetic,
    ned_to_enu,
    quat_enu_flu_to_ned_frd,
    quat_from_euler,
    quat_ned_frd_to_enu_flu,
    quat_to_matrix,
    rotate,
)


def same_rotation(a, b, tol=1e-9):
    return (
        max(abs(x - y) for x, y in zip(a, b, strict=True)) < tol
        or max(abs(x + y) for x, y in zip(a, b, strict=True)) < tol
    )


def test_vectors():
    assert enu_to_ned((1.0, 2.0, 3.0)) == (2.0, 1.0, -3.0)
    assert ned_to_enu(enu_to_ned((1.0, 2.0, 3.0))) == (1.0, 2.0, 3.0)
    assert flu_to_frd((1.0, 2.0, 3.0)) == (1.0, -2.0, -3.0)


@pytest.mark.parametrize(
    ("roll", "pitch", "yaw"),
    [(0, 0, 0), (10, 0, 0), (0, 15, 0), (0, 0, 30), (10, -5, 30), (-20, 25, 170), (5, 80, -100)],
)
def test_attitude_to_ned_frd_matches_mavlink_euler(roll, pitch, yaw):
    """ENU yaw is from east counter-clockwise, NED yaw from north clockwise; pitch up is
    negative about FLU y (left) and positive about FRD y (right); roll keeps its sign."""
    q_enu = quat_from_euler(math.radians(roll), math.radians(pitch), math.radians(yaw))
    expected = Quaternion([math.radians(roll), math.radians(-pitch), math.radians(90 - yaw)]).q
    assert same_rotation(quat_enu_flu_to_ned_frd(q_enu), tuple(expected), tol=1e-9)
    assert same_rotation(quat_ned_frd_to_enu_flu(quat_enu_flu_to_ned_frd(q_enu)), q_enu)


def test_euler_roundtrip_and_matrix():
    q = quat_from_euler(0.1, -0.2, 0.3)
    assert euler_from_quat(q) == pytest.approx((0.1, -0.2, 0.3))
    # a 90 degree yaw turns body forward into world north (+y)
    m = quat_to_matrix(quat_from_euler(0.0, 0.0, math.pi / 2))
    assert rotate(m, (1.0, 0.0, 0.0)) == pytest.approx((0.0, 1.0, 0.0))


def test_geodetic_projection_matches_pymavlink():
    lat0, lon0 = 59.3498, 18.0707
    for east, north in [(0.5, -0.3), (10.0, 20.0), (-150.0, 75.0)]:
        lat, lon = local_to_geodetic(lat0, lon0, east, north)
        # the great-circle distance (haversine, R = 6371 km, as PX4 uses) is the offset's length
        assert mavextra.distance_lat_lon(lat0, lon0, lat, lon) == pytest.approx(
            math.hypot(east, north), rel=1e-6
        )
        # pymavlink's flat-earth offset uses R = 6378.1 km: the same direction, 0.11 % shorter
        ref_lat, ref_lon = mavextra.gps_offset(lat0, lon0, east, north)
        assert (ref_lat - lat0) / (lat - lat0) == pytest.approx(6371000 / 6378100, rel=1e-4)
        assert (ref_lon - lon0) / (lon - lon0) == pytest.approx(6371000 / 6378100, rel=1e-4)
        assert geodetic_to_local(lat0, lon0, lat, lon) == pytest.approx((east, north), abs=1e-6)
