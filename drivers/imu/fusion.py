"""Orientation of one IMU from its calibrated samples, behind one seam (`FusionCore`),
with two implementations chosen by name (`make_core`):

- "madgwick": `ahrs.filters.Madgwick` (ahrs 0.4.x): `updateMARG(q, gyr, acc, mag, dt=None)` /
  `updateIMU(q, gyr, acc, dt=None)`, gyro in rad/s, accelerometer and magnetometer used
  only by direction.
- "imufusion": x-io's Fusion (`imufusion` 1.3.x), Madgwick's revised AHRS with magnetic
  rejection (its acceleration rejection is left off, see `IMUFUSION_*`): `Ahrs.update(gyr, acc, mag)` with gyro in deg/s,
  accelerometer in g, `set_sample_period(dt)`, `set_quaternion`, `skip_startup`.

Both earth frames have z up and x along the horizontal part of the magnetic field (Fusion's
"NWU" convention); both quaternions (w, x, y, z) map sensor-frame vectors into that
frame, the same convention as `drivers.rotations`. The default is the winner of the
benchmark in docs/imu-fusion.md (`drivers.imu.fusion_benchmark`).

A filter corrects only at its gain's rate, so starting from identity a 30 degree tilt
would take seconds to converge; the first sample instead sets the orientation from
gravity and the field directly (TRIAD).
"""

from __future__ import annotations

from collections import deque

from collections.abc import Sequence
from typing import Literal, Protocol

import imufusion
import numpy as np
from ahrs.filters import Madgwick

from drivers.imu.calibration import ImuSample
from drivers.imu.registers import DEG_TO_RAD, STANDARD_GRAVITY_M_S2
from drivers.rotations import quat_conjugate, quat_from_matrix, quat_multiply, quat_normalize

FusionName = Literal["madgwick", "imufusion"]
FUSION_NAMES: tuple[FusionName, ...] = ("madgwick", "imufusion")
# Measured in docs/imu-fusion.md: 0.0 deg of tilt leaked from a 15 uT disturbance against
# Madgwick's several degrees, about 20x cheaper per update.
DEFAULT_FUSION: FusionName = "imufusion"
# ahrs' default MARG gain (Madgwick's beta), rad/s.
DEFAULT_GAIN = 0.041
# Fusion's recommended gain (x-io Fusion README) and magnetic rejection threshold. The
# rejection timeout is longer than its README's 5 s so that a 15 s magnetic disturbance is
# ridden out on the (bias-corrected) gyro instead of being accepted. Acceleration
# rejection is off: on the imu-vs-em plan at the simulated rig's 10 Hz, a fast move put
# the estimate more than 10 degrees off gravity, the accelerometer was then ignored for the
# whole timeout and holds read up to 48 degrees wrong (18.8 degrees RMS against EM, 3.3
# without rejection; docs/imu-fusion.md).
IMUFUSION_GAIN = 0.5
IMUFUSION_MAGNETIC_REJECTION_DEG = 10.0
IMUFUSION_REJECTION_TIMEOUT_S = 20.0
# A gap of more than this many sample periods restarts the filter from gravity and the
# field: the orientation integrated over the gap from one gyro sample is not to be trusted.
MAX_GAP_PERIODS = 5


class FusionCore(Protocol):
    """One IMU's orientation filter, stepped one sample at a time. Quaternions (w, x, y, z)
    map the IMU frame into the earth frame (z up, x towards the horizontal field)."""

    def seed(self, quaternion: np.ndarray) -> None:
        """Start from this orientation, converged (no start-up transient)."""
        ...

    def step(self, gyro_rad_s: Sequence[float], accel_m_s2: Sequence[float], mag_ut: Sequence[float] | None,
             dt_s: float) -> np.ndarray:
        """Fuse one sample taken dt_s after the previous one; returns the orientation."""
        ...


class MadgwickCore:
    """`ahrs`' Madgwick filter; gain is beta (rad/s)."""

    def __init__(self, sample_rate_hz: float, gain: float = DEFAULT_GAIN) -> None:
        self._filter = Madgwick(frequency=float(sample_rate_hz), gain=float(gain))
        self._q = np.array([1.0, 0.0, 0.0, 0.0])

    def seed(self, quaternion: np.ndarray) -> None:
        self._q = quat_normalize(quaternion)

    def step(self, gyro_rad_s: Sequence[float], accel_m_s2: Sequence[float], mag_ut: Sequence[float] | None,
             dt_s: float) -> np.ndarray:
        gyro_rad_s = np.asarray(gyro_rad_s, dtype=float)
        accel_m_s2 = np.asarray(accel_m_s2, dtype=float)
        if mag_ut is not None:
            q = self._filter.updateMARG(self._q, gyro_rad_s, accel_m_s2, np.asarray(mag_ut, dtype=float), dt=dt_s)
        else:
            q = self._filter.updateIMU(self._q, gyro_rad_s, accel_m_s2, dt=dt_s)
        self._q = quat_normalize(np.asarray(q, dtype=float))
        return self._q


class ImufusionCore:
    """x-io's Fusion AHRS (`imufusion`), NWU earth frame, with magnetic rejection
    (`IMUFUSION_*`)."""

    def __init__(self, sample_rate_hz: float, gain: float = IMUFUSION_GAIN) -> None:
        self._ahrs = imufusion.Ahrs()
        self._ahrs.set_settings(imufusion.AhrsSettings(
            sample_rate=float(sample_rate_hz),
            convention=imufusion.CONVENTION_NWU,
            gain=float(gain),
            gyroscope_range=0.0,  # no over-range recovery: the driver's ranges are not known here
            acceleration_rejection=0.0,  # off, see IMUFUSION_MAGNETIC_REJECTION_DEG
            magnetic_rejection=IMUFUSION_MAGNETIC_REJECTION_DEG,
            rejection_timeout=IMUFUSION_REJECTION_TIMEOUT_S,  # seconds in imufusion 1.3 (measured)
        ))
        self._dt_s = 1.0 / sample_rate_hz
        self._ahrs.set_sample_period(self._dt_s)

    def seed(self, quaternion: np.ndarray) -> None:
        self._ahrs.set_quaternion(np.asarray(quat_normalize(quaternion), dtype=float))
        self._ahrs.skip_startup()

    def step(self, gyro_rad_s: Sequence[float], accel_m_s2: Sequence[float], mag_ut: Sequence[float] | None,
             dt_s: float) -> np.ndarray:
        if dt_s != self._dt_s:
            self._dt_s = dt_s
            self._ahrs.set_sample_period(dt_s)
        # Scaled in Python as each array is made: imufusion's own update takes 2 us, and
        # numpy's per-call cost on 3-vectors (asarray, then a division) was as much again.
        gx, gy, gz = gyro_rad_s
        ax, ay, az = accel_m_s2
        gyro_dps = np.array((gx / DEG_TO_RAD, gy / DEG_TO_RAD, gz / DEG_TO_RAD))
        accel_g = np.array((ax / STANDARD_GRAVITY_M_S2, ay / STANDARD_GRAVITY_M_S2, az / STANDARD_GRAVITY_M_S2))
        if mag_ut is not None:
            self._ahrs.update(gyro_dps, accel_g, np.array(mag_ut, dtype=float))
        else:
            self._ahrs.update_no_magnetometer(gyro_dps, accel_g)
        return self._ahrs.get_quaternion()


def make_core(name: FusionName, sample_rate_hz: float, *, madgwick_gain: float = DEFAULT_GAIN) -> FusionCore:
    """The filter called `name` ("madgwick" or "imufusion") for samples at sample_rate_hz."""
    if name == "madgwick":
        return MadgwickCore(sample_rate_hz, madgwick_gain)
    if name == "imufusion":
        return ImufusionCore(sample_rate_hz)
    raise ValueError(f"fusion must be one of {', '.join(FUSION_NAMES)}, got {name!r}")


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
    """One IMU's filter (`make_core(fusion, ...)`) with its seeding and time steps.
    sample_rate_hz sets the default step; gain is Madgwick's beta (rad/s, "madgwick" only);
    use_magnetometer=False fuses gyro and accelerometer only (heading drifts)."""

    def __init__(self, sample_rate_hz: float, *, fusion: FusionName = DEFAULT_FUSION, gain: float = DEFAULT_GAIN,
                 use_magnetometer: bool = True) -> None:
        if not sample_rate_hz > 0:
            raise ValueError(f"sample_rate_hz must be positive, got {sample_rate_hz!r}")
        if not gain > 0:
            raise ValueError(f"gain must be positive, got {gain!r}")
        self._core = make_core(fusion, float(sample_rate_hz), madgwick_gain=float(gain))
        self.fusion = fusion
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
            self._core.seed(self.quaternion)
            self._last_t_s = sample.t_s
            return self.quaternion.copy()
        dt = self.default_dt_s
        if self._last_t_s is not None and sample.t_s > self._last_t_s:
            dt = sample.t_s - self._last_t_s
        self._last_t_s = sample.t_s
        self.quaternion = quat_normalize(self._core.step(sample.gyro_rad_s, sample.accel_m_s2, mag, dt))
        return self.quaternion.copy()


class ImuPairFusion:
    """Base and tip filters and the tip-relative-to-base orientation."""

    def __init__(self, sample_rate_hz: float, *, fusion: FusionName = DEFAULT_FUSION, gain: float = DEFAULT_GAIN,
                 use_magnetometer: bool = True) -> None:
        self.base = ImuOrientationFilter(sample_rate_hz, fusion=fusion, gain=gain, use_magnetometer=use_magnetometer)
        self.tip = ImuOrientationFilter(sample_rate_hz, fusion=fusion, gain=gain, use_magnetometer=use_magnetometer)

    def update(self, base: ImuSample, tip: ImuSample) -> np.ndarray:
        """Fuse one sample of each; returns q_base^-1 * q_tip (w, x, y, z)."""
        return tip_relative_to_base(self.base.update(base), self.tip.update(tip))


def paired_samples(base: deque[ImuSample], tip: deque[ImuSample], period_s: float) -> list[tuple[ImuSample, ImuSample]]:
    """Pop base/tip pairs sampled within half a period (s) of each other, oldest first.
    A sample whose partner was lost (a FIFO overflow on one chip) is dropped; a sample
    whose partner has not been read yet stays queued."""
    pairs = []
    while base and tip:
        gap_s = tip[0].t_s - base[0].t_s
        if gap_s > 0.5 * period_s:
            base.popleft()
        elif gap_s < -0.5 * period_s:
            tip.popleft()
        else:
            pairs.append((base.popleft(), tip.popleft()))
    return pairs
