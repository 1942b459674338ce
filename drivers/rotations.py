"""The few rotation helpers the drivers and emulators need, so `drivers` stands alone.

Convention (the same as the bench's own geometry module): a quaternion is scalar-first
``(w, x, y, z)``, unit norm, and maps vectors from the rotated (sensor) frame into the
reference frame, like the matching rotation matrix ``R``: ``v_ref = R @ v_sensor``.
Every function takes and returns a single quaternion (shape (4,)) or matrix (3, 3).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

# Below this rotation angle (rad) the series form of sin(theta/2)/theta is used: the
# closed form divides by theta and loses all precision near zero.
_SMALL_ANGLE_RAD = 1e-6


def _four(quaternion: ArrayLike) -> list[float]:
    if type(quaternion) is np.ndarray and quaternion.dtype.kind == "f":
        return quaternion.tolist()  # a filter's output, thousands a second: no copy to float64 first
    return np.asarray(quaternion, dtype=float).tolist()


def quat_normalize(quaternion: ArrayLike) -> FloatArray:
    """Unit quaternion with a non-negative scalar part (one representative of +-q)."""
    w, x, y, z = _four(quaternion)
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    if norm == 0.0:
        raise ValueError("a zero quaternion has no rotation to normalise")
    scale = 1.0 / norm
    if w < 0.0:
        scale = -scale
    return np.array([w * scale, x * scale, y * scale, z * scale])


def quat_conjugate(quaternion: ArrayLike) -> FloatArray:
    """Conjugate: the inverse rotation of a unit quaternion."""
    w, x, y, z = _four(quaternion)
    return np.array([w, -x, -y, -z])


def quat_multiply(left: ArrayLike, right: ArrayLike) -> FloatArray:
    """Hamilton product ``left * right``: apply ``right`` first, then ``left``."""
    aw, ax, ay, az = _four(left)
    bw, bx, by, bz = _four(right)
    return np.array(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ]
    )


def quat_from_rotvec(rotation_vector: ArrayLike) -> FloatArray:
    """Unit quaternion of an axis-angle vector (axis times angle in rad)."""
    x, y, z = np.asarray(rotation_vector, dtype=float).tolist()
    theta = math.sqrt(x * x + y * y + z * z)
    scale = 0.5 - theta**2 / 48.0 if theta < _SMALL_ANGLE_RAD else math.sin(0.5 * theta) / theta
    return np.array([math.cos(0.5 * theta), scale * x, scale * y, scale * z])


def matrix_from_quat(quaternion: ArrayLike) -> FloatArray:
    """Rotation matrix of a quaternion (normalised first)."""
    w, x, y, z = quat_normalize(quaternion)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def quat_from_matrix(rotation: ArrayLike) -> FloatArray:
    """Unit quaternion (w >= 0) of a rotation matrix, by Shepperd's method: start from the
    largest of the four squared components so the divisions are well conditioned."""
    m = np.asarray(rotation, dtype=float)
    trace = float(np.trace(m))
    case = int(np.argmax([trace, m[0, 0], m[1, 1], m[2, 2]]))
    if case == 0:
        s = 2.0 * np.sqrt(1.0 + trace)
        q = np.array([0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s])
    else:
        i = case - 1
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(max(1.0 + m[i, i] - m[j, j] - m[k, k], 0.0))
        q = np.empty(4)
        q[0] = (m[k, j] - m[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (m[j, i] + m[i, j]) / s
        q[1 + k] = (m[k, i] + m[i, k]) / s
    return quat_normalize(q)
