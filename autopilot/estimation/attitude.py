"""Attitude arithmetic of the state estimator: rotation matrices, quaternion products and
rotation vectors on numpy arrays or floats, the heading of a quaternion, and the attitude of
a vehicle at rest from gravity and the magnetic field."""

from __future__ import annotations

import math

import numpy as np

from simbridge.frames import Quat, quat_multiply


def _floats(v: np.ndarray | tuple[float, ...]) -> list[float]:
    """Python floats: arithmetic on numpy scalars is several times slower."""
    return v.tolist() if isinstance(v, np.ndarray) else list(v)


def skew(v: np.ndarray) -> np.ndarray:
    x, y, z = _floats(v)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rotation(q: np.ndarray) -> np.ndarray:
    w, x, y, z = _floats(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.array(quat_multiply(tuple(_floats(a)), tuple(_floats(b))))


def rotation_vector_floats(x: float, y: float, z: float) -> Quat:
    """The quaternion of a rotation vector (exact), in floats."""
    x, y, z = float(x), float(y), float(z)
    angle = math.sqrt(x * x + y * y + z * z)
    if angle < 1e-12:
        return (1.0, 0.5 * x, 0.5 * y, 0.5 * z)
    s = math.sin(0.5 * angle) / angle
    return (math.cos(0.5 * angle), s * x, s * y, s * z)


def rotation_vector_quat(theta: np.ndarray) -> np.ndarray:
    """The quaternion of a rotation vector (exact)."""
    return np.array(rotation_vector_floats(*_floats(theta)))


def attitude_from_gravity_and_field(
    specific_force_body: np.ndarray, field_body: np.ndarray, field_world: np.ndarray
) -> np.ndarray:
    """Attitude of a vehicle at rest: the specific force points up, the magnetic field's
    horizontal part north-ish as in the world (TRIAD)."""

    def triad(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        t1 = a / np.linalg.norm(a)
        t2 = np.cross(a, b)
        t2 /= np.linalg.norm(t2)
        return np.column_stack([t1, t2, np.cross(t1, t2)])

    r = triad(np.array([0.0, 0.0, 1.0]), field_world) @ triad(specific_force_body, field_body).T
    return matrix_quat(r)


def matrix_quat(r: np.ndarray) -> np.ndarray:
    tr = r[0, 0] + r[1, 1] + r[2, 2]
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = [(r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s]
    elif r[1, 1] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s]
    out = np.array(q)
    return out / np.linalg.norm(out) * (1.0 if out[0] >= 0 else -1.0)


def yaw_of(q: np.ndarray | tuple[float, ...]) -> float:
    """The heading of a (w, x, y, z) quaternion: the body x axis from world east, ccw."""
    w, x, y, z = _floats(q)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
