"""Orientation from calibrated IMU samples with `ahrs.filters.Madgwick` (ahrs 0.4.x).

Checked against the installed ahrs: `Madgwick(frequency=..., gain=...)`,
`updateMARG(q, gyr, acc, mag, dt=None)` / `updateIMU(q, gyr, acc, dt=None)`; gyro in
rad/s, accelerometer and magnetometer used only by direction; quaternions scalar-first.
Its earth frame has z up (a resting accelerometer reads +z) and x along the horizontal
part of the magnetic field; its quaternion maps sensor-frame vectors into that frame,
the same convention as `drivers.rotations`.

The filter corrects only at rate `gain` (rad/s), so starting from identity a 30 degree
tilt would take ~10 s to converge; the first sample instead sets the orientation from
gravity and the field directly (TRIAD).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from ahrs.filters import Madgwick

from drivers.imu.calibration import ImuSample
from drivers.rotations import quat_conjugate, quat_from_matrix, quat_multiply, quat_normalize

# ahrs' default MARG gain (Madgwick's beta), rad/s.
DEFAULT_GAIN = 0.041
# A gap of more than this many sample periods restarts the filter from gravity and the
# field: the orientation integrated over the gap from one gyro sample is not to be trusted.
MAX_GAP_PERIODS = 5


def orientation_from_gravity_and_field(accel: Sequence[float], mag: Sequence[float] | None) -> np.ndarray:
    """Unit quaternion (w, x, y, z), sensor -> earth (z up, x towards the horizontal field;
    without a field, x is the sensor's x projected onto the horizontal plane)."""
    up = np.asarray(accel, dtype=float)
    norm = np.linalg.norm(up)
    if not np.isfinite(norm) or norm == 0.0:
        raise ValueError("accelerometer vector must be non-zero and finite to find 'up'")
    up = up / norm
    reference = np.asarray(mag, dtype=float) if mag is not None else np.array([1.0, 0.0, 0.0])
    west = np.cross(up, reference)
    if np.linalg.norm(west) < 1e-6:
        # field (or sensor x) parallel to gravity: any heading will do
        west = np.cross(up, np.array([0.0, 1.0, 0.0]) if abs(up[1]) < 0.9 else np.array([1.0, 0.0, 0.0]))
    west = west / np.linalg.norm(west)
    north = np.cross(west, up)
    # Rows are the earth axes in sensor coordinates, so this maps sensor -> earth.
    return quat_from_matrix(np.vstack([north, west, up]))


def tip_relative_to_base(q_base: Sequence[float], q_tip: Sequence[float]) -> np.ndarray:
    """q_base^-1 * q_tip: the tip IMU frame's orientation in the base IMU frame."""
    return quat_normalize(quat_multiply(quat_conjugate(q_base), q_tip))


class ImuOrientationFilter:
    """Madgwick filter for one IMU. sample_rate_hz sets the default step; gain is beta
    (rad/s); use_magnetometer=False fuses gyro and accelerometer only (heading drifts)."""

    def __init__(self, sample_rate_hz: float, *, gain: float = DEFAULT_GAIN, use_magnetometer: bool = True) -> None:
        if not sample_rate_hz > 0:
            raise ValueError(f"sample_rate_hz must be positive, got {sample_rate_hz!r}")
        if not gain > 0:
            raise ValueError(f"gain must be positive, got {gain!r}")
        self._filter = Madgwick(frequency=float(sample_rate_hz), gain=float(gain))
        self.default_dt_s = 1.0 / sample_rate_hz
        self.use_magnetometer = use_magnetometer
        self.quaternion: np.ndarray | None = None
        self._last_t_s: float | None = None

    def update(self, sample: ImuSample) -> np.ndarray:
        """Fuse one sample; returns the orientation (w, x, y, z), IMU frame -> earth.

        The step is the time since the previous sample (its t_s), falling back to the
        nominal period if the stamps are not increasing; after a gap of more than
        `MAX_GAP_PERIODS` periods the filter restarts from gravity and the field."""
        mag = sample.mag_ut if self.use_magnetometer else None
        stale = self._last_t_s is not None and sample.t_s - self._last_t_s > MAX_GAP_PERIODS * self.default_dt_s
        if self.quaternion is None or stale:
            # First sample, or after a gap: integrating the gyro's rate now over the whole
            # gap would turn one fast moment into a large, slowly corrected error.
            self.quaternion = orientation_from_gravity_and_field(sample.accel_m_s2, mag)
            self._last_t_s = sample.t_s
            return self.quaternion.copy()
        dt = self.default_dt_s
        if self._last_t_s is not None and sample.t_s > self._last_t_s:
            dt = sample.t_s - self._last_t_s
        self._last_t_s = sample.t_s
        gyro = np.asarray(sample.gyro_rad_s, dtype=float)
        accel = np.asarray(sample.accel_m_s2, dtype=float)
        if mag is not None:
            q = self._filter.updateMARG(self.quaternion, gyro, accel, np.asarray(mag, dtype=float), dt=dt)
        else:
            q = self._filter.updateIMU(self.quaternion, gyro, accel, dt=dt)
        self.quaternion = quat_normalize(np.asarray(q, dtype=float))
        return self.quaternion.copy()


class ImuPairFusion:
    """Base and tip filters and the tip-relative-to-base orientation."""

    def __init__(self, sample_rate_hz: float, *, gain: float = DEFAULT_GAIN, use_magnetometer: bool = True) -> None:
        self.base = ImuOrientationFilter(sample_rate_hz, gain=gain, use_magnetometer=use_magnetometer)
        self.tip = ImuOrientationFilter(sample_rate_hz, gain=gain, use_magnetometer=use_magnetometer)

    def update(self, base: ImuSample, tip: ImuSample) -> np.ndarray:
        """Fuse one sample of each; returns q_base^-1 * q_tip (w, x, y, z)."""
        return tip_relative_to_base(self.base.update(base), self.tip.update(tip))
