"""Frames, rotations and the geodetic projection: the one place for conversions.

Inside groundfx: world x east, y north, z up (ENU); body x forward, y left, z up (FLU);
quaternions (w, x, y, z) rotating body vectors into the world. MAVLink speaks NED (world)
and FRD (body); the conversions below are used only at the MAVLink edge.
"""

from __future__ import annotations

import math

import numpy as np

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
Mat3 = tuple[float, float, float, float, float, float, float, float, float]  # row-major

EARTH_RADIUS_M = 6371000.0  # PX4's map projection radius
_H = math.sqrt(0.5)
# Rotations taking ENU vectors to NED (pi about (1, 1, 0)/sqrt 2), FRD to FLU (pi about x).
Q_NED_FROM_ENU: Quat = (0.0, _H, _H, 0.0)
Q_FLU_FROM_FRD: Quat = (0.0, 1.0, 0.0, 0.0)


def enu_to_ned(v: Vec3) -> Vec3:
    return (v[1], v[0], -v[2])


def ned_to_enu(v: Vec3) -> Vec3:
    return (v[1], v[0], -v[2])


def flu_to_frd(v: Vec3) -> Vec3:
    return (v[0], -v[1], -v[2])


frd_to_flu = flu_to_frd  # the same reflection both ways


def quat_multiply(a: Quat, b: Quat) -> Quat:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def quat_conjugate(q: Quat) -> Quat:
    return (q[0], -q[1], -q[2], -q[3])


def quat_normalize(q: Quat) -> Quat:
    w, x, y, z = q
    n = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
    return (w * n, x * n, y * n, z * n)


def quat_to_matrix(q: Quat) -> Mat3:
    w, x, y, z = q
    return (
        1 - 2 * (y * y + z * z),
        2 * (x * y - w * z),
        2 * (x * z + w * y),
        2 * (x * y + w * z),
        1 - 2 * (x * x + z * z),
        2 * (y * z - w * x),
        2 * (x * z - w * y),
        2 * (y * z + w * x),
        1 - 2 * (x * x + y * y),
    )


def quat_to_matrices(q: np.ndarray) -> np.ndarray:
    """quat_to_matrix for many: (N, 4) w, x, y, z -> (N, 3, 3)."""
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def rotate(m: Mat3, v: Vec3) -> Vec3:
    """m v."""
    return (
        m[0] * v[0] + m[1] * v[1] + m[2] * v[2],
        m[3] * v[0] + m[4] * v[1] + m[5] * v[2],
        m[6] * v[0] + m[7] * v[1] + m[8] * v[2],
    )


def rotate_transposed(m: Mat3, v: Vec3) -> Vec3:
    """m^T v: a world vector into the body frame."""
    return (
        m[0] * v[0] + m[3] * v[1] + m[6] * v[2],
        m[1] * v[0] + m[4] * v[1] + m[7] * v[2],
        m[2] * v[0] + m[5] * v[1] + m[8] * v[2],
    )


def quat_from_euler(roll: float, pitch: float, yaw: float) -> Quat:
    """Z-Y-X (yaw, then pitch, then roll) Euler angles in radians to (w, x, y, z)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def euler_from_quat(q: Quat) -> Vec3:
    """(roll, pitch, yaw) in radians, Z-Y-X convention."""
    w, x, y, z = q
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return (roll, pitch, yaw)


def quat_enu_flu_to_ned_frd(q: Quat) -> Quat:
    """Body-FLU-to-ENU attitude into the body-FRD-to-NED attitude MAVLink reports."""
    return quat_multiply(quat_multiply(Q_NED_FROM_ENU, q), Q_FLU_FROM_FRD)


def quat_ned_frd_to_enu_flu(q: Quat) -> Quat:
    return quat_multiply(
        quat_multiply(quat_conjugate(Q_NED_FROM_ENU), q), quat_conjugate(Q_FLU_FROM_FRD)
    )


def xyzw_to_wxyz(q: tuple[float, ...]) -> Quat:
    """PyBullet's (x, y, z, w) to our (w, x, y, z)."""
    return (q[3], q[0], q[1], q[2])


def wxyz_to_xyzw(q: Quat) -> tuple[float, float, float, float]:
    return (q[1], q[2], q[3], q[0])


def local_to_geodetic(
    lat0_deg: float, lon0_deg: float, east_m: float, north_m: float
) -> tuple[float, float]:
    """Azimuthal equidistant projection (PX4's map_projection) from the origin: (lat, lon) deg."""
    lat0, lon0 = math.radians(lat0_deg), math.radians(lon0_deg)
    x_rad, y_rad = north_m / EARTH_RADIUS_M, east_m / EARTH_RADIUS_M
    c = math.hypot(x_rad, y_rad)
    if c == 0.0:
        return (lat0_deg, lon0_deg)
    sin_c, cos_c = math.sin(c), math.cos(c)
    lat = math.asin(cos_c * math.sin(lat0) + x_rad * sin_c * math.cos(lat0) / c)
    lon = lon0 + math.atan2(
        y_rad * sin_c, c * math.cos(lat0) * cos_c - x_rad * math.sin(lat0) * sin_c
    )
    return (math.degrees(lat), math.degrees(lon))


def geodetic_to_local(
    lat0_deg: float, lon0_deg: float, lat_deg: float, lon_deg: float
) -> tuple[float, float]:
    """Inverse of `local_to_geodetic`: (east, north) in metres."""
    lat0, lon0 = math.radians(lat0_deg), math.radians(lon0_deg)
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    cos_d_lon = math.cos(lon - lon0)
    arg = max(
        -1.0, min(1.0, math.sin(lat0) * math.sin(lat) + math.cos(lat0) * math.cos(lat) * cos_d_lon)
    )
    c = math.acos(arg)
    k = c / math.sin(c) if c != 0.0 else 1.0
    north = (
        k
        * (math.cos(lat0) * math.sin(lat) - math.sin(lat0) * math.cos(lat) * cos_d_lon)
        * EARTH_RADIUS_M
    )
    east = k * math.cos(lat) * math.sin(lon - lon0) * EARTH_RADIUS_M
    return (east, north)
