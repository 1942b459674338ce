"""One sensor's state on the twin's settling law at one instant or a run of them, compiled.

The emulated IMUs ask the twin for the truth at every sample of every chip (thousands
of times per wall second on a fast simulated rig); the vectorised path over stacks of
times (`DigitalTwin._poses_in_segment`) costs ~0.1 ms per single instant in numpy
overhead alone, this kernel a few microseconds. Same law and conventions:
R = R_eq exp(e phi) as a unit quaternion (w, x, y, z) with w >= 0, p = p_eq + e offset.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..geometry import _SMALL_ANGLE_RAD


@njit(cache=True, inline="always")
def _settle_into(target_orientation: np.ndarray, rotation_offset_rad: np.ndarray, target_position_m: np.ndarray,
                 position_offset_m: np.ndarray, sensor: int, decay: float, time_constant_s: float, q: np.ndarray,
                 p: np.ndarray, omega: np.ndarray, acceleration: np.ndarray) -> None:
    """The law at one settling factor, written into ``q`` (4,), ``p``, ``omega`` and
    ``acceleration`` (3,): what both kernels below compute, once."""
    rx = decay * rotation_offset_rad[sensor, 0]
    ry = decay * rotation_offset_rad[sensor, 1]
    rz = decay * rotation_offset_rad[sensor, 2]
    theta = math.sqrt(rx * rx + ry * ry + rz * rz)
    if theta < _SMALL_ANGLE_RAD:
        scale = 0.5 - theta * theta / 48.0
    else:
        scale = math.sin(0.5 * theta) / theta
    bw, bx, by, bz = math.cos(0.5 * theta), scale * rx, scale * ry, scale * rz
    aw, ax = target_orientation[sensor, 0], target_orientation[sensor, 1]
    ay, az = target_orientation[sensor, 2], target_orientation[sensor, 3]
    q[0] = aw * bw - ax * bx - ay * by - az * bz
    q[1] = aw * bx + ax * bw + ay * bz - az * by
    q[2] = aw * by - ax * bz + ay * bw + az * bx
    q[3] = aw * bz + ax * by - ay * bx + az * bw
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    sign = -1.0 if q[0] < 0.0 else 1.0
    for k in range(4):
        q[k] *= sign / norm
    # decay = exp(-t / tau): its rate is -decay / tau, its second derivative decay / tau^2.
    rate = -decay / time_constant_s if time_constant_s > 0.0 else 0.0
    curvature = decay / time_constant_s**2 if time_constant_s > 0.0 else 0.0
    for axis in range(3):
        p[axis] = target_position_m[sensor, axis] + decay * position_offset_m[sensor, axis]
        omega[axis] = rate * rotation_offset_rad[sensor, axis]
        acceleration[axis] = curvature * position_offset_m[sensor, axis]


# Compiled eagerly for any array layout (the segments' arrays may be views of differing
# layouts): a new layout met during a session would otherwise be compiled then, holding
# the GIL for a second while the valve heartbeat waits.
@njit("Tuple((float64[::1], float64[::1], float64[::1], float64[::1]))(float64[:, :], float64[:, :], "
      "float64[:, :], float64[:, :], int64, float64, float64)", cache=True)
def settling_state(target_orientation: np.ndarray, rotation_offset_rad: np.ndarray, target_position_m: np.ndarray,
                   position_offset_m: np.ndarray, sensor: int, decay: float,
                   time_constant_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sensor ``sensor``'s (row of the segment's (2, .) arrays) orientation (4,),
    position (3,) (m), angular velocity (3,) (rad/s, sensor frame) and linear
    acceleration (3,) (m/s^2, tracker frame) at settling factor ``decay`` (1 at the
    command, 0 settled) of first-order settling with ``time_constant_s`` (0: it jumps,
    and is never seen moving). Offsets as in the twin's segments (sensor frame, rad; m)."""
    q, p, omega, acceleration = np.empty(4), np.empty(3), np.empty(3), np.empty(3)
    _settle_into(target_orientation, rotation_offset_rad, target_position_m, position_offset_m, sensor, decay,
                 time_constant_s, q, p, omega, acceleration)
    return q, p, omega, acceleration


@njit("void(float64[:, :], float64[:, :], float64[:, :], float64[:, :], int64, float64[::1], float64, "
      "float64[:, ::1], float64[:, ::1], float64[:, ::1], float64[:, ::1])", cache=True)
def settling_states_into(target_orientation: np.ndarray, rotation_offset_rad: np.ndarray,
                         target_position_m: np.ndarray, position_offset_m: np.ndarray, sensor: int,
                         decays: np.ndarray, time_constant_s: float, orientations: np.ndarray,
                         positions_m: np.ndarray, angular_velocities_rad_s: np.ndarray,
                         accelerations_m_s2: np.ndarray) -> None:
    """`settling_state` at each of ``decays`` (n,), written into row i of the (n, 4) and
    (n, 3) outputs: an emulated IMU's FIFO asks for a run of instants at once."""
    for i in range(decays.shape[0]):
        _settle_into(target_orientation, rotation_offset_rad, target_position_m, position_offset_m, sensor,
                     decays[i], time_constant_s, orientations[i], positions_m[i], angular_velocities_rad_s[i],
                     accelerations_m_s2[i])
