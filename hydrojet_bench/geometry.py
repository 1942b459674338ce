"""Rotations, rigid transforms and the rotation-error measures of the bench.

Conventions, stated once for the whole project:

* Quaternions are scalar-first, ``(w, x, y, z)``, unit norm, and represent the rotation
  that maps vectors from the rotated (body) frame into the reference frame, like the
  matching rotation matrix ``R``: ``v_ref = R @ v_body``.
* Twists and wrenches are 6-vectors with the linear part first: twist ``(v, omega)``,
  wrench ``(force, moment)``, as in Murray, Li and Sastry (the paper's reference [27]).
* Homogeneous transforms ``g`` are 4x4 arrays ``[[R, p], [0, 1]]``; ``g_a_in_b`` maps
  frame-a coordinates into frame b.

Functions accept a single item or a stack with leading batch dimensions where noted.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

# Below this rotation angle (rad) the series forms are used: the closed forms divide by
# sin(theta) or theta^2 and lose all precision near zero.
_SMALL_ANGLE_RAD = 1e-6


def hat(vector: ArrayLike) -> FloatArray:
    """Skew-symmetric matrix of a 3-vector (or a stack ``(..., 3)``): ``hat(a) @ b = a x b``."""
    v = np.asarray(vector, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def vee(matrix: ArrayLike) -> FloatArray:
    """Inverse of `hat`: the 3-vector of a (nearly) skew-symmetric matrix, antisymmetrised."""
    m = np.asarray(matrix, dtype=float)
    return 0.5 * np.stack(
        [m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]],
        axis=-1,
    )


def so3_exp(rotation_vector: ArrayLike) -> FloatArray:
    """Rotation matrix of an axis-angle vector (rad), Rodrigues' formula; stacks allowed."""
    w = np.asarray(rotation_vector, dtype=float)
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    small = theta < _SMALL_ANGLE_RAD
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    w_hat = hat(w)
    return np.eye(3) + a * w_hat + b * (w_hat @ w_hat)


def so3_log(rotation: ArrayLike) -> FloatArray:
    """Axis-angle vector (rad, angle in [0, pi]) of a rotation matrix; via the quaternion,
    which stays accurate near both 0 and pi where the trace formula does not."""
    return rotvec_from_quat(quat_from_matrix(rotation))


def se3(rotation: ArrayLike, translation: ArrayLike) -> FloatArray:
    """4x4 homogeneous transform from a rotation matrix and a translation (m)."""
    g = np.eye(4)
    g[:3, :3] = rotation
    g[:3, 3] = translation
    return g


def se3_inverse(transform: ArrayLike) -> FloatArray:
    """Inverse of a homogeneous transform without a general matrix inversion."""
    g = np.asarray(transform, dtype=float)
    rotation_t = g[:3, :3].T
    return se3(rotation_t, -rotation_t @ g[:3, 3])


def twist_hat(twist: ArrayLike) -> FloatArray:
    """4x4 se(3) matrix of a twist ``(v, omega)``."""
    xi = np.asarray(twist, dtype=float)
    out = np.zeros((4, 4))
    out[:3, :3] = hat(xi[3:])
    out[:3, 3] = xi[:3]
    return out


def twist_vee(matrix: ArrayLike) -> FloatArray:
    """Twist ``(v, omega)`` of a 4x4 se(3) matrix (the rotation block is antisymmetrised)."""
    m = np.asarray(matrix, dtype=float)
    return np.concatenate([m[:3, 3], vee(m[:3, :3])])


def se3_exp(twist: ArrayLike) -> FloatArray:
    """Exponential of a twist ``(v, omega)``: the rigid motion after unit time."""
    xi = np.asarray(twist, dtype=float)
    v, w = xi[:3], xi[3:]
    theta = float(np.linalg.norm(w))
    w_hat = hat(w)
    if theta < _SMALL_ANGLE_RAD:
        left_jacobian = np.eye(3) + 0.5 * w_hat + w_hat @ w_hat / 6.0
    else:
        left_jacobian = (
            np.eye(3)
            + (1.0 - np.cos(theta)) / theta**2 * w_hat
            + (theta - np.sin(theta)) / theta**3 * (w_hat @ w_hat)
        )
    return se3(so3_exp(w), left_jacobian @ v)


def se3_log(transform: ArrayLike) -> FloatArray:
    """Twist ``(v, omega)`` whose exponential is the given transform."""
    g = np.asarray(transform, dtype=float)
    w = so3_log(g[:3, :3])
    theta = float(np.linalg.norm(w))
    w_hat = hat(w)
    if theta < _SMALL_ANGLE_RAD:
        inverse_left_jacobian = np.eye(3) - 0.5 * w_hat + w_hat @ w_hat / 12.0
    else:
        half = 0.5 * theta
        coefficient = (1.0 - half * np.cos(half) / np.sin(half)) / theta**2
        inverse_left_jacobian = np.eye(3) - 0.5 * w_hat + coefficient * (w_hat @ w_hat)
    return np.concatenate([inverse_left_jacobian @ g[:3, 3], w])


def adjoint(transform: ArrayLike) -> FloatArray:
    """6x6 adjoint of ``g`` for twists ``(v, omega)``: ``Ad_g xi = (g xi^ g^-1)^vee``."""
    g = np.asarray(transform, dtype=float)
    rotation, translation = g[:3, :3], g[:3, 3]
    out = np.zeros((6, 6))
    out[:3, :3] = rotation
    out[:3, 3:] = hat(translation) @ rotation
    out[3:, 3:] = rotation
    return out


# --- quaternions (w, x, y, z) -------------------------------------------------------


def quat_normalize(quaternion: ArrayLike) -> FloatArray:
    """Unit quaternion with a non-negative scalar part (one representative of +-q)."""
    q = np.asarray(quaternion, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0.0, -q, q)


def quat_conjugate(quaternion: ArrayLike) -> FloatArray:
    """Conjugate (the inverse rotation for a unit quaternion)."""
    q = np.asarray(quaternion, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_multiply(left: ArrayLike, right: ArrayLike) -> FloatArray:
    """Hamilton product ``left * right`` (apply ``right`` first, then ``left``); stacks broadcast."""
    a = np.asarray(left, dtype=float)
    b = np.asarray(right, dtype=float)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_rotate(quaternion: ArrayLike, vector: ArrayLike) -> FloatArray:
    """Rotate vectors by unit quaternions (``R(q) @ v``); stacks broadcast."""
    q = np.asarray(quaternion, dtype=float)
    v = np.asarray(vector, dtype=float)
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def matrix_from_quat(quaternion: ArrayLike) -> FloatArray:
    """Rotation matrix (or stack) of unit quaternion(s)."""
    q = quat_normalize(quaternion)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def quat_from_matrix(rotation: ArrayLike) -> FloatArray:
    """Unit quaternion (w >= 0) of a rotation matrix (or stack), by Shepperd's method:
    pick the largest of the four squared components so the division is well conditioned."""
    m = np.asarray(rotation, dtype=float)
    batch = m.shape[:-2]
    flat = np.ascontiguousarray(m.reshape(-1, 3, 3))
    q = np.empty((flat.shape[0], 4))
    _shepperd(flat, q)
    return q.reshape(batch + (4,))


# Compiled: a diagnosis turns about 15,000 predicted rotations into quaternions one at
# a time, and numpy's per-call overhead made that 25 us each (0.4 s of 3.5 s on one
# worker).
@njit(cache=True)
def _shepperd(m, out):
    for n in range(m.shape[0]):
        r = m[n]
        trace = r[0, 0] + r[1, 1] + r[2, 2]
        case = 0
        largest = trace
        for i in range(3):
            if r[i, i] > largest:
                largest = r[i, i]
                case = i + 1
        if case == 0:
            s = 2.0 * np.sqrt(1.0 + trace)
            w, x, y, z = 0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s
        else:
            i = case - 1
            j, k = (i + 1) % 3, (i + 2) % 3
            s = 2.0 * np.sqrt(max(1.0 + r[i, i] - r[j, j] - r[k, k], 0.0))
            v = np.empty(3)
            v[i] = 0.25 * s
            v[j] = (r[j, i] + r[i, j]) / s
            v[k] = (r[k, i] + r[i, k]) / s
            w, x, y, z = (r[k, j] - r[j, k]) / s, v[0], v[1], v[2]
        norm = np.sqrt(w * w + x * x + y * y + z * z)
        if w < 0.0:
            norm = -norm
        out[n, 0] = w / norm
        out[n, 1] = x / norm
        out[n, 2] = y / norm
        out[n, 3] = z / norm


def quat_from_rotvec(rotation_vector: ArrayLike) -> FloatArray:
    """Unit quaternion of an axis-angle vector (rad); stacks allowed."""
    w = np.asarray(rotation_vector, dtype=float)
    theta = np.linalg.norm(w, axis=-1, keepdims=True)
    small = theta < _SMALL_ANGLE_RAD
    safe = np.where(small, 1.0, theta)
    scale = np.where(small, 0.5 - theta**2 / 48.0, np.sin(0.5 * safe) / safe)
    return np.concatenate([np.cos(0.5 * theta), scale * w], axis=-1)


def rotvec_from_quat(quaternion: ArrayLike) -> FloatArray:
    """Axis-angle vector (rad, angle in [0, pi]) of a quaternion (or stack); uses atan2 so
    it is accurate for small and near-pi angles alike."""
    q = np.asarray(quaternion, dtype=float)
    flat = np.ascontiguousarray(q.reshape(-1, 4))
    out = np.empty((flat.shape[0], 3))
    _rotvec_rows(flat, out)
    return out.reshape(q.shape[:-1] + (3,))


# Compiled for the same reason as `_shepperd`: a calibration takes the logarithm of 40
# rotations some hundred times, and numpy's per-call overhead made each stack 40 us.
# error_model="numpy": a zero quaternion gives NaN, as numpy's division does, not an exception.
@njit(cache=True, error_model="numpy")
def _rotvec_rows(q, out):
    for n in range(q.shape[0]):
        w, x, y, z = q[n, 0], q[n, 1], q[n, 2], q[n, 3]
        norm = np.sqrt(w * w + x * x + y * y + z * z)
        if w < 0.0:
            norm = -norm  # the representative with w >= 0
        w, x, y, z = w / norm, x / norm, y / norm, z / norm
        sin_half = np.sqrt(x * x + y * y + z * z)
        if sin_half < 0.5 * _SMALL_ANGLE_RAD:
            scale = 2.0 / max(w, 1e-300)
        else:
            scale = 2.0 * np.arctan2(sin_half, w) / sin_half
        out[n, 0] = scale * x
        out[n, 1] = scale * y
        out[n, 2] = scale * z


# --- rotation-error measures --------------------------------------------------------


def rotation_angle_deg(quat_a: ArrayLike, quat_b: ArrayLike) -> FloatArray:
    """Angle (degrees, in [0, 180]) of the rotation taking orientation ``a`` to ``b``.

    This is the error the bench reports: independent of frame and of the sign of q."""
    return np.degrees(2.0 * np.arccos(_abs_cosine_of_half_angle(quat_a, quat_b)))


def quaternion_inner_product_metric(quat_a: ArrayLike, quat_b: ArrayLike) -> FloatArray:
    """The paper's calibration metric (eq. 24, after Huynh 2009's Phi_4): ``1 - |<q_a, q_b>|``.

    Zero for equal rotations, 1 for a half turn; equals ``1 - cos(theta / 2)``, about
    ``theta^2 / 8`` for a small relative angle ``theta`` (rad). Eq. 24 prints the bare
    inner product, which a minimiser would drive towards orthogonal quaternions; Huynh's
    metric, which the paper cites, is what is meant."""
    return 1.0 - _abs_cosine_of_half_angle(quat_a, quat_b)


def _abs_cosine_of_half_angle(quat_a: ArrayLike, quat_b: ArrayLike) -> FloatArray:
    """|<q_a, q_b>| of the normalised quaternions, clipped to [0, 1]: the sign of either
    does not matter, so they are not made w >= 0 first."""
    a = np.asarray(quat_a, dtype=float)
    b = np.asarray(quat_b, dtype=float)
    dot = np.abs(np.sum(a * b, axis=-1)) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.clip(dot, 0.0, 1.0)


def body_rotation_error(rotation_estimated: ArrayLike, rotation_measured: ArrayLike) -> FloatArray:
    """Axis-angle vector (rad), in the estimated body frame, of the rotation that takes the
    estimated orientation to the measured one: ``log(R_est^T R_meas)``. This is the
    ``omega_des`` of the paper's eq. 4."""
    r_est = np.asarray(rotation_estimated, dtype=float)
    r_meas = np.asarray(rotation_measured, dtype=float)
    return so3_log(np.swapaxes(r_est, -1, -2) @ r_meas)


def position_error_mm(predicted_m: ArrayLike, measured_m: ArrayLike) -> FloatArray:
    """Distance (mm) between predicted and measured positions given in m, one (3,) pair
    or stacks ``(..., 3)``: the paper's ||epsilon||_2."""
    return np.linalg.norm(np.asarray(predicted_m, dtype=float) - np.asarray(measured_m, dtype=float), axis=-1) * 1e3
