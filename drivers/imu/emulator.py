"""Emulator of the bench's I2C bus: two ICM-20948s (0x68 base, 0x69 tip), each with an
AK09916 behind its auxiliary I2C master, speaking register for register.

`Icm20948BusEmulator` is a drop-in for `smbus2.SMBus`: the same method names and the same
limits (32-byte SMBus blocks, `OSError(EREMOTEIO)` for an address nobody acknowledges).
Per chip it models the four register banks and REG_BANK_SEL, reset and sleep, the gyro
and accel output data rates (GYRO_SMPLRT_DIV, ACCEL_SMPLRT_DIV_1/2), INT_STATUS_1's
raw-data-ready bit, the noise each DLPF setting lets through, read-to-clear
I2C_MST_STATUS, the FIFO (FIFO_EN_1/2, USER_CTRL.FIFO_EN, FIFO_RST, stream and snapshot
FIFO_MODE, FIFO_COUNTH/L, FIFO_R_W, INT_STATUS_2's overflow bit; one record per gyro
sample instant, so a host that reads late still gets every sample up to the FIFO's
512 bytes), and the auxiliary master on its own clock (LP_CONFIG.I2C_MST_CYC,
I2C_MST_ODR_CONFIG) or on the gyro's: SLV0 (repeated transfer, reads land in
EXT_SLV_SENS_DATA) and SLV4 (one transfer per enable, DONE / NACK status). The AK09916
model has WIA1/WIA2, power-down / single / continuous modes, DRDY and DOR, ST2 release
of the data registers, HOFL overflow, soft reset and the register auto-increment of its
datasheet. Not modelled: DMP, FIFO watermarks, interrupt pins, bank 1, SLV1-3, self-test, the
DLPF's delay (only its noise bandwidth).

Data come from the plant's truth at each sample instant (plant time = `clock()`):

    accel = S_a R^T (a_tracker - g_tracker) + noise           (specific force, m/s^2)
    gyro  = S_g omega_sensor + bias + drift + noise        (rad/s)
    mag   = M_soft R^T (B_tracker + disturbance) + hard + noise   (uT)

with R the IMU frame's orientation in the tracker frame (the plant sensor's orientation times the
optional mounting rotation), S the per-axis scale errors, all noise from one seeded
generator per chip. Noise is not optional in spirit: `ahrs`' Madgwick returns q
unchanged for a gyro of exactly zero, so a noiseless emulator would never converge.
"""

from __future__ import annotations

import ctypes
import errno as errno_codes
import math
import os
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from drivers.imu import registers as reg
from drivers.imu.codec import ImuRanges, Vector3, encode_ak09916_block, encode_motion
from drivers.plant import Plant, truths_at_instants
from drivers.rotations import matrix_from_quat

Matrix3 = tuple[Vector3, Vector3, Vector3]

DEFAULT_SENSORS: Mapping[int, str] = {
    reg.ICM20948_ADDRESS_AD0_LOW: "base",
    reg.ICM20948_ADDRESS_AD0_HIGH: "tip",
}
# linux/i2c-dev.h: I2C_RDWR_IOCTL_MAX_MSGS
_MAX_RDWR_MESSAGES = 42
_RESET_DURATION_S = 0.001
# AK09916 datasheet: single measurement takes at most about 8 ms.
_AK_SINGLE_MEASUREMENT_S = 0.008
# Bank 0 registers a read clears (DS 8, I2C_MST_STATUS and INT_STATUS_1/2).
_READ_TO_CLEAR = (reg.I2C_MST_STATUS, reg.INT_STATUS_1, reg.INT_STATUS_2)
# Bank 0 registers whose read is not a plain copy of the register file.
_READ_SPECIAL = (*_READ_TO_CLEAR, reg.FIFO_COUNTH, reg.FIFO_COUNTL, reg.FIFO_R_W)
# Register addresses and bits the kernels use (numba freezes module globals as constants).
ACCEL_XOUT_H, TEMP_OUT_H, EXT_SLV_SENS_DATA_00 = reg.ACCEL_XOUT_H, reg.TEMP_OUT_H, reg.EXT_SLV_SENS_DATA_00
AK_ST1, AK_HXL, AK_TMPS, AK_ST2 = reg.AK_ST1, reg.AK_HXL, reg.AK_TMPS, reg.AK_ST2
AK_ST1_DRDY, AK_ST1_DOR, AK_ST2_HOFL = reg.AK_ST1_DRDY, reg.AK_ST1_DOR, reg.AK_ST2_HOFL
_AK_VALID_MODES = {reg.AK_MODE_POWER_DOWN, reg.AK_MODE_SINGLE, 0x10, *reg.AK_CONTINUOUS_MODES_HZ}


@dataclass(frozen=True)
class ImuErrorModel:
    """Imperfections of one emulated IMU (all in the IMU's accel/gyro frame).

    accel/gyro_noise_density_*: white noise spectral density; the standard deviation
        per output sample is density * sqrt(noise bandwidth of the DLPF setting). Defaults:
        the datasheet's typical densities (accel 230 ug/sqrt(Hz), gyro 0.015
        deg/s/sqrt(Hz)). mag_noise_ut: per-measurement standard deviation (a few LSB).
    gyro_bias_rad_s: constant bias; gyro_bias_random_walk_rad_s_per_sqrt_s: the slow
        drift added on top (a random walk).
    accel_scale_error / gyro_scale_error: per-axis fractional scale errors.
    mag_hard_iron_ut: offset added to the field; mag_soft_iron: distortion matrix applied
        to the true field (an `ImuCalibration` with the inverse undoes it).
    temperature_degc: die temperature reported.
    """

    accel_noise_density_m_s2_per_sqrt_hz: float = reg.ACCEL_NOISE_DENSITY_UG_PER_SQRT_HZ * 1e-6 * reg.STANDARD_GRAVITY_M_S2
    gyro_noise_density_rad_s_per_sqrt_hz: float = reg.GYRO_NOISE_DENSITY_DPS_PER_SQRT_HZ * reg.DEG_TO_RAD
    mag_noise_ut: float = 0.3
    gyro_bias_rad_s: Vector3 = (0.006, -0.004, 0.005)
    gyro_bias_random_walk_rad_s_per_sqrt_s: float = 2e-5
    accel_scale_error: Vector3 = (0.002, -0.003, 0.001)
    gyro_scale_error: Vector3 = (0.003, 0.002, -0.002)
    mag_hard_iron_ut: Vector3 = (0.0, 0.0, 0.0)
    mag_soft_iron: Matrix3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    temperature_degc: float = 30.0

    def __post_init__(self) -> None:
        for name in ("accel_noise_density_m_s2_per_sqrt_hz", "gyro_noise_density_rad_s_per_sqrt_hz", "mag_noise_ut",
                     "gyro_bias_random_walk_rad_s_per_sqrt_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
        for name in ("gyro_bias_rad_s", "accel_scale_error", "gyro_scale_error", "mag_hard_iron_ut"):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.shape != (3,) or not np.all(np.isfinite(value)):
                raise ValueError(f"{name} must be three finite numbers")
        soft = np.asarray(self.mag_soft_iron, dtype=float)
        if soft.shape != (3, 3) or not np.all(np.isfinite(soft)):
            raise ValueError("mag_soft_iron must be a finite 3x3 matrix")


class _StandardNormals:
    """A generator's standard normals, drawn a block at a time and handed out in order.

    Bit for bit what ``rng.normal(0.0, scale, n)`` would give call after call (numpy
    draws both from the same sequence, and scales by one multiplication); a call per
    sample cost 0.7 us, most of it numpy's per-call overhead."""

    _BLOCK = 1024

    def __init__(self, rng: np.random.Generator) -> None:
        self._rng = rng
        self._block = np.empty(0)
        self._next = 0

    def take(self, count: int) -> np.ndarray:
        """The next ``count`` standard normals (a view into the block: not to be written)."""
        start = self._next
        if start + count > len(self._block):
            self._block = np.concatenate((self._block[start:], self._rng.standard_normal(self._BLOCK)))
            start = 0
        self._next = start + count
        return self._block[start:start + count]


@dataclass
class _TruthFrame:
    """What the physics says at one instant, in the IMU frame."""

    specific_force_m_s2: np.ndarray
    angular_velocity_rad_s: np.ndarray
    field_ut: np.ndarray


@njit(cache=True, inline="always")
def _frame_truth_into(orientation_in_tracker: np.ndarray, mounting: np.ndarray,
                      angular_velocity_in_sensor_rad_s: np.ndarray, acceleration_in_tracker_m_s2: np.ndarray,
                      gravity_in_tracker_m_s2: np.ndarray, field_in_tracker_ut: np.ndarray,
                      specific_force: np.ndarray, omega: np.ndarray, field: np.ndarray) -> None:
    """`_imu_frame_truth` written into the three (3,) outputs: the one body of both kernels."""
    q = orientation_in_tracker / np.sqrt(np.sum(orientation_in_tracker * orientation_in_tracker))
    w, x, y, z = q[0], q[1], q[2], q[3]
    sensor = np.empty((3, 3))
    sensor[0, 0], sensor[0, 1], sensor[0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    sensor[1, 0], sensor[1, 1], sensor[1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    sensor[2, 0], sensor[2, 1], sensor[2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    for i in range(3):
        specific_force[i] = 0.0
        omega[i] = 0.0
        field[i] = 0.0
    # Explicit sums: 3x3 products through BLAS cost more than they compute.
    for i in range(3):  # IMU axis i: column i of R = R(q) M
        for k in range(3):
            r_ki = sensor[k, 0] * mounting[0, i] + sensor[k, 1] * mounting[1, i] + sensor[k, 2] * mounting[2, i]
            specific_force[i] += r_ki * (acceleration_in_tracker_m_s2[k] - gravity_in_tracker_m_s2[k])
            field[i] += r_ki * field_in_tracker_ut[k]
            omega[i] += mounting[k, i] * angular_velocity_in_sensor_rad_s[k]


# Compiled eagerly for any array layout, so no call during a session compiles a new one
# (a second with the GIL held, while the valve heartbeat waits).
@njit("Tuple((float64[::1], float64[::1], float64[::1]))(float64[:], float64[:, :], float64[:], float64[:], float64[:], "
      "float64[:])", cache=True)
def _imu_frame_truth(orientation_in_tracker: np.ndarray, mounting: np.ndarray, angular_velocity_in_sensor_rad_s: np.ndarray,
                     acceleration_in_tracker_m_s2: np.ndarray, gravity_in_tracker_m_s2: np.ndarray,
                     field_in_tracker_ut: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The plant sensor's state seen in the IMU frame: specific force R^T (a - g) (m/s^2),
    angular velocity M^T omega (rad/s) and field R^T B (uT), R = R(q) M, q normalised first.
    Compiled: every sample of every chip asks (thousands per wall second on a 25x rig),
    and a dozen numpy calls on 3-vectors cost ~20 us where this costs ~2 us."""
    specific_force, omega, field = np.empty(3), np.empty(3), np.empty(3)
    _frame_truth_into(orientation_in_tracker, mounting, angular_velocity_in_sensor_rad_s,
                      acceleration_in_tracker_m_s2, gravity_in_tracker_m_s2, field_in_tracker_ut,
                      specific_force, omega, field)
    return specific_force, omega, field


@njit(cache=True, inline="always")
def _put_count(out: np.ndarray, offset: int, value: float, low: int, high: int) -> None:
    """Nearest count, saturated like the sensor, as a big-endian int16 at ``offset``."""
    count = min(high, max(low, int(round(value))))
    count &= 0xFFFF
    out[offset] = count >> 8
    out[offset + 1] = count & 0xFF


@njit(cache=True, inline="always")
def _motion_into(specific_force_m_s2: np.ndarray, angular_velocity_rad_s: np.ndarray, accel_gain: np.ndarray,
                 gyro_gain: np.ndarray, gyro_bias_rad_s: np.ndarray, unit_noise: np.ndarray, accel_noise_m_s2: float,
                 gyro_noise_rad_s: float, accel_m_s2_per_lsb: float, gyro_rad_s_per_lsb: float,
                 out: np.ndarray) -> None:
    for axis in range(3):
        accel = accel_gain[axis] * specific_force_m_s2[axis] + accel_noise_m_s2 * unit_noise[axis]
        gyro = (gyro_gain[axis] * angular_velocity_rad_s[axis] + gyro_bias_rad_s[axis]
                + gyro_noise_rad_s * unit_noise[3 + axis])
        _put_count(out, 2 * axis, accel / accel_m_s2_per_lsb, -32768, 32767)
        _put_count(out, 6 + 2 * axis, gyro / gyro_rad_s_per_lsb, -32768, 32767)


@njit("void(float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64, float64, "
      "float64, float64, uint8[::1])", cache=True)
def _motion_register_bytes(specific_force_m_s2: np.ndarray, angular_velocity_rad_s: np.ndarray,
                           accel_gain: np.ndarray, gyro_gain: np.ndarray, gyro_bias_rad_s: np.ndarray,
                           unit_noise: np.ndarray, accel_noise_m_s2: float, gyro_noise_rad_s: float,
                           accel_m_s2_per_lsb: float, gyro_rad_s_per_lsb: float, out: np.ndarray) -> None:
    """ACCEL_XOUT_H..GYRO_ZOUT_L (12 bytes into ``out``) of one sample: gain x truth (+ bias
    for the gyro) + noise (``unit_noise``: 6 standard normals, accel then gyro), in counts.
    Compiled: the FIFO asks for every sample instant of both chips (5000 per wall second
    on a 25x rig), where `codec.encode_motion` and a dozen numpy calls cost ~15 us."""
    _motion_into(specific_force_m_s2, angular_velocity_rad_s, accel_gain, gyro_gain, gyro_bias_rad_s, unit_noise,
                 accel_noise_m_s2, gyro_noise_rad_s, accel_m_s2_per_lsb, gyro_rad_s_per_lsb, out)


@njit(cache=True, inline="always")
def _mag_counts_into(field_ut: np.ndarray, soft_iron: np.ndarray, hard_iron_ut: np.ndarray, noise_ut: np.ndarray,
                     die_signs: np.ndarray, out: np.ndarray) -> None:
    total = 0.0
    for i in range(3):
        measured = (soft_iron[i, 0] * field_ut[0] + soft_iron[i, 1] * field_ut[1] + soft_iron[i, 2] * field_ut[2]
                    + hard_iron_ut[i] + noise_ut[i])
        total += abs(measured)
        out[i] = min(reg.MAG_COUNT_LIMIT, max(-reg.MAG_COUNT_LIMIT, int(round(die_signs[i] * measured
                                                                              / reg.MAG_UT_PER_LSB))))
    out[3] = 1 if total >= reg.MAG_OVERFLOW_SUM_UT else 0


@njit("int64[::1](float64[::1], float64[:, ::1], float64[::1], float64[::1], float64[::1])", cache=True)
def _mag_counts(field_ut: np.ndarray, soft_iron: np.ndarray, hard_iron_ut: np.ndarray, noise_ut: np.ndarray,
                die_signs: np.ndarray) -> np.ndarray:
    """AK09916 die-axis counts of M_soft B + hard + noise (field in the IMU frame, uT),
    saturated at +-32752, and 1 in the last element when |X| + |Y| + |Z| >= 4912 uT (HOFL)."""
    out = np.zeros(4, dtype=np.int64)
    _mag_counts_into(field_ut, soft_iron, hard_iron_ut, noise_ut, die_signs, out)
    return out


# Where a run's parameters sit in `_fifo_run`'s packed arguments (a compiled call costs
# ~0.7 us per argument on a slow host: a run passes a handful of arrays, not 30 values).
_V_GRAVITY, _V_FIELD, _V_GYRO_BIAS, _V_ACCEL_GAIN, _V_GYRO_GAIN, _V_HARD_IRON, _V_DIE_SIGNS, _V_DRIFT = range(8)
_S_FIRST_WALK, _S_WALK, _S_ACCEL_NOISE, _S_GYRO_NOISE, _S_ACCEL_LSB, _S_GYRO_LSB, _S_MAG_NOISE, _S_AK_SINCE, \
    _S_AK_RATE = range(9)
_I_WRITE_ACCEL, _I_WRITE_GYRO, _I_SLAVE_REGISTER, _I_SLAVE_LENGTH, _I_AK_LAST_INDEX, _I_AK_LOCKED, \
    _I_FIRST_LATCH = range(7)


@njit("void(int64, float64[::1], int64[::1], float64[:, ::1], float64[:, ::1], float64[:, ::1], float64[:, :], "
      "float64[:, ::1], float64[:, ::1], float64[::1], int64[::1], float64[:, ::1], float64[::1], uint8[::1], "
      "uint8[::1], uint8[::1], int64[::1], uint8[:, ::1])", cache=True)
def _fifo_run(count: int, instants: np.ndarray, accel_rows: np.ndarray, orientations: np.ndarray,
              angular_velocities: np.ndarray, accelerations: np.ndarray, mounting: np.ndarray, soft_iron: np.ndarray,
              vectors: np.ndarray, scalars: np.ndarray, settings: np.ndarray, motion_normals: np.ndarray,
              mag_normals: np.ndarray, temperature: np.ndarray, bank0: np.ndarray, ak_registers: np.ndarray,
              columns: np.ndarray, records: np.ndarray) -> None:
    """``count`` FIFO records at ``count`` gyro instants (the master on the gyro's clock),
    exactly as `_tick_newest` and `_fifo_record` make them, into ``records``.

    ``instants`` and the plant states (rows of ``orientations``, ``angular_velocities``,
    ``accelerations``): the gyro instants, the accel instants that differ from them
    (``accel_rows[i]``: the row of gyro instant i's accel sample, -1 when none is due),
    then the magnetometer's new measurements (from row ``settings[_I_FIRST_LATCH]``),
    each instant asked once. Per gyro instant: the drift's step (3 of
    ``motion_normals``' 9), the motion registers (the other 6), the temperature, then the
    master's SLV0 copy (``settings``' register and length, 0 for none) from the AK09916's
    ``ak_registers`` after its continuous-mode `update`, which latches a measurement (3 of
    ``mag_normals``) on its own clock; finally the record's ``columns`` of ``bank0``.
    ``bank0``, ``ak_registers``, the drift row of ``vectors`` and the AK's last index and
    lock in ``settings`` are left as the Python path leaves them. Rows of ``vectors`` and
    entries of ``scalars``/``settings``: the _V_, _S_, _I_ names."""
    specific_force, omega, field = np.empty(3), np.empty(3), np.empty(3)
    accel_time_omega = np.empty(3)
    motion = np.empty(12, dtype=np.uint8)
    bias = np.empty(3)
    counts = np.zeros(4, dtype=np.int64)
    drift = vectors[_V_DRIFT]
    start, length = settings[_I_SLAVE_REGISTER], settings[_I_SLAVE_LENGTH]
    end = start + length - 1
    since, rate = scalars[_S_AK_SINCE], scalars[_S_AK_RATE]
    latch = settings[_I_FIRST_LATCH]
    for i in range(count):
        walk = scalars[_S_FIRST_WALK] if i == 0 else scalars[_S_WALK]
        for axis in range(3):
            drift[axis] = drift[axis] + walk * motion_normals[i, axis]
            bias[axis] = vectors[_V_GYRO_BIAS, axis] + drift[axis]
        _frame_truth_into(orientations[i], mounting, angular_velocities[i], accelerations[i], vectors[_V_GRAVITY],
                          vectors[_V_FIELD], specific_force, omega, field)
        row = accel_rows[i]
        if row > i:  # the accel's own instant: its truth for the specific force
            _frame_truth_into(orientations[row], mounting, angular_velocities[row], accelerations[row],
                              vectors[_V_GRAVITY], vectors[_V_FIELD], specific_force, accel_time_omega, field)
        _motion_into(specific_force, omega, vectors[_V_ACCEL_GAIN], vectors[_V_GYRO_GAIN], bias,
                     motion_normals[i, 3:], scalars[_S_ACCEL_NOISE], scalars[_S_GYRO_NOISE], scalars[_S_ACCEL_LSB],
                     scalars[_S_GYRO_LSB], motion)
        if settings[_I_WRITE_ACCEL] and row >= 0:
            bank0[ACCEL_XOUT_H:ACCEL_XOUT_H + 6] = motion[0:6]
        if settings[_I_WRITE_GYRO]:
            bank0[ACCEL_XOUT_H + 6:ACCEL_XOUT_H + 12] = motion[6:12]
        bank0[TEMP_OUT_H:TEMP_OUT_H + 2] = temperature
        if length:
            # `_EmulatedAk09916.update` in a continuous mode, then its `read`.
            index = math.floor((instants[i] - since) * rate)
            if index > settings[_I_AK_LAST_INDEX]:
                skipped = index - settings[_I_AK_LAST_INDEX] > 1
                settings[_I_AK_LAST_INDEX] = index
                if settings[_I_AK_LOCKED] or ak_registers[AK_ST1] & AK_ST1_DRDY:
                    ak_registers[AK_ST1] |= AK_ST1_DOR
                if not settings[_I_AK_LOCKED]:
                    _frame_truth_into(orientations[latch], mounting, angular_velocities[latch], accelerations[latch],
                                      vectors[_V_GRAVITY], vectors[_V_FIELD], specific_force, omega, field)
                    drawn = 3 * (latch - settings[_I_FIRST_LATCH])
                    noise = mag_normals[drawn:drawn + 3] * scalars[_S_MAG_NOISE]
                    _mag_counts_into(field, soft_iron, vectors[_V_HARD_IRON], noise, vectors[_V_DIE_SIGNS], counts)
                    latch += 1
                    for axis in range(3):  # HXL..HZH: little-endian int16
                        ak_registers[AK_HXL + 2 * axis] = counts[axis] & 0xFF
                        ak_registers[AK_HXL + 2 * axis + 1] = (counts[axis] >> 8) & 0xFF
                    ak_registers[AK_TMPS] = 0
                    ak_registers[AK_ST2] = AK_ST2_HOFL if counts[3] else 0
                    ak_registers[AK_ST1] |= AK_ST1_DRDY
                if skipped:
                    ak_registers[AK_ST1] |= AK_ST1_DOR
            bank0[EXT_SLV_SENS_DATA_00:EXT_SLV_SENS_DATA_00 + length] = ak_registers[start:start + length]
            if start <= AK_TMPS and end >= AK_HXL:
                ak_registers[AK_ST1] &= ~(AK_ST1_DRDY | AK_ST1_DOR) & 0xFF
                settings[_I_AK_LOCKED] = 1
            if end == AK_ST2:
                ak_registers[AK_ST1] &= ~(AK_ST1_DRDY | AK_ST1_DOR) & 0xFF
                settings[_I_AK_LOCKED] = 0
        for column in range(columns.shape[0]):
            records[i, column] = bank0[columns[column]]
    if latch != instants.shape[0]:
        raise ValueError("the magnetometer latched at other instants than its truths were asked for")


class _EmulatedAk09916:
    """The magnetometer die behind one chip's auxiliary master (address 0x0C)."""

    def __init__(self, measure: Callable[[float], tuple[tuple[int, int, int], bool]]) -> None:
        # measure(t) -> (die-axis counts, overflow) for a measurement at plant time t.
        self._measure = measure
        self.reset(0.0)

    def reset(self, now: float) -> None:
        self.regs = bytearray(0x40)
        self.regs[reg.AK_WIA1] = reg.AK_WIA1_VALUE
        self.regs[reg.AK_WIA2] = reg.AK_WIA2_VALUE
        self.mode = reg.AK_MODE_POWER_DOWN
        self.mode_since = now
        self.last_index = 0
        self._single_due: float | None = None
        self.locked = False  # data registers read but ST2 not yet: hold them

    def _latch(self, t: float, *, continuous: bool) -> None:
        if continuous and (self.locked or self.regs[reg.AK_ST1] & reg.AK_ST1_DRDY):
            # The previous measurement was never fully read: this one is skipped over it
            # (ST1.DOR is defined for the continuous modes only).
            self.regs[reg.AK_ST1] |= reg.AK_ST1_DOR
        if self.locked:
            return
        counts, overflow = self._measure(t)
        block = encode_ak09916_block(counts, data_ready=True, overrun=False, overflow=overflow)
        self.regs[reg.AK_HXL : reg.AK_ST2 + 1] = block[1:]
        self.regs[reg.AK_ST1] |= reg.AK_ST1_DRDY

    def update(self, now: float) -> None:
        if self.mode in reg.AK_CONTINUOUS_MODES_HZ:
            rate = reg.AK_CONTINUOUS_MODES_HZ[self.mode]
            index = math.floor((now - self.mode_since) * rate)
            if index > self.last_index:
                skipped = index - self.last_index > 1
                self.last_index = index
                self._latch(self.mode_since + index / rate, continuous=True)
                if skipped:
                    # measurements came and went unread between two looks at the die
                    self.regs[reg.AK_ST1] |= reg.AK_ST1_DOR
        elif self._single_due is not None and now >= self._single_due:
            self._latch(self._single_due, continuous=False)
            self._single_due = None
            self.mode = reg.AK_MODE_POWER_DOWN
            self.regs[reg.AK_CNTL2] = reg.AK_MODE_POWER_DOWN

    @staticmethod
    def _next_address(address: int) -> int:
        # AK09916 auto-increment: 00-03 then 10-18 then back to 00; 30-32 wraps to 30.
        if address == 0x03:
            return 0x10
        if address == reg.AK_ST2:
            return 0x00
        if address == reg.AK_CNTL3:
            return reg.AK_CNTL2 - 1
        return (address + 1) % 0x40

    def read(self, address: int, length: int, now: float) -> bytes:
        self.update(now)
        out = bytearray()
        for _ in range(length):
            out.append(self.regs[address])
            if reg.AK_HXL <= address <= reg.AK_TMPS:
                self.regs[reg.AK_ST1] &= ~(reg.AK_ST1_DRDY | reg.AK_ST1_DOR) & 0xFF
                self.locked = True
            elif address == reg.AK_ST2:
                self.regs[reg.AK_ST1] &= ~(reg.AK_ST1_DRDY | reg.AK_ST1_DOR) & 0xFF
                self.locked = False
            address = self._next_address(address)
        return bytes(out)

    def write(self, address: int, value: int, now: float) -> None:
        self.update(now)
        if address == reg.AK_CNTL3 and value & reg.AK_CNTL3_SRST:
            self.reset(now)
        elif address == reg.AK_CNTL2:
            mode = value & 0x1F
            if mode not in _AK_VALID_MODES:
                return
            self.regs[reg.AK_CNTL2] = mode
            # A new mode command ends a read that never reached ST2: the data protection
            # guards one read cycle of one measurement, not the next measurement's result.
            # Pimoroni's driver reads 14 bytes from HXL (through ST2 and on, ending on HXL)
            # and then commands the next single measurement; on silicon that one arrives.
            self.locked = False
            self.mode = mode
            self.mode_since = now
            self.last_index = 0
            self._single_due = now + _AK_SINGLE_MEASUREMENT_S if mode == reg.AK_MODE_SINGLE else None


class _Grid:
    """One output-rate grid: instants origin + k * period, k counted since the last look."""

    def __init__(self, origin_s: float) -> None:
        self.origin_s = origin_s
        self.index = 0

    def advance(self, now: float, period_s: float) -> tuple[float, int] | None:
        """(newest instant <= now, periods since the last one returned), or None."""
        # The margin: an instant computed as origin + k * period may land a rounding error
        # short of k, and the FIFO asks at exactly those instants.
        index = math.floor((now - self.origin_s) / period_s + 1e-9)
        if index <= self.index:
            return None
        steps = index - self.index
        self.index = index
        return self.origin_s + index * period_s, steps


class _EmulatedIcm20948:
    """One chip's register file, sampling and auxiliary master."""

    # False: every FIFO instant through `_tick_newest`, the reference `_sample_run` is
    # tested against.
    batched = True

    def __init__(self, owner: Icm20948BusEmulator, address: int, sensor: str, model: ImuErrorModel,
                 mounting: np.ndarray, seed: int) -> None:
        self.owner = owner
        self.address = address
        self.sensor = sensor
        self.model = model
        self.mounting = mounting
        self.rng = np.random.default_rng([seed, address])
        self._motion_normals = _StandardNormals(self.rng)
        # The magnetometer's own: it is read on the auxiliary master's clock, which the
        # emulator runs whenever it is looked at, so its draws must not shift the motion's.
        self.mag_rng = np.random.default_rng([seed, address, 0x0C])
        self._mag_normals = _StandardNormals(self.mag_rng)
        self.bias_drift_rad_s = np.zeros(3)
        self._gyro_bias_constant_rad_s = np.asarray(model.gyro_bias_rad_s, dtype=float)
        self._accel_gain = 1.0 + np.asarray(model.accel_scale_error, dtype=float)
        self._gyro_gain = 1.0 + np.asarray(model.gyro_scale_error, dtype=float)
        self._temperature_bytes = encode_motion((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), model.temperature_degc,
                                                ImuRanges())[12:14]
        self._temperature_registers = np.frombuffer(self._temperature_bytes, dtype=np.uint8).copy()
        self._ranges: dict[tuple[int, int], ImuRanges] = {}
        self._motion_registers = np.empty(12, dtype=np.uint8)
        self._record_key: tuple[int, int, int] | None = None
        self._record_spans: tuple[tuple[int, int], ...] = ()
        self._record_length = 0
        self._record_columns = np.empty(0, dtype=np.int64)  # bank 0 registers of a record, in order
        self._soft_iron = np.ascontiguousarray(model.mag_soft_iron, dtype=float)
        self._hard_iron_ut = np.asarray(model.mag_hard_iron_ut, dtype=float)
        self._die_signs = np.asarray(reg.MAG_AXIS_SIGNS_IN_IMU_FRAME, dtype=float)
        self.ak = _EmulatedAk09916(self._measure_mag)
        self.fifo_size_bytes = owner.fifo_size_bytes
        self._power_on(owner.clock())

    # --- state ------------------------------------------------------------------------

    def _power_on(self, now: float) -> None:
        self.banks = [bytearray(0x80) for _ in range(reg.BANK_COUNT)]
        self.banks[0][reg.WHO_AM_I] = self.owner.who_am_i.get(self.address, reg.WHO_AM_I_VALUE)
        self.banks[0][reg.PWR_MGMT_1] = reg.PWR_MGMT_1_RESET_VALUE
        self.banks[0][reg.LP_CONFIG] = reg.LP_CONFIG_RESET_VALUE
        self.banks[2][reg.GYRO_CONFIG_1] = 0x01  # DS 7 bank 2 map: reset value
        self.banks[2][reg.ACCEL_CONFIG] = 0x01
        self.bank = 0
        self.reset_until = now
        self.fifo = bytearray()
        self._fifo_last_byte = 0
        self._anchor_all(now)

    def _anchor_all(self, now: float) -> None:
        """Restart every output-rate grid (wake)."""
        self.gyro_grid, self.accel_grid, self.master_grid = _Grid(now), _Grid(now), _Grid(now)

    @property
    def awake(self) -> bool:
        return not self.banks[0][reg.PWR_MGMT_1] & reg.PWR_MGMT_1_SLEEP

    @property
    def period_s(self) -> float:
        """Gyro output period (s): 1.125 kHz / (1 + GYRO_SMPLRT_DIV)."""
        return (1 + self.banks[2][reg.GYRO_SMPLRT_DIV]) / reg.BASE_SAMPLE_RATE_HZ

    @property
    def accel_period_s(self) -> float:
        """Accel output period (s): 1.125 kHz / (1 + ACCEL_SMPLRT_DIV), a 12-bit divider."""
        bank2 = self.banks[2]
        divider = ((bank2[reg.ACCEL_SMPLRT_DIV_1] << 8) | bank2[reg.ACCEL_SMPLRT_DIV_2]) & reg.ACCEL_SMPLRT_DIV_MAX
        return (1 + divider) / reg.BASE_SAMPLE_RATE_HZ

    @property
    def master_period_s(self) -> float | None:
        """Period (s) of the auxiliary master's own clock, or None when it follows the gyro.

        LP_CONFIG.I2C_MST_CYC (set at reset, DS 7) duty-cycles the master at
        1.1 kHz / 2^I2C_MST_ODR_CONFIG. DS 11 also says that with the gyro on "all sensors
        (including I2C_MASTER) use the gyroscope ODR"; Pimoroni's driver, which works on
        silicon, gives the master 5 ms between enable and disable at a 100 Hz gyro rate and
        so relies on the faster duty-cycled clock: the emulator takes that reading."""
        if not self.banks[0][reg.LP_CONFIG] & reg.LP_CONFIG_I2C_MST_CYC:
            return None
        return (1 << (self.banks[3][reg.I2C_MST_ODR_CONFIG] & 0x0F)) / reg.BASE_SAMPLE_RATE_HZ

    @property
    def fifo_writing(self) -> bool:
        """USER_CTRL.FIFO_EN with some source enabled and FIFO_RST not held."""
        bank0 = self.banks[0]
        return bool(bank0[reg.USER_CTRL] & reg.USER_CTRL_FIFO_EN and not bank0[reg.FIFO_RST] & reg.FIFO_RST_ASSERT
                    and (bank0[reg.FIFO_EN_1] & 0x0F or bank0[reg.FIFO_EN_2] & reg.FIFO_EN_2_MOTION))

    def ranges(self) -> ImuRanges:
        key = ((self.banks[2][reg.ACCEL_CONFIG] >> 1) & 0x03, (self.banks[2][reg.GYRO_CONFIG_1] >> 1) & 0x03)
        ranges = self._ranges.get(key)
        if ranges is None:
            ranges = self._ranges[key] = ImuRanges(accel_full_scale_g=reg.ACCEL_FULL_SCALES[key[0]][0],
                                                   gyro_full_scale_dps=reg.GYRO_FULL_SCALES[key[1]][0])
        return ranges

    def noise_std(self) -> tuple[float, float]:
        """(accel m/s^2, gyro rad/s) white noise per sample at the current DLPF settings."""
        bank2 = self.banks[2]
        accel_nbw = reg.noise_bandwidth_hz(bank2[reg.ACCEL_CONFIG], reg.ACCEL_DLPF_NBW_HZ, reg.ACCEL_BYPASS_NBW_HZ)
        gyro_nbw = reg.noise_bandwidth_hz(bank2[reg.GYRO_CONFIG_1], reg.GYRO_DLPF_NBW_HZ, reg.GYRO_BYPASS_NBW_HZ)
        return (self.model.accel_noise_density_m_s2_per_sqrt_hz * math.sqrt(accel_nbw),
                self.model.gyro_noise_density_rad_s_per_sqrt_hz * math.sqrt(gyro_nbw))

    # --- physics ----------------------------------------------------------------------

    def truth(self, t: float) -> _TruthFrame:
        plant = self.owner.plant
        state = plant.sensor_truth(self.sensor, t)
        field_in_tracker = self.owner.field_in_tracker_ut(self.sensor)
        specific_force, omega, field = _imu_frame_truth(
            np.asarray(state.orientation_in_tracker, dtype=float), self.mounting,
            np.asarray(state.angular_velocity_in_sensor_rad_s, dtype=float),
            np.asarray(state.linear_acceleration_in_tracker_m_s2, dtype=float),
            np.asarray(plant.gravity_in_tracker_m_s2, dtype=float),
            field_in_tracker)
        return _TruthFrame(specific_force, omega, field)

    def gyro_bias_rad_s(self) -> np.ndarray:
        return self._gyro_bias_constant_rad_s + self.bias_drift_rad_s

    def _measure_mag(self, t: float) -> tuple[tuple[int, int, int], bool]:
        counts = _mag_counts(self.truth(t).field_ut, self._soft_iron, self._hard_iron_ut,
                             self.model.mag_noise_ut * self._mag_normals.take(3), self._die_signs)
        return (int(counts[0]), int(counts[1]), int(counts[2])), bool(counts[3])

    def _sample_motion(self, accel_due: tuple[float, int] | None, gyro_due: tuple[float, int] | None) -> None:
        """Latch new accel and/or gyro (+ temperature) data for their own sample instants."""
        m = self.model
        accel_noise, gyro_noise = self.noise_std()
        if gyro_due is not None:
            walk = m.gyro_bias_random_walk_rad_s_per_sqrt_s * math.sqrt(gyro_due[1] * self.period_s)
            self.bias_drift_rad_s = self.bias_drift_rad_s + walk * self._motion_normals.take(3)
        frame = self.truth(accel_due[0] if accel_due is not None else gyro_due[0])  # type: ignore[index]
        if accel_due is not None and gyro_due is not None and accel_due[0] != gyro_due[0]:
            gyro_frame = self.truth(gyro_due[0])
        else:
            gyro_frame = frame
        ranges = self.ranges()
        registers = self._motion_registers
        _motion_register_bytes(frame.specific_force_m_s2, gyro_frame.angular_velocity_rad_s, self._accel_gain,
                               self._gyro_gain, self.gyro_bias_rad_s(), self._motion_normals.take(6), accel_noise,
                               gyro_noise, ranges.accel_m_s2_per_lsb, ranges.gyro_rad_s_per_lsb, registers)
        motion = registers.tobytes()
        disabled = self.banks[0][reg.PWR_MGMT_2]
        data = self.banks[0]
        if accel_due is not None and not disabled & reg.PWR_MGMT_2_DISABLE_ACCEL:
            data[reg.ACCEL_XOUT_H : reg.GYRO_XOUT_H] = motion[0:6]
        if gyro_due is not None:
            if not disabled & reg.PWR_MGMT_2_DISABLE_GYRO:
                data[reg.GYRO_XOUT_H : reg.TEMP_OUT_H] = motion[6:12]
            data[reg.TEMP_OUT_H : reg.EXT_SLV_SENS_DATA_00] = self._temperature_bytes
        data[reg.INT_STATUS_1] |= reg.INT_STATUS_1_RAW_DATA_0_RDY

    def _run_aux_master(self, now: float) -> None:
        if not self.banks[0][reg.USER_CTRL] & reg.USER_CTRL_I2C_MST_EN:
            return
        bank3 = self.banks[3]
        status = 0
        if bank3[reg.I2C_SLV0_CTRL] & reg.I2C_SLV_EN:
            address = bank3[reg.I2C_SLV0_ADDR] & 0x7F
            length = bank3[reg.I2C_SLV0_CTRL] & reg.I2C_SLV_LENG_MASK
            if address != reg.AK09916_ADDRESS:
                status |= reg.I2C_MST_STATUS_SLV0_NACK
            elif bank3[reg.I2C_SLV0_ADDR] & reg.I2C_SLV_READ:
                if length:
                    data = self.ak.read(bank3[reg.I2C_SLV0_REG], length, now)
                    start = reg.EXT_SLV_SENS_DATA_00
                    self.banks[0][start : start + length] = data
            else:
                self.ak.write(bank3[reg.I2C_SLV0_REG], bank3[reg.I2C_SLV0_DO], now)
        if bank3[reg.I2C_SLV4_CTRL] & reg.I2C_SLV_EN:
            address = bank3[reg.I2C_SLV4_ADDR] & 0x7F
            status |= reg.I2C_MST_STATUS_SLV4_DONE
            if address != reg.AK09916_ADDRESS:
                status |= reg.I2C_MST_STATUS_SLV4_NACK
            elif bank3[reg.I2C_SLV4_ADDR] & reg.I2C_SLV_READ:
                bank3[reg.I2C_SLV4_DI] = self.ak.read(bank3[reg.I2C_SLV4_REG], 1, now)[0]
            else:
                self.ak.write(bank3[reg.I2C_SLV4_REG], bank3[reg.I2C_SLV4_DO], now)
            bank3[reg.I2C_SLV4_CTRL] &= ~reg.I2C_SLV_EN & 0xFF  # a single transfer
        self.banks[0][reg.I2C_MST_STATUS] |= status

    def tick(self, now: float) -> None:
        """Bring the chip up to time `now`: finish a reset, latch the newest accel and gyro
        samples and run the auxiliary master once for its newest instant.

        The magnetometer is brought up to date only by the master's transfers, the one
        way it is seen: each begins with its `update`, which latches the newest
        measurement of its own clock whenever it is asked. Run between transfers too, it
        would latch measurements nobody reads, each a truth and three draws (over a
        quarter of the emulator's time at 25x with the master on the gyro's clock)."""
        pwr = self.banks[0][reg.PWR_MGMT_1]
        if pwr & reg.PWR_MGMT_1_DEVICE_RESET and now >= self.reset_until:
            self._power_on(now)
            return
        if not self.awake:
            return
        if self.fifo_writing:
            self._tick_every_instant(now)
        else:
            self._tick_newest(now)

    def _tick_newest(self, now: float) -> None:
        gyro_due = self.gyro_grid.advance(now, self.period_s)
        accel_due = self.accel_grid.advance(now, self.accel_period_s)
        if gyro_due is not None or accel_due is not None:
            self._sample_motion(accel_due, gyro_due)
        master_period = self.master_period_s
        if master_period is None:
            master_due = gyro_due
        else:
            master_due = self.master_grid.advance(now, master_period)
        if master_due is not None:
            self._run_aux_master(master_due[0])

    def _tick_every_instant(self, now: float) -> None:
        """With the FIFO on, every gyro sample instant since the last look is sampled and
        written to it, oldest first. Instants the FIFO has no room for (snapshot mode)
        or would overwrite anyway (stream mode) only advance the registers.

        An accel instant after the newest gyro instant shows only in the registers: it
        is latched when they are read (`_latch_for_register_read`), not at every look,
        where each cost a truth and six draws, and made the FIFO's noise depend on how
        often the chip was looked at (the simulated rig's accel grid lags its gyro's)."""
        period = self.period_s
        grid = self.gyro_grid
        newest = math.floor((now - grid.origin_s) / period)
        self._fifo_record_spans()
        record_bytes = max(self._record_length, 1)
        first, last = grid.index + 1, newest
        if self.banks[0][reg.FIFO_MODE] & reg.FIFO_MODE_SNAPSHOT:
            # The oldest instants fill what is left (the last one partly); newer ones are lost.
            last = min(last, grid.index + (self.fifo_size_bytes - len(self.fifo)) // record_bytes + 1)
        else:
            # Only the newest FIFO-full survives: older instants would be overwritten.
            first = max(first, newest - self.fifo_size_bytes // record_bytes)
        if first > grid.index + 1 or last < newest:
            self._fifo_overflowed()
        if last >= first and self.batched and self._runs_in_lockstep():
            self._sample_run(first, last)
        else:
            for index in range(first, last + 1):
                self._tick_newest(grid.origin_s + index * period)
                self._fifo_write(self._fifo_record())
        if last < newest or self.master_period_s is not None:
            # Dropped instants still move the registers on, and a master on its own clock
            # runs between gyro instants.
            self._tick_newest(now)

    def _latch_for_register_read(self, register: int, length: int, now: float) -> None:
        """Before a bank-0 read that shows the newest sample (INT_STATUS_1's data-ready
        bit, the sample registers), with the FIFO on: the newest accel instant, which
        `_tick_every_instant` leaves to this."""
        end = register + length
        if self.bank == 0 and self.fifo_writing and self.awake and (
                register <= reg.INT_STATUS_1 < end
                or (register < reg.EXT_SLV_SENS_DATA_00 + reg.EXT_SLV_SENS_DATA_COUNT and end > reg.ACCEL_XOUT_H)):
            self._tick_newest(now)

    def _runs_in_lockstep(self) -> bool:
        """Whether `_sample_run` may make this run of records: the master on the gyro's
        clock, and idle or copying through SLV0 alone from the
        magnetometer in a continuous mode, a run of ST1..ST2 that ends on ST2 (so each
        copy releases the data and every new measurement is latched)."""
        if self.master_period_s is not None:
            return False
        bank3 = self.banks[3]
        if not self.banks[0][reg.USER_CTRL] & reg.USER_CTRL_I2C_MST_EN:
            return True
        if bank3[reg.I2C_SLV4_CTRL] & reg.I2C_SLV_EN:
            return False
        length = bank3[reg.I2C_SLV0_CTRL] & reg.I2C_SLV_LENG_MASK
        if not bank3[reg.I2C_SLV0_CTRL] & reg.I2C_SLV_EN or not length:
            return True
        start = bank3[reg.I2C_SLV0_REG]
        return (bank3[reg.I2C_SLV0_ADDR] == reg.I2C_SLV_READ | reg.AK09916_ADDRESS
                and self.ak.mode in reg.AK_CONTINUOUS_MODES_HZ and not self.ak.locked
                and reg.AK_ST1 <= start and start + length - 1 == reg.AK_ST2)

    def _sample_run(self, first: int, last: int) -> None:
        """Gyro instants ``first``..``last`` of the grid sampled and written to the FIFO at
        once: bit for bit what `_tick_newest` and `_fifo_write` instant by instant make
        (the same truths, the same draws in the same order, the same magnetometer state),
        with one plant call and one compiled kernel for the whole run instead of a dozen
        Python calls per instant (~100 us an instant on a slow host, where at 25x and
        100 Hz two chips are asked for 5000 a wall second)."""
        period = self.period_s
        grid = self.gyro_grid
        instants = [grid.origin_s + index * period for index in range(first, last + 1)]
        count = len(instants)
        # The newest accel instant at each gyro instant, as `_Grid.advance` finds it: the
        # same one when the two grids coincide, else one more truth to ask for.
        accel_grid, accel_period = self.accel_grid, self.accel_period_s
        accel_rows = [-1] * count
        accel_index = accel_grid.index
        for row, t in enumerate(instants[:count]):
            index = math.floor((t - accel_grid.origin_s) / accel_period + 1e-9)
            if index > accel_index:
                accel_index = index
                accel_t = accel_grid.origin_s + index * accel_period
                if accel_t == t:
                    accel_rows[row] = row
                else:
                    accel_rows[row] = len(instants)
                    instants.append(accel_t)
        first_latch = len(instants)
        bank0, bank3 = self.banks[0], self.banks[3]
        ak = self.ak
        length = bank3[reg.I2C_SLV0_CTRL] & reg.I2C_SLV_LENG_MASK if (
            bank0[reg.USER_CTRL] & reg.USER_CTRL_I2C_MST_EN and bank3[reg.I2C_SLV0_CTRL] & reg.I2C_SLV_EN) else 0
        since = rate = 0.0
        if length:
            # The magnetometer's new measurements in the run, found as its `update` will:
            # their truths come from the same plant call as the motion's.
            since, rate = ak.mode_since, reg.AK_CONTINUOUS_MODES_HZ[ak.mode]
            previous = ak.last_index
            for t in instants[:count]:
                index = math.floor((t - since) * rate)
                if index > previous:
                    previous = index
                    instants.append(since + index / rate)
        latches = len(instants) - first_latch
        times = np.array(instants)
        owner = self.owner
        state = owner.truths_at_instants(self.sensor, times)
        vectors = np.array((owner.plant.gravity_in_tracker_m_s2, owner.field_in_tracker_ut(self.sensor),
                            self._gyro_bias_constant_rad_s, self._accel_gain, self._gyro_gain, self._hard_iron_ut,
                            self._die_signs, self.bias_drift_rad_s), dtype=float)
        walk = self.model.gyro_bias_random_walk_rad_s_per_sqrt_s
        ranges = self.ranges()
        scalars = np.array((walk * math.sqrt((first - grid.index) * period), walk * math.sqrt(period),
                            *self.noise_std(), ranges.accel_m_s2_per_lsb, ranges.gyro_rad_s_per_lsb,
                            self.model.mag_noise_ut, since, rate))
        disabled = bank0[reg.PWR_MGMT_2]
        settings = np.array((not disabled & reg.PWR_MGMT_2_DISABLE_ACCEL, not disabled & reg.PWR_MGMT_2_DISABLE_GYRO,
                             bank3[reg.I2C_SLV0_REG], length, ak.last_index, ak.locked, first_latch), dtype=np.int64)
        records = np.empty((count, self._record_length), dtype=np.uint8)
        _fifo_run(count, times, np.array(accel_rows, dtype=np.int64),
                  state.orientation_in_tracker, state.angular_velocity_in_sensor_rad_s,
                  state.linear_acceleration_in_tracker_m_s2, self.mounting, self._soft_iron, vectors, scalars,
                  settings, self._motion_normals.take(9 * count).reshape(count, 9),
                  self._mag_normals.take(3 * latches), self._temperature_registers, np.frombuffer(bank0, dtype=np.uint8),
                  np.frombuffer(ak.regs, dtype=np.uint8), self._record_columns, records)
        self.bias_drift_rad_s = vectors[_V_DRIFT].copy()
        ak.last_index, ak.locked = int(settings[_I_AK_LAST_INDEX]), bool(settings[_I_AK_LOCKED])
        self._fifo_write(records.tobytes())
        bank0[reg.INT_STATUS_1] |= reg.INT_STATUS_1_RAW_DATA_0_RDY
        grid.index, accel_grid.index = last, accel_index

    # --- FIFO -------------------------------------------------------------------------

    def _fifo_record_spans(self) -> tuple[tuple[int, int], ...]:
        """Where a FIFO record's bytes sit in bank 0, in record order: the enabled sources'
        registers, in register order (DS 4.16). Remembered per setting: it is asked at
        every sample instant and changes only when the host reconfigures the FIFO."""
        bank0 = self.banks[0]
        key = (bank0[reg.FIFO_EN_2], bank0[reg.FIFO_EN_1], self.banks[3][reg.I2C_SLV0_CTRL])
        if key != self._record_key:
            enabled, slaves, slave_control = key
            spans = []
            if enabled & reg.FIFO_EN_2_ACCEL:
                spans.append((reg.ACCEL_XOUT_H, reg.GYRO_XOUT_H))
            for offset, bit in enumerate((reg.FIFO_EN_2_GYRO_X, reg.FIFO_EN_2_GYRO_Y, reg.FIFO_EN_2_GYRO_Z)):
                if enabled & bit:
                    spans.append((reg.GYRO_XOUT_H + 2 * offset, reg.GYRO_XOUT_H + 2 * offset + 2))
            if enabled & reg.FIFO_EN_2_TEMP:
                spans.append((reg.TEMP_OUT_H, reg.EXT_SLV_SENS_DATA_00))
            if slaves & reg.FIFO_EN_1_SLV_0:
                length = slave_control & reg.I2C_SLV_LENG_MASK
                spans.append((reg.EXT_SLV_SENS_DATA_00, reg.EXT_SLV_SENS_DATA_00 + length))
            # Adjacent spans as one slice: the usual record is one run of registers.
            merged: list[tuple[int, int]] = []
            for start, stop in spans:
                if merged and merged[-1][1] == start:
                    merged[-1] = (merged[-1][0], stop)
                else:
                    merged.append((start, stop))
            self._record_key, self._record_spans = key, tuple(merged)
            self._record_length = sum(stop - start for start, stop in merged)
            self._record_columns = np.array([register for start, stop in merged for register in range(start, stop)],
                                            dtype=np.int64)
        return self._record_spans

    def _fifo_record(self) -> bytes:
        """The enabled sources' current register bytes, in register order (DS 4.16)."""
        bank0 = self.banks[0]
        return b"".join([bank0[start:stop] for start, stop in self._fifo_record_spans()])

    def _fifo_overflowed(self) -> None:
        self.banks[0][reg.INT_STATUS_2] |= reg.INT_STATUS_2_FIFO_OVERFLOW & 0x01

    def _fifo_write(self, record: bytes) -> None:
        room = self.fifo_size_bytes - len(self.fifo)
        if len(record) <= room:
            self.fifo += record
            return
        self._fifo_overflowed()
        if self.banks[0][reg.FIFO_MODE] & reg.FIFO_MODE_SNAPSHOT:
            self.fifo += record[:room]  # the bytes that fit, then nothing until a reset
        else:
            self.fifo += record
            del self.fifo[:len(self.fifo) - self.fifo_size_bytes]  # the oldest go, records cut

    def _fifo_pop(self, length: int) -> bytes:
        """FIFO_R_W read: the oldest ``length`` bytes; an empty FIFO repeats the last byte."""
        out = bytes(self.fifo[:length])
        del self.fifo[:length]
        if out:
            self._fifo_last_byte = out[-1]
        return out + bytes([self._fifo_last_byte]) * (length - len(out))

    # --- register access --------------------------------------------------------------

    def read(self, register: int, length: int, now: float) -> bytes:
        self.tick(now)
        self._latch_for_register_read(register, length, now)
        bank0 = self.banks[0]
        end = register + length
        if self.bank == 0 and register == reg.FIFO_R_W:
            out = self._fifo_pop(length)  # the address does not advance: every byte pops
        elif end <= reg.REG_BANK_SEL and (self.bank != 0 or not any(register <= r < end for r in _READ_SPECIAL)):
            out = bytes(self.banks[self.bank][register:end])  # a sample burst: no wrap, no side effects
        else:
            out = self._read_bytewise(register, length)
        if bank0[reg.INT_PIN_CFG] & reg.INT_PIN_CFG_INT_ANYRD_2CLEAR:
            bank0[reg.INT_STATUS_1] = 0
        return out

    def _read_bytewise(self, register: int, length: int) -> bytes:
        out = bytearray()
        for _ in range(length):
            if register == reg.REG_BANK_SEL:
                out.append(self.bank << reg.BANK_SHIFT)
            elif self.bank == 0 and register == reg.FIFO_R_W:
                out += self._fifo_pop(1)
                continue  # FIFO_R_W does not advance the address
            elif self.bank == 0 and register == reg.FIFO_COUNTH:
                out.append((len(self.fifo) >> 8) & 0x1F)
            elif self.bank == 0 and register == reg.FIFO_COUNTL:
                out.append(len(self.fifo) & 0xFF)
            else:
                out.append(self.banks[self.bank][register])
                if self.bank == 0 and register in _READ_TO_CLEAR:
                    self.banks[0][register] = 0  # read-to-clear
            register = (register + 1) & 0x7F
        return bytes(out)

    _READ_ONLY = {
        0: {reg.WHO_AM_I, reg.I2C_MST_STATUS, reg.INT_STATUS_1, reg.INT_STATUS_2, reg.FIFO_COUNTH, reg.FIFO_COUNTL,
            reg.FIFO_R_W,
            *range(reg.ACCEL_XOUT_H, reg.EXT_SLV_SENS_DATA_00 + reg.EXT_SLV_SENS_DATA_COUNT)},
        3: {reg.I2C_SLV4_DI},
    }

    def write(self, register: int, data: Sequence[int], now: float) -> None:
        self.tick(now)
        for value in data:
            self._write_one(register, value, now)
            register = (register + 1) & 0x7F

    def _write_one(self, register: int, value: int, now: float) -> None:
        if register == reg.REG_BANK_SEL:
            self.bank = (value >> reg.BANK_SHIFT) & 0x03
            return
        if register in self._READ_ONLY.get(self.bank, ()):
            return
        bank = self.banks[self.bank]
        if self.bank == 0 and register == reg.PWR_MGMT_1:
            if value & reg.PWR_MGMT_1_DEVICE_RESET:
                bank[register] = value | reg.PWR_MGMT_1_DEVICE_RESET
                self.reset_until = now + _RESET_DURATION_S
                return
            was_awake = self.awake
            bank[register] = value
            if self.awake and not was_awake:
                self._anchor_all(now)
            return
        if self.bank == 0 and register == reg.USER_CTRL and value & reg.USER_CTRL_I2C_MST_RST:
            value &= ~reg.USER_CTRL_I2C_MST_RST & 0xFF  # self-clearing
        if self.bank == 0 and register == reg.FIFO_RST and value & reg.FIFO_RST_ASSERT:
            self.fifo.clear()
        bank[register] = value
        # A new divider restarts that sensor's output grid; the master's own clock runs on.
        if self.bank == 2 and register == reg.GYRO_SMPLRT_DIV:
            self.gyro_grid = _Grid(now)
        elif self.bank == 2 and register in (reg.ACCEL_SMPLRT_DIV_1, reg.ACCEL_SMPLRT_DIV_2):
            self.accel_grid = _Grid(now)


class Icm20948BusEmulator:
    """An `smbus2.SMBus` stand-in with ICM-20948s on it.

    plant: truth source (`Plant.sensor_truth(name, t)`, gravity and field).
    clock: time source; plant time = clock() (default time.monotonic). Drive it virtually
        in tests: nothing here sleeps.
    sensors: I2C address -> plant sensor name (default 0x68 "base", 0x69 "tip"); leave
        one out to emulate an absent chip.
    error_models: sensor name -> ImuErrorModel (default ImuErrorModel()).
    mounting: sensor name -> unit quaternion (w, x, y, z) of the IMU frame in the plant
        sensor frame (default identity: the IMU frame is the plant sensor frame).
    magnetic_disturbance_ut: sensor name -> extra field at that sensor, tracker frame (uT).
    seed: seeds the per-chip noise generators and the fault generator.
    fifo_size_bytes: each chip's FIFO (default the datasheet's 512 bytes).
    fault_probability: chance that any transaction fails with OSError(EIO).
    who_am_i: address -> WHO_AM_I value, to emulate a different part at an address
        (e.g. 0x71, an MPU-9250); default 0xEA.
    """

    # No transaction waits on anything (nothing here sleeps): `AsyncIcm20948` reads it
    # without a worker thread.
    calls_block = False

    def __init__(
        self,
        plant: Plant,
        clock: Callable[[], float] = time.monotonic,
        *,
        sensors: Mapping[int, str] | None = None,
        error_models: Mapping[str, ImuErrorModel] | None = None,
        mounting: Mapping[str, Sequence[float]] | None = None,
        magnetic_disturbance_ut: Mapping[str, Sequence[float]] | None = None,
        seed: int = 0,
        fault_probability: float = 0.0,
        who_am_i: Mapping[int, int] | None = None,
        fifo_size_bytes: int = reg.FIFO_SIZE_BYTES,
    ) -> None:
        if not 0.0 <= fault_probability <= 1.0:
            raise ValueError(f"fault_probability must be in [0, 1], got {fault_probability}")
        if not 0 < fifo_size_bytes <= 0x1FFF:
            raise ValueError(f"fifo_size_bytes must be 1..8191 (a 13-bit count), got {fifo_size_bytes}")
        self.plant = plant
        self.truths_at_instants = truths_at_instants(plant)
        self.clock = clock
        self.fifo_size_bytes = fifo_size_bytes
        self.who_am_i = dict(who_am_i or {})
        self._lock = threading.RLock()
        self._disturbance: dict[str, np.ndarray] = {}
        for name, vector in (magnetic_disturbance_ut or {}).items():
            self.set_magnetic_disturbance(name, vector)
        self.fault_probability = fault_probability
        self._fault_rng = np.random.default_rng([seed, 0xFA17])
        self._scheduled_faults: list[tuple[int | None, int]] = []
        self._detached: set[int] = set()
        self._pointer: dict[int, int] = {}
        self.transaction_count = 0
        models = error_models or {}
        mounts = mounting or {}
        self.chips: dict[int, _EmulatedIcm20948] = {}
        for address, sensor in (sensors if sensors is not None else DEFAULT_SENSORS).items():
            mount = matrix_from_quat(mounts[sensor]) if sensor in mounts else np.eye(3)
            self.chips[address] = _EmulatedIcm20948(
                self, address, sensor, models.get(sensor, ImuErrorModel()), mount, seed
            )

    # --- test and bench controls --------------------------------------------------------

    def set_magnetic_disturbance(self, sensor: str, field_in_tracker_ut: Sequence[float]) -> None:
        """Add a constant extra field (tracker frame, uT) at one sensor, e.g. a magnet."""
        vector = np.asarray(field_in_tracker_ut, dtype=float)
        if vector.shape != (3,) or not np.all(np.isfinite(vector)):
            raise ValueError(f"magnetic disturbance must be three finite numbers, got {field_in_tracker_ut!r}")
        with self._lock:
            self._disturbance[sensor] = vector

    def magnetic_disturbance(self, sensor: str) -> np.ndarray:
        return self._disturbance.get(sensor, np.zeros(3))

    def field_in_tracker_ut(self, sensor: str) -> np.ndarray:
        """The field at a sensor, tracker frame (uT): the plant's plus any disturbance."""
        return np.asarray(self.plant.magnetic_field_in_tracker_ut, dtype=float) + self.magnetic_disturbance(sensor)

    def gyro_bias_rad_s(self, sensor: str) -> np.ndarray:
        """The true current gyro bias of a sensor's chip (constant + drift so far), rad/s."""
        with self._lock:
            for chip in self.chips.values():
                if chip.sensor == sensor:
                    return chip.gyro_bias_rad_s().copy()
        raise KeyError(f"no emulated chip for sensor {sensor!r}")

    def fail_next(self, count: int = 1, *, errno: int = errno_codes.EIO, address: int | None = None) -> None:
        """Make the next `count` transactions (to `address`, or to any) raise OSError."""
        with self._lock:
            self._scheduled_faults.extend([(address, errno)] * count)

    def detach(self, address: int) -> None:
        """Unplug a chip: it stops acknowledging (its registers keep their state)."""
        with self._lock:
            self._detached.add(address)

    def attach(self, address: int) -> None:
        with self._lock:
            self._detached.discard(address)

    def run_chips(self) -> None:
        """Bring every chip up to ``clock()`` now, as silicon samples between transactions
        too. A later read finds the same samples whenever this is called (the FIFO tests
        check it), until a FIFO overflows: instants a full FIFO drops are not sampled, so
        the noise draws they cost, and the noise after them, depend on when the chip was
        looked at. Called often, it does the sampling work in small slices instead of
        all at the read (the simulated rig no longer does: a read's batched run costs
        less than the looks between reads did)."""
        with self._lock:
            now = self.clock()
            for chip in self.chips.values():
                chip.tick(now)

    # --- bus plumbing -----------------------------------------------------------------

    def _device(self, address: int) -> _EmulatedIcm20948:
        """The chip at `address` after fault injection; OSError like the kernel driver."""
        self.transaction_count += 1
        for index, (target, code) in enumerate(self._scheduled_faults):
            if target is None or target == address:
                del self._scheduled_faults[index]
                raise OSError(code, os.strerror(code))
        if self.fault_probability and self._fault_rng.random() < self.fault_probability:
            raise OSError(errno_codes.EIO, os.strerror(errno_codes.EIO))
        chip = self.chips.get(address)
        if chip is None or address in self._detached:
            # No ACK on the address byte: i2c-dev reports EREMOTEIO (121).
            raise OSError(errno_codes.EREMOTEIO, os.strerror(errno_codes.EREMOTEIO))
        return chip

    @staticmethod
    def _check_byte(name: str, value: int) -> int:
        if not isinstance(value, int) or not 0 <= value <= 0xFF:
            raise ValueError(f"{name} must be an int 0..255, got {value!r}")
        return value

    # --- the smbus2.SMBus surface -----------------------------------------------------

    def read_byte_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int:
        with self._lock:
            chip = self._device(i2c_addr)
            return chip.read(self._check_byte("register", register), 1, self.clock())[0]

    def write_byte_data(self, i2c_addr: int, register: int, value: int, force: bool | None = None) -> None:
        with self._lock:
            chip = self._device(i2c_addr)
            chip.write(self._check_byte("register", register), [self._check_byte("value", value)], self.clock())

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int, force: bool | None = None) -> list[int]:
        if length > reg.SMBUS_BLOCK_MAX:
            # Same check and message as smbus2 (I2C_SMBUS_BLOCK_MAX).
            raise ValueError(f"Desired block length over {reg.SMBUS_BLOCK_MAX} bytes")
        with self._lock:
            chip = self._device(i2c_addr)
            if length < 1:
                raise OSError(errno_codes.EINVAL, os.strerror(errno_codes.EINVAL))
            return list(chip.read(self._check_byte("register", register), length, self.clock()))

    def write_i2c_block_data(self, i2c_addr: int, register: int, data: Sequence[int], force: bool | None = None) -> None:
        if len(data) > reg.SMBUS_BLOCK_MAX:
            raise ValueError(f"Data length cannot exceed {reg.SMBUS_BLOCK_MAX} bytes")
        values = [self._check_byte("data byte", v) for v in data]
        with self._lock:
            chip = self._device(i2c_addr)
            chip.write(self._check_byte("register", register), values, self.clock())

    def write_byte(self, i2c_addr: int, value: int, force: bool | None = None) -> None:
        """Set the register pointer (a one-byte write)."""
        with self._lock:
            self._device(i2c_addr)
            self._pointer[i2c_addr] = self._check_byte("value", value)

    def read_byte(self, i2c_addr: int, force: bool | None = None) -> int:
        """Read at the register pointer, which then advances."""
        with self._lock:
            chip = self._device(i2c_addr)
            register = self._pointer.get(i2c_addr, 0)
            self._pointer[i2c_addr] = (register + 1) & 0x7F
            return chip.read(register, 1, self.clock())[0]

    def i2c_rdwr(self, *i2c_msgs: Any) -> None:
        """Combined transfer of `smbus2.i2c_msg`s: a write sets the register pointer (and
        writes any further bytes); a read returns bytes from the pointer on."""
        if len(i2c_msgs) > _MAX_RDWR_MESSAGES:
            raise OSError(errno_codes.EINVAL, os.strerror(errno_codes.EINVAL))
        with self._lock:
            now = self.clock()
            for message in i2c_msgs:
                chip = self._device(message.addr)
                if message.flags & 0x0001:  # I2C_M_RD
                    register = self._pointer.get(message.addr, 0)
                    data = chip.read(register, message.len, now)
                    ctypes.memmove(message.buf, data, message.len)
                    self._pointer[message.addr] = (register + message.len) & 0x7F
                else:
                    payload = bytes(message)
                    if not payload:
                        continue
                    register = payload[0]
                    if len(payload) > 1:
                        chip.write(register, payload[1:], now)
                    self._pointer[message.addr] = (register + len(payload) - 1) & 0x7F

    def close(self) -> None:
        """Nothing to release (mirrors SMBus.close)."""

    def __enter__(self) -> Icm20948BusEmulator:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
