"""Pure codec: one register burst of the ICM-20948 <-> a `RawImuSample` in SI units.

The burst is what one read from ACCEL_XOUT_H (0x2D) returns once the auxiliary I2C master
copies the AK09916's ST1..ST2 into EXT_SLV_SENS_DATA (see `registers`):

    offset  0..5   accel X, Y, Z   big-endian int16
    offset  6..11  gyro X, Y, Z    big-endian int16
    offset 12..13  temperature     big-endian int16
    offset 14      AK09916 ST1     (DRDY bit 0, DOR bit 1, bits 7:2 always zero)
    offset 15..20  mag X, Y, Z     little-endian int16, AK09916 die axes
    offset 21      TMPS            dummy
    offset 22      AK09916 ST2     (HOFL bit 3; bits 7 and 2:0 always zero)

The FIFO (`registers.FIFO_EN_2_MOTION` with SLV0) holds the same 23 bytes per sample
instant, oldest first: `decode_fifo` splits whole records and decodes each.

There is no stream to resynchronise: an I2C register read either returns the requested
number of bytes or fails, so the decoder is a plain function. It raises only
`ImuProtocolError`: for a wrong length, for status bytes whose always-zero bits are set,
and for magnetometer counts outside the AK09916's +-32752 output range (either way the
auxiliary master copied something that is not an AK09916 measurement). A magnetic
overflow (HOFL) is not an error: it is flagged and the meaningless field is withheld.

Frames and units: every vector is in the ICM-20948 accel/gyro frame (the magnetometer is
re-signed from the AK09916 die axes); accel m/s^2 (specific force: reads +g up at rest),
gyro rad/s, magnetic field uT, temperature degC.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from functools import cached_property

from drivers.imu import registers as reg
from drivers.imu.errors import ImuProtocolError

Vector3 = tuple[float, float, float]

_MOTION = struct.Struct(">7h")  # accel xyz, gyro xyz, temperature
_MAG = struct.Struct("<BhhhBB")  # ST1, HX, HY, HZ, TMPS, ST2
_ST1_ZERO_BITS = 0xFC
_ST2_ZERO_BITS = 0x87
_INT16_MAX = 32767
_INT16_MIN = -32768
_MAG_COUNT_LIMIT = reg.MAG_COUNT_LIMIT


@dataclass(frozen=True)
class ImuRanges:
    """Configured full scales: accelerometer +-g and gyroscope +-deg/s."""

    accel_full_scale_g: int = 4
    gyro_full_scale_dps: int = 500

    def __post_init__(self) -> None:
        if self.accel_full_scale_g not in {fs for fs, _ in reg.ACCEL_FULL_SCALES.values()}:
            raise ValueError(f"accel_full_scale_g must be 2, 4, 8 or 16, got {self.accel_full_scale_g!r}")
        if self.gyro_full_scale_dps not in {fs for fs, _ in reg.GYRO_FULL_SCALES.values()}:
            raise ValueError(
                f"gyro_full_scale_dps must be 250, 500, 1000 or 2000, got {self.gyro_full_scale_dps!r}"
            )

    @property
    def accel_fs_sel(self) -> int:
        """ACCEL_FS_SEL field value (ACCEL_CONFIG bits 2:1)."""
        return next(k for k, (fs, _) in reg.ACCEL_FULL_SCALES.items() if fs == self.accel_full_scale_g)

    @property
    def gyro_fs_sel(self) -> int:
        """GYRO_FS_SEL field value (GYRO_CONFIG_1 bits 2:1)."""
        return next(k for k, (fs, _) in reg.GYRO_FULL_SCALES.items() if fs == self.gyro_full_scale_dps)

    # Cached: every decoded sample asks for both (the field values never change).
    @cached_property
    def accel_m_s2_per_lsb(self) -> float:
        return reg.STANDARD_GRAVITY_M_S2 / reg.ACCEL_FULL_SCALES[self.accel_fs_sel][1]

    @cached_property
    def gyro_rad_s_per_lsb(self) -> float:
        return reg.DEG_TO_RAD / reg.GYRO_FULL_SCALES[self.gyro_fs_sel][1]


TEMPERATURE_DEGC_PER_LSB = 1.0 / reg.TEMP_SENSITIVITY_LSB_PER_DEGC


@dataclass(frozen=True)
class RawImuSample:
    """One decoded burst, uncalibrated, in the accel/gyro frame.

    accel_m_s2: specific force (m/s^2); gyro_rad_s: angular rate (rad/s);
    temperature_degc: die temperature (degC);
    mag_ut: magnetic field (uT), None exactly when mag_overflow is set;
    mag_data_ready: ST1 DRDY, a new magnetometer measurement since the previous read
        (otherwise mag_ut repeats the last one);
    mag_data_overrun: ST1 DOR, a measurement was skipped before this one;
    mag_overflow: ST2 HOFL, the field exceeded the measurement range.
    """

    accel_m_s2: Vector3
    gyro_rad_s: Vector3
    temperature_degc: float
    mag_ut: Vector3 | None
    mag_data_ready: bool = True
    mag_data_overrun: bool = False
    mag_overflow: bool = False

    def __post_init__(self) -> None:
        for name in ("accel_m_s2", "gyro_rad_s", "mag_ut"):
            value = getattr(self, name)
            if value is None and name == "mag_ut":
                continue
            if len(value) != 3 or not (math.isfinite(value[0]) and math.isfinite(value[1])
                                       and math.isfinite(value[2])):
                raise ValueError(f"{name} must be three finite numbers, got {value!r}")
        if not math.isfinite(self.temperature_degc):
            raise ValueError(f"temperature_degc must be finite, got {self.temperature_degc!r}")
        if (self.mag_ut is None) != self.mag_overflow:
            raise ValueError("mag_ut must be None exactly when mag_overflow is set")


def decode_burst(data: bytes | bytearray | list[int], ranges: ImuRanges) -> RawImuSample:
    """Decode one `registers.BURST_LENGTH`-byte burst read from ACCEL_XOUT_H.

    Raises ImuProtocolError for a wrong length, non-byte values, or status bytes with
    their always-zero bits set."""
    if isinstance(data, (int, str)):
        # bytes(5) would silently make five zero bytes
        raise ImuProtocolError(f"burst must be bytes, got {type(data).__name__}")
    try:
        raw = bytes(data)
    except (TypeError, ValueError) as exc:
        raise ImuProtocolError(f"burst is not a sequence of bytes: {exc}") from None
    if len(raw) != reg.BURST_LENGTH:
        raise ImuProtocolError(f"burst must be {reg.BURST_LENGTH} bytes, got {len(raw)}")
    ax, ay, az, gx, gy, gz, temp = _MOTION.unpack_from(raw, 0)
    st1, hx, hy, hz, _tmps, st2 = _MAG.unpack_from(raw, reg.MOTION_BYTES)
    if st1 & _ST1_ZERO_BITS:
        raise ImuProtocolError(f"AK09916 ST1 = 0x{st1:02X} has reserved bits set: not a status byte")
    if st2 & _ST2_ZERO_BITS:
        raise ImuProtocolError(f"AK09916 ST2 = 0x{st2:02X} has reserved bits set: not a status byte")
    a = ranges.accel_m_s2_per_lsb
    g = ranges.gyro_rad_s_per_lsb
    overflow = bool(st2 & reg.AK_ST2_HOFL)
    mag: Vector3 | None = None
    if not overflow:
        if max(abs(hx), abs(hy), abs(hz)) > _MAG_COUNT_LIMIT:
            raise ImuProtocolError(
                f"magnetometer counts {(hx, hy, hz)} outside the AK09916's +-{_MAG_COUNT_LIMIT} range"
            )
        sx, sy, sz = reg.MAG_AXIS_SIGNS_IN_IMU_FRAME
        m = reg.MAG_UT_PER_LSB
        mag = (sx * hx * m, sy * hy * m, sz * hz * m)
    return RawImuSample(
        accel_m_s2=(ax * a, ay * a, az * a),
        gyro_rad_s=(gx * g, gy * g, gz * g),
        temperature_degc=temp * TEMPERATURE_DEGC_PER_LSB + reg.TEMP_OFFSET_DEGC,
        mag_ut=mag,
        mag_data_ready=bool(st1 & reg.AK_ST1_DRDY),
        mag_data_overrun=bool(st1 & reg.AK_ST1_DOR),
        mag_overflow=overflow,
    )


def decode_fifo(data: bytes | bytearray, ranges: ImuRanges) -> list[RawImuSample]:
    """Decode whole `registers.FIFO_RECORD_LENGTH`-byte FIFO records, oldest first.

    Raises ImuProtocolError when the length is not a whole number of records (the reader
    lost the record boundary) or when any record fails `decode_burst`."""
    if not isinstance(data, (bytes, bytearray)):
        raise ImuProtocolError(f"FIFO data must be bytes, got {type(data).__name__}")
    size = reg.FIFO_RECORD_LENGTH
    if len(data) % size:
        raise ImuProtocolError(f"FIFO data of {len(data)} bytes is not a whole number of {size}-byte records")
    view = bytes(data)
    return [decode_burst(view[start:start + size], ranges) for start in range(0, len(view), size)]


def _counts(value: float, per_lsb: float, low: int, high: int) -> int:
    """Nearest register count, saturating like the sensor does at full scale."""
    return max(low, min(high, round(value / per_lsb)))


def encode_motion(accel_m_s2: Vector3, gyro_rad_s: Vector3, temperature_degc: float, ranges: ImuRanges) -> bytes:
    """The 14 bytes ACCEL_XOUT_H..TEMP_OUT_L for these values (saturating at full scale)."""
    a = ranges.accel_m_s2_per_lsb
    g = ranges.gyro_rad_s_per_lsb
    return _MOTION.pack(
        *(_counts(v, a, _INT16_MIN, _INT16_MAX) for v in accel_m_s2),
        *(_counts(v, g, _INT16_MIN, _INT16_MAX) for v in gyro_rad_s),
        _counts(temperature_degc - reg.TEMP_OFFSET_DEGC, TEMPERATURE_DEGC_PER_LSB, _INT16_MIN, _INT16_MAX),
    )


def encode_mag_counts(mag_ut_in_imu_frame: Vector3) -> tuple[int, int, int]:
    """AK09916 die-axis counts of a field given in the accel/gyro frame (saturating)."""
    return tuple(  # type: ignore[return-value]
        _counts(s * v, reg.MAG_UT_PER_LSB, -_MAG_COUNT_LIMIT, _MAG_COUNT_LIMIT)
        for s, v in zip(reg.MAG_AXIS_SIGNS_IN_IMU_FRAME, mag_ut_in_imu_frame)
    )


def encode_ak09916_block(
    counts: tuple[int, int, int], *, data_ready: bool, overrun: bool, overflow: bool
) -> bytes:
    """The AK09916's ST1, HXL..HZH, TMPS, ST2 (9 bytes) for die-axis counts."""
    st1 = (reg.AK_ST1_DRDY if data_ready else 0) | (reg.AK_ST1_DOR if overrun else 0)
    st2 = reg.AK_ST2_HOFL if overflow else 0
    return _MAG.pack(st1, *counts, 0, st2)


def encode_burst(sample: RawImuSample, ranges: ImuRanges) -> bytes:
    """Inverse of `decode_burst` to within one LSB per field (values saturate at full
    scale). An overflowed magnetometer is encoded with HOFL set and zero data."""
    counts = (0, 0, 0) if sample.mag_ut is None else encode_mag_counts(sample.mag_ut)
    return encode_motion(sample.accel_m_s2, sample.gyro_rad_s, sample.temperature_degc, ranges) + (
        encode_ak09916_block(
            counts,
            data_ready=sample.mag_data_ready,
            overrun=sample.mag_data_overrun,
            overflow=sample.mag_overflow,
        )
    )
