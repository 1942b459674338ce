"""Calibration of one IMU: gyro bias, magnetometer hard iron and soft iron.

All vectors are in the ICM-20948 accel/gyro frame (see `codec`). The corrections are

    gyro_corrected = gyro_raw - gyro_bias_rad_s
    mag_corrected  = mag_soft_iron @ (mag_raw - mag_hard_iron_ut)

`mag_soft_iron` is the correction matrix (the inverse of the distortion the soft iron
causes), as an ellipsoid fit delivers it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from drivers.imu.codec import RawImuSample, Vector3
from drivers.imu.errors import ImuMotionError

Matrix3 = tuple[Vector3, Vector3, Vector3]
_IDENTITY: Matrix3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
# A soft-iron correction that shrinks or stretches any axis more than this is a fit gone
# wrong rather than a distortion (ferrous material near a sensor gives tens of percent).
_MAX_SOFT_IRON_CONDITION = 100.0


def _vector(name: str, value: object) -> Vector3:
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be three finite numbers, got {value!r}") from None
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be three finite numbers, got {value!r}")
    return (float(array[0]), float(array[1]), float(array[2]))


@dataclass(frozen=True)
class ImuCalibration:
    """Corrections for one IMU (frame: accel/gyro axes).

    gyro_bias_rad_s: subtracted from the gyro (rad/s).
    mag_hard_iron_ut: subtracted from the magnetometer (uT).
    mag_soft_iron: 3x3 matrix applied after the offset; finite, determinant > 0 (a
        reflection would mean a sign error) and condition number <= 100.
    Any sequence is accepted and stored as tuples; a bad value raises ValueError naming
    the field.
    """

    gyro_bias_rad_s: Vector3 = (0.0, 0.0, 0.0)
    mag_hard_iron_ut: Vector3 = (0.0, 0.0, 0.0)
    mag_soft_iron: Matrix3 = field(default=_IDENTITY)

    def __post_init__(self) -> None:
        object.__setattr__(self, "gyro_bias_rad_s", _vector("gyro_bias_rad_s", self.gyro_bias_rad_s))
        object.__setattr__(self, "mag_hard_iron_ut", _vector("mag_hard_iron_ut", self.mag_hard_iron_ut))
        try:
            matrix = np.asarray(self.mag_soft_iron, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"mag_soft_iron must be a 3x3 matrix, got {self.mag_soft_iron!r}") from None
        if matrix.shape != (3, 3) or not np.all(np.isfinite(matrix)):
            raise ValueError(f"mag_soft_iron must be a finite 3x3 matrix, got {self.mag_soft_iron!r}")
        if np.linalg.det(matrix) <= 0.0:
            raise ValueError("mag_soft_iron must have a positive determinant (no reflection, not singular)")
        if np.linalg.cond(matrix) > _MAX_SOFT_IRON_CONDITION:
            raise ValueError(
                f"mag_soft_iron is ill-conditioned (condition number {np.linalg.cond(matrix):.3g} > "
                f"{_MAX_SOFT_IRON_CONDITION:g})"
            )
        object.__setattr__(self, "mag_soft_iron", tuple(tuple(float(v) for v in row) for row in matrix))

    def apply(self, raw: RawImuSample, t_s: float) -> ImuSample:
        """The calibrated sample of a raw one, stamped with host time t_s (s): the module's
        two corrections, on the fields' plain floats (numpy's per-call cost on 3-vectors
        was most of a sample's decode, at 200 samples a second, 25 times that on the
        simulated rig)."""
        bx, by, bz = self.gyro_bias_rad_s
        gx, gy, gz = raw.gyro_rad_s
        mag = None
        if raw.mag_ut is not None:
            hx, hy, hz = self.mag_hard_iron_ut
            (s00, s01, s02), (s10, s11, s12), (s20, s21, s22) = self.mag_soft_iron
            mx, my, mz = raw.mag_ut
            mx, my, mz = mx - hx, my - hy, mz - hz
            mag = (s00 * mx + s01 * my + s02 * mz, s10 * mx + s11 * my + s12 * mz, s20 * mx + s21 * my + s22 * mz)
        return ImuSample(
            t_s=t_s,
            accel_m_s2=raw.accel_m_s2,
            gyro_rad_s=(gx - bx, gy - by, gz - bz),
            mag_ut=mag,
            temperature_degc=raw.temperature_degc,
            mag_data_ready=raw.mag_data_ready,
        )


def _tuple3(array: np.ndarray) -> Vector3:
    return (float(array[0]), float(array[1]), float(array[2]))


@dataclass(frozen=True)
class ImuSample:
    """A calibrated sample (accel/gyro frame).

    t_s: host clock when the burst was read (s); accel_m_s2 (m/s^2); gyro_rad_s (rad/s,
    bias removed); mag_ut (uT, hard/soft iron corrected; None when the magnetometer
    overflowed); temperature_degc; mag_data_ready: the magnetometer value is new."""

    t_s: float
    accel_m_s2: Vector3
    gyro_rad_s: Vector3
    mag_ut: Vector3 | None
    temperature_degc: float
    mag_data_ready: bool


@dataclass(frozen=True)
class GyroBiasEstimate:
    """Result of a rest measurement: mean and per-axis standard deviation of the gyro
    (rad/s), the accelerometer's per-axis standard deviation (m/s^2), and the count."""

    bias_rad_s: Vector3
    gyro_std_rad_s: Vector3
    accel_std_m_s2: Vector3
    sample_count: int


def estimate_gyro_bias(
    samples: Sequence[RawImuSample],
    *,
    max_gyro_std_rad_s: float = 0.01,
    max_accel_std_m_s2: float = 0.2,
    min_samples: int = 10,
    address: int | None = None,
) -> GyroBiasEstimate:
    """Gyro bias as the mean of samples taken at rest.

    Rejects (ImuMotionError) when any axis's gyro standard deviation exceeds
    max_gyro_std_rad_s or the accelerometer's exceeds max_accel_std_m_s2: the sensor
    moved, and a mean over motion is not a bias. The defaults sit well above the
    ICM-20948's noise (about 0.1 deg/s = 0.002 rad/s rms) and well below a hand's tremor.
    """
    if len(samples) < min_samples:
        raise ValueError(f"need at least {min_samples} samples, got {len(samples)}")
    if not (math.isfinite(max_gyro_std_rad_s) and max_gyro_std_rad_s > 0):
        raise ValueError(f"max_gyro_std_rad_s must be positive, got {max_gyro_std_rad_s!r}")
    if not (math.isfinite(max_accel_std_m_s2) and max_accel_std_m_s2 > 0):
        raise ValueError(f"max_accel_std_m_s2 must be positive, got {max_accel_std_m_s2!r}")
    gyro = np.array([s.gyro_rad_s for s in samples])
    accel = np.array([s.accel_m_s2 for s in samples])
    gyro_std = gyro.std(axis=0, ddof=1)
    accel_std = accel.std(axis=0, ddof=1)
    if np.any(gyro_std > max_gyro_std_rad_s):
        raise ImuMotionError(
            address,
            f"gyro std {np.round(gyro_std, 5).tolist()} rad/s exceeds {max_gyro_std_rad_s} rad/s "
            "(the sensor moved)",
        )
    if np.any(accel_std > max_accel_std_m_s2):
        raise ImuMotionError(
            address,
            f"accel std {np.round(accel_std, 4).tolist()} m/s^2 exceeds {max_accel_std_m_s2} m/s^2 "
            "(the sensor moved)",
        )
    return GyroBiasEstimate(
        bias_rad_s=_tuple3(gyro.mean(axis=0)),
        gyro_std_rad_s=_tuple3(gyro_std),
        accel_std_m_s2=_tuple3(accel_std),
        sample_count=len(samples),
    )
