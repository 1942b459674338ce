"""Two ICM-20948 IMUs (0x68 base, 0x69 tip) on one I2C bus, each with its AK09916
magnetometer read through the chip's auxiliary I2C master.

Layers: `registers` (datasheet register map), `codec` (one burst or FIFO record <-> `RawImuSample`,
SI units), `driver` (`Icm20948`, synchronous register-level start-up and sampling over
any `smbus2.SMBus`-like object), `async_driver` (worker thread + timeout for the bench; none on a bus that never blocks),
`calibration` (gyro bias, hard/soft iron), `fusion` (the orientation filter seam with
`imufusion` and `ahrs` Madgwick behind it, and the tip-relative-to-base rotation),
`fusion_benchmark` (the filters scored on the emulator) and `emulator` (`Icm20948BusEmulator`, an SMBus stand-in
that synthesises both chips from a `drivers.plant.Plant`).

Real bus: `Icm20948(smbus2.SMBus(1), 0x68)`.
"""

from drivers.imu.async_driver import AsyncIcm20948
from drivers.imu.calibration import GyroBiasEstimate, ImuCalibration, ImuSample, estimate_gyro_bias
from drivers.imu.codec import ImuRanges, RawImuSample, decode_burst, decode_fifo, encode_burst
from drivers.imu.driver import FifoRead, Icm20948, output_rate_hz, sample_rate_divider_for
from drivers.imu.emulator import Icm20948BusEmulator, ImuErrorModel
from drivers.imu.errors import (
    ImuAuxBusError,
    ImuBusError,
    ImuConfigError,
    ImuError,
    ImuIdentityError,
    ImuMotionError,
    ImuNotFoundError,
    ImuProtocolError,
    ImuTimeoutError,
)
from drivers.imu.fusion import ImuOrientationFilter, ImuPairFusion, paired_samples, tip_relative_to_base

__all__ = [
    "AsyncIcm20948",
    "FifoRead",
    "GyroBiasEstimate",
    "Icm20948",
    "Icm20948BusEmulator",
    "ImuAuxBusError",
    "ImuBusError",
    "ImuCalibration",
    "ImuConfigError",
    "ImuError",
    "ImuErrorModel",
    "ImuIdentityError",
    "ImuMotionError",
    "ImuNotFoundError",
    "ImuOrientationFilter",
    "ImuPairFusion",
    "ImuProtocolError",
    "ImuRanges",
    "ImuSample",
    "ImuTimeoutError",
    "RawImuSample",
    "decode_burst",
    "decode_fifo",
    "encode_burst",
    "estimate_gyro_bias",
    "output_rate_hz",
    "paired_samples",
    "sample_rate_divider_for",
    "tip_relative_to_base",
]
