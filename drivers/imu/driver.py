"""Synchronous register-level driver of one ICM-20948 (with its AK09916) on an I2C bus.

I2C register access is short and blocking by nature, so this layer is synchronous; the
bench runs it through `drivers.imu.async_driver.AsyncIcm20948`, which moves each call to
a worker thread under a per-bus lock and bounds it with a timeout (sample reads on an
emulated bus, which never blocks, stay on the caller's thread).

Two chips share one bus (0x68 base, 0x69 tip) and both AK09916s answer at 0x0C on their
chip's auxiliary bus. Bypass mode would put both at 0x0C on the host bus, so the driver
keeps bypass off and reads each magnetometer through its own chip's I2C master: SLV4 for
single set-up transfers, SLV0 to copy ST1..ST2 into EXT_SLV_SENS_DATA at every sample.
One burst from ACCEL_XOUT_H then returns everything (`codec`).

At the rig's 100 Hz a host that reads one burst per sample loses every sample it is late
for: the data registers hold only the newest. `enable_fifo` makes the chip queue one
record per sample instant (the burst's 23 bytes) in its FIFO, and `read_fifo` drains the
whole records in one transfer, so a host that is late by up to the FIFO's depth (22
records, ~0.2 s at 102 Hz) loses nothing; one that is later loses what the FIFO held and
is told (`FifoRead.overflowed`).

Every transaction is retried a bounded number of times on OSError (a glitch on a long
cable, EREMOTEIO on a missed ACK) before a typed error names the address.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from smbus2 import i2c_msg

from drivers.imu import registers as reg
from drivers.imu.calibration import GyroBiasEstimate, ImuCalibration, ImuSample, estimate_gyro_bias
from drivers.imu.codec import ImuRanges, RawImuSample, decode_burst, decode_fifo
from drivers.imu.errors import (
    ImuAuxBusError,
    ImuBusError,
    ImuConfigError,
    ImuIdentityError,
    ImuNotFoundError,
    ImuProtocolError,
)

T = TypeVar("T")


class SmbusLike(Protocol):
    """The subset of `smbus2.SMBus` the driver uses (so an emulator or mock can stand in).
    A bus whose calls never wait may also say ``calls_block = False`` (`async_driver`)."""

    def read_byte_data(self, i2c_addr: int, register: int) -> int: ...

    def write_byte_data(self, i2c_addr: int, register: int, value: int) -> None: ...

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> list[int]: ...

    def i2c_rdwr(self, *i2c_msgs: Any) -> None: ...


# DLPF configuration 3 (DS 10, GYRO_CONFIG_1 / ACCEL_CONFIG tables): about 51 Hz (gyro)
# and 50 Hz (accel) 3 dB bandwidth, just under Nyquist at the default ~102 Hz output rate.
DEFAULT_DLPF_CONFIG = 3
# 1125 Hz / (1 + 10) = 102.3 Hz: a little above the AK09916's 100 Hz, so every magnetometer
# sample is read and the fusion runs at about the magnetometer's rate.
DEFAULT_SAMPLE_RATE_DIVIDER = 10

# Waits of the start-up sequence (s). DS 3 gives ~35 ms gyro start-up; the reset and the
# AK09916 soft reset are given generous margins since they run once.
_RESET_WAIT_S = 0.1
_WAKE_WAIT_S = 0.05
_AK_RESET_WAIT_S = 0.01
_RESET_POLLS = 10
_RESET_POLL_S = 0.01
# SLV4 transfers run at the next internal sample (<= ~9 ms at the slowest rate we allow);
# poll for up to ~100 ms.
_AUX_POLLS = 50
_AUX_POLL_S = 0.002


@dataclass(frozen=True)
class FifoRead:
    """What one `Icm20948.read_fifo` drained. samples: calibrated, oldest first, stamped
    one output period apart on the host clock (s); overflowed: the FIFO had filled, so
    its content was dropped and it restarts empty (samples lost since the last read)."""

    samples: tuple[ImuSample, ...]
    overflowed: bool


def sample_rate_divider_for(rate_hz: float) -> int:
    """GYRO_SMPLRT_DIV whose output rate, 1125 Hz / (1 + divider), is nearest ``rate_hz``
    at or above it (so a consumer asking for 100 Hz gets 102.3 Hz, never fewer)."""
    if not 0 < rate_hz <= reg.BASE_SAMPLE_RATE_HZ:
        raise ValueError(f"IMU rate must be in (0, {reg.BASE_SAMPLE_RATE_HZ:g}] Hz, got {rate_hz!r}")
    return min(255, max(0, int(reg.BASE_SAMPLE_RATE_HZ / rate_hz) - 1))


def output_rate_hz(rate_hz: float) -> float:
    """The output rate (Hz) the chip runs at when ``rate_hz`` is asked (`sample_rate_divider_for`)."""
    return reg.BASE_SAMPLE_RATE_HZ / (1 + sample_rate_divider_for(rate_hz))


class Icm20948:
    """One ICM-20948 at `address` on `bus` (anything with the `SmbusLike` methods, such as
    `smbus2.SMBus(bus_number)`).

    ranges: accel/gyro full scales; sample_rate_divider: ODR = 1125 Hz / (1 + divider),
    0..255; dlpf_config: 0..7 for both DLPFs; retries: extra attempts per transaction
    after an OSError; clock: host time source for sample stamps (s); sleep: used for
    every wait, so tests can run on virtual time; calibration: applied by `read_sample`.
    """

    def __init__(
        self,
        bus: SmbusLike,
        address: int = reg.ICM20948_ADDRESS_AD0_LOW,
        *,
        ranges: ImuRanges | None = None,
        sample_rate_divider: int = DEFAULT_SAMPLE_RATE_DIVIDER,
        dlpf_config: int = DEFAULT_DLPF_CONFIG,
        retries: int = 3,
        retry_delay_s: float = 0.001,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        calibration: ImuCalibration | None = None,
    ) -> None:
        if address not in (reg.ICM20948_ADDRESS_AD0_LOW, reg.ICM20948_ADDRESS_AD0_HIGH):
            raise ValueError(f"ICM-20948 address must be 0x68 or 0x69, got {address:#04x}")
        if not 0 <= sample_rate_divider <= 255:
            raise ValueError(f"sample_rate_divider must be 0..255, got {sample_rate_divider}")
        if not 0 <= dlpf_config <= 7:
            raise ValueError(f"dlpf_config must be 0..7, got {dlpf_config}")
        if retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        self.bus = bus
        self.address = address
        self.ranges = ranges or ImuRanges()
        self.sample_rate_divider = sample_rate_divider
        self.dlpf_config = dlpf_config
        self.retries = retries
        self.retry_delay_s = retry_delay_s
        self.clock = clock
        self.sleep = sleep
        self.calibration = calibration or ImuCalibration()
        # The bank the chip is in, or None when unknown (before init, after any failure:
        # a failed transaction may or may not have reached the chip).
        self._bank: int | None = None
        self.initialized = False
        # Host time of the newest FIFO record drained, None until the first read after a reset.
        self._fifo_newest_t_s: float | None = None

    # --- properties -----------------------------------------------------------------

    @property
    def sample_rate_hz(self) -> float:
        """Output data rate of accel, gyro and the SLV0 copy of the magnetometer (Hz)."""
        return reg.BASE_SAMPLE_RATE_HZ / (1 + self.sample_rate_divider)

    @property
    def sample_period_s(self) -> float:
        return 1.0 / self.sample_rate_hz

    # --- transactions with bounded retries -------------------------------------------

    def _retrying(self, operation: str, action: Callable[[], T]) -> T:
        last: OSError | None = None
        for attempt in range(self.retries + 1):
            if attempt:
                self.sleep(self.retry_delay_s)
            try:
                return action()
            except OSError as exc:
                last = exc
                self._bank = None
        assert last is not None
        raise ImuBusError(self.address, operation, last.errno, str(last))

    def _select_bank(self, bank: int) -> None:
        if self._bank != bank:
            self.bus.write_byte_data(self.address, reg.REG_BANK_SEL, reg.bank_select_value(bank))
            self._bank = bank

    def read_register(self, bank: int, register: int) -> int:
        """One register of a user bank."""

        def action() -> int:
            self._select_bank(bank)
            return int(self.bus.read_byte_data(self.address, register))

        return self._retrying(f"read bank {bank} register 0x{register:02X}", action)

    def write_register(self, bank: int, register: int, value: int) -> None:
        """Write one register of a user bank."""
        if not 0 <= value <= 0xFF:
            raise ValueError(f"register value must be 0..255, got {value}")

        def action() -> None:
            self._select_bank(bank)
            self.bus.write_byte_data(self.address, register, value)

        self._retrying(f"write bank {bank} register 0x{register:02X}", action)

    def read_registers(self, bank: int, register: int, length: int) -> bytes:
        """`length` consecutive registers in ONE bus transaction (the chip auto-increments
        the address). Up to 32 bytes use an SMBus block read, longer ones a combined
        write-then-read `i2c_rdwr`: two block reads would not be one coherent sample."""
        if length < 1:
            raise ValueError(f"length must be >= 1, got {length}")

        def action() -> bytes:
            self._select_bank(bank)
            if length <= reg.SMBUS_BLOCK_MAX:
                return bytes(self.bus.read_i2c_block_data(self.address, register, length))
            write = i2c_msg.write(self.address, [register])
            read = i2c_msg.read(self.address, length)
            self.bus.i2c_rdwr(write, read)
            return bytes(read)

        return self._retrying(f"read {length} bytes from bank {bank} register 0x{register:02X}", action)

    def _write_verified(self, bank: int, register: int, value: int, name: str) -> None:
        self.write_register(bank, register, value)
        got = self.read_register(bank, register)
        if got != value:
            raise ImuConfigError(self.address, f"{name} reads back 0x{got:02X} after writing 0x{value:02X}")

    # --- start-up ---------------------------------------------------------------------

    def probe(self) -> None:
        """Check that an ICM-20948 answers: ImuNotFoundError without an ACK,
        ImuIdentityError if WHO_AM_I is not 0xEA. Touches nothing but REG_BANK_SEL."""
        self._bank = None
        try:
            self._select_bank_checked(0)
        except ImuBusError as exc:
            raise ImuNotFoundError(self.address, exc.errno) from exc
        who = self.read_register(0, reg.WHO_AM_I)
        if who != reg.WHO_AM_I_VALUE:
            raise ImuIdentityError(self.address, "ICM-20948", "WHO_AM_I", reg.WHO_AM_I_VALUE, who)

    def initialize(self) -> None:
        """Full start-up: probe, reset, wake, ranges and rates, auxiliary master, AK09916
        identity and continuous 100 Hz mode, SLV0 copy of ST1..ST2. Ends in bank 0."""
        self.initialized = False
        self.probe()
        # Reset so a chip left half-configured by a crashed run starts from known state.
        self.write_register(0, reg.PWR_MGMT_1, reg.PWR_MGMT_1_DEVICE_RESET)
        self._bank = None  # the reset returns the chip to bank 0, but confirm it below
        self.sleep(_RESET_WAIT_S)
        for _ in range(_RESET_POLLS):
            if not self.read_register(0, reg.PWR_MGMT_1) & reg.PWR_MGMT_1_DEVICE_RESET:
                break
            self.sleep(_RESET_POLL_S)
        else:
            raise ImuConfigError(self.address, "DEVICE_RESET did not clear")
        # Wake from the reset's sleep state with the auto-selected (PLL) clock.
        self.write_register(0, reg.PWR_MGMT_1, reg.PWR_MGMT_1_CLKSEL_AUTO)
        self.sleep(_WAKE_WAIT_S)
        self.write_register(0, reg.PWR_MGMT_2, reg.PWR_MGMT_2_ALL_ON)
        # Bypass must stay off: with two chips it would put both AK09916s at 0x0C.
        self.write_register(0, reg.INT_PIN_CFG, 0x00)
        # The master copies ST1..ST2 at every gyro sample, not on its faster duty-cycled
        # clock (LP_CONFIG.I2C_MST_CYC, set at reset), so each burst's DRDY tells whether
        # the magnetometer value is new since the previous sample.
        self.write_register(0, reg.LP_CONFIG, 0x00)
        self._configure_motion()
        self._configure_aux_master()
        self._select_bank_checked(0)
        # Let the first SLV0 copy and a magnetometer measurement happen.
        self.sleep(max(2.0 * self.sample_period_s, 0.02))
        self.initialized = True

    def _select_bank_checked(self, bank: int) -> None:
        self._retrying(f"select bank {bank}", lambda: self._select_bank(bank))

    def _configure_motion(self) -> None:
        div = self.sample_rate_divider
        dlpf = self.dlpf_config << reg.CONFIG_DLPF_SHIFT
        gyro_config = dlpf | (self.ranges.gyro_fs_sel << reg.CONFIG_FS_SHIFT) | reg.CONFIG_FCHOICE_DLPF
        accel_config = dlpf | (self.ranges.accel_fs_sel << reg.CONFIG_FS_SHIFT) | reg.CONFIG_FCHOICE_DLPF
        self._write_verified(2, reg.GYRO_SMPLRT_DIV, div, "GYRO_SMPLRT_DIV")
        self._write_verified(2, reg.GYRO_CONFIG_1, gyro_config, "GYRO_CONFIG_1")
        self.write_register(2, reg.ACCEL_SMPLRT_DIV_1, div >> 8)
        self._write_verified(2, reg.ACCEL_SMPLRT_DIV_2, div & 0xFF, "ACCEL_SMPLRT_DIV_2")
        self._write_verified(2, reg.ACCEL_CONFIG, accel_config, "ACCEL_CONFIG")

    def _configure_aux_master(self) -> None:
        self.write_register(0, reg.USER_CTRL, reg.USER_CTRL_I2C_MST_EN)
        self.write_register(3, reg.I2C_MST_CTRL, reg.I2C_MST_CLK_RECOMMENDED)
        self.aux_write(reg.AK_CNTL3, reg.AK_CNTL3_SRST)
        self.sleep(_AK_RESET_WAIT_S)
        wia2 = self.aux_read(reg.AK_WIA2)
        if wia2 != reg.AK_WIA2_VALUE:
            raise ImuIdentityError(self.address, "AK09916", "WIA2", reg.AK_WIA2_VALUE, wia2)
        self.aux_write(reg.AK_CNTL2, reg.AK_MODE_CONTINUOUS_100HZ)
        # SLV0 reads ST1..ST2 at every sample: reading through ST2 releases the next one.
        self.write_register(3, reg.I2C_SLV0_ADDR, reg.I2C_SLV_READ | reg.AK09916_ADDRESS)
        self.write_register(3, reg.I2C_SLV0_REG, reg.AK_BURST_START)
        self.write_register(3, reg.I2C_SLV0_CTRL, reg.I2C_SLV_EN | reg.AK_BURST_LENGTH)

    # --- single transfers on the auxiliary bus (SLV4) ---------------------------------

    def _aux_transfer(self, ak_register: int, value: int | None) -> None:
        read = value is None
        self.write_register(3, reg.I2C_SLV4_ADDR, (reg.I2C_SLV_READ if read else 0) | reg.AK09916_ADDRESS)
        self.write_register(3, reg.I2C_SLV4_REG, ak_register)
        if not read:
            self.write_register(3, reg.I2C_SLV4_DO, value)
        self.write_register(3, reg.I2C_SLV4_CTRL, reg.I2C_SLV_EN)
        what = f"{'read' if read else 'write'} AK09916 register 0x{ak_register:02X}"
        for _ in range(_AUX_POLLS):
            self.sleep(_AUX_POLL_S)
            status = self.read_register(0, reg.I2C_MST_STATUS)
            if status & reg.I2C_MST_STATUS_SLV4_NACK:
                raise ImuAuxBusError(self.address, f"{what}: no ACK from 0x0C")
            if status & reg.I2C_MST_STATUS_SLV4_DONE:
                return
        raise ImuAuxBusError(self.address, f"{what}: SLV4 transfer never completed")

    def aux_read(self, ak_register: int) -> int:
        """One AK09916 register through SLV4."""
        self._aux_transfer(ak_register, None)
        return self.read_register(3, reg.I2C_SLV4_DI)

    def aux_write(self, ak_register: int, value: int) -> None:
        """Write one AK09916 register through SLV4."""
        if not 0 <= value <= 0xFF:
            raise ValueError(f"register value must be 0..255, got {value}")
        self._aux_transfer(ak_register, value)

    # --- samples ----------------------------------------------------------------------

    def read_raw(self) -> RawImuSample:
        """One burst, decoded (uncalibrated). A burst that fails to decode is re-read up to
        `retries` times before its ImuProtocolError propagates."""
        for attempt in range(self.retries + 1):
            burst = self.read_registers(0, reg.BURST_START, reg.BURST_LENGTH)
            try:
                return decode_burst(burst, self.ranges)
            except ImuProtocolError:
                if attempt == self.retries:
                    raise
        raise AssertionError("unreachable")

    def read_sample(self) -> ImuSample:
        """One burst, calibrated with `self.calibration`, stamped with `clock()`."""
        t_s = self.clock()
        return self.calibration.apply(self.read_raw(), t_s)

    # --- the FIFO -------------------------------------------------------------------

    def enable_fifo(self) -> None:
        """Queue every sample in the FIFO: accel, gyro, temperature and the SLV0 copy of
        the magnetometer per record, in snapshot mode (a full FIFO keeps its oldest
        records and drops new ones, so what is queued stays in time order), emptied."""
        self.write_register(0, reg.FIFO_EN_2, reg.FIFO_EN_2_MOTION)
        self.write_register(0, reg.FIFO_EN_1, reg.FIFO_EN_1_SLV_0)
        self.write_register(0, reg.FIFO_MODE, reg.FIFO_MODE_SNAPSHOT)
        self.write_register(0, reg.USER_CTRL, reg.USER_CTRL_I2C_MST_EN | reg.USER_CTRL_FIFO_EN)
        self.reset_fifo()

    def reset_fifo(self) -> None:
        """Empty the FIFO (assert, then release FIFO_RST) and clear its overflow flag."""
        self.write_register(0, reg.FIFO_RST, reg.FIFO_RST_ASSERT)
        self.write_register(0, reg.FIFO_RST, 0x00)
        self.read_register(0, reg.INT_STATUS_2)
        self._fifo_newest_t_s = None

    def read_fifo(self) -> FifoRead:
        """Drain the FIFO's whole records in one transfer, decoded and calibrated.

        Stamps: the newest record was sampled within one output period before the host
        clock just after the FIFO count was read (not before the first register read: the
        chip goes on sampling while the host reads INT_STATUS_2, and a record newer than
        the host's time was stamped up to a transfer too early; at the simulated rig's
        x25 that was half a period, and 0.7 % of the samples found no partner on the
        other chip). The first read after a reset stamps it half a period before;
        later reads continue the previous stamps one period apart while
        they stay in that window (so host jitter does not reach them) and move them to
        its nearer edge when they leave it, which only shrinks their error (at most half
        a period) and follows a chip clock that drifts from the host's.

        An overflow (INT_STATUS_2, or a count that is not whole records) empties the
        FIFO unread: a full snapshot-mode FIFO ends in a cut record, and once the host
        pops records in front of it, new ones land after the cut, so no record boundary
        in it can be trusted."""
        overflowed = bool(self.read_register(0, reg.INT_STATUS_2) & reg.INT_STATUS_2_FIFO_OVERFLOW)
        count_bytes = self.read_registers(0, reg.FIFO_COUNTH, 2)
        t_s = self.clock()
        records, partial = divmod(((count_bytes[0] & 0x1F) << 8) | count_bytes[1], reg.FIFO_RECORD_LENGTH)
        if overflowed or partial:
            self.reset_fifo()
            return FifoRead((), overflowed=True)
        if not records:
            return FifoRead((), overflowed=False)
        raw = decode_fifo(self._read_fifo_bytes(records * reg.FIFO_RECORD_LENGTH), self.ranges)
        period = self.sample_period_s
        newest = t_s - 0.5 * period  # the middle of where the newest record can be
        if self._fifo_newest_t_s is not None:
            newest = min(t_s, max(self._fifo_newest_t_s + records * period, t_s - period))
        self._fifo_newest_t_s = newest
        first = newest - (records - 1) * period
        return FifoRead(tuple(self.calibration.apply(sample, first + index * period)
                              for index, sample in enumerate(raw)), overflowed=False)

    def _read_fifo_bytes(self, length: int) -> bytes:
        """``length`` bytes popped from FIFO_R_W in one transfer (no retry: a failed
        transfer may have popped some, so the caller's record boundary is gone)."""
        self._select_bank_checked(0)
        write = i2c_msg.write(self.address, [reg.FIFO_R_W])
        read = i2c_msg.read(self.address, length)
        try:
            self.bus.i2c_rdwr(write, read)
        except OSError as exc:
            self._bank = None
            self.reset_fifo()
            raise ImuBusError(self.address, f"read {length} FIFO bytes", exc.errno, str(exc)) from exc
        return bytes(read)

    def read_raw_series(self, count: int) -> list[RawImuSample]:
        """`count` raw samples, one per output period (waiting with `sleep`)."""
        samples: list[RawImuSample] = []
        for index in range(count):
            if index:
                self.sleep(self.sample_period_s)
            samples.append(self.read_raw())
        return samples

    def estimate_gyro_bias(
        self,
        sample_count: int = 200,
        *,
        max_gyro_std_rad_s: float = 0.01,
        max_accel_std_m_s2: float = 0.2,
        apply: bool = True,
    ) -> GyroBiasEstimate:
        """Gyro bias from `sample_count` samples at rest (ImuMotionError if the sensor
        moved). With apply=True the result replaces `calibration.gyro_bias_rad_s`."""
        samples: Sequence[RawImuSample] = self.read_raw_series(sample_count)
        estimate = estimate_gyro_bias(
            samples,
            max_gyro_std_rad_s=max_gyro_std_rad_s,
            max_accel_std_m_s2=max_accel_std_m_s2,
            address=self.address,
        )
        if apply:
            self.calibration = ImuCalibration(
                gyro_bias_rad_s=estimate.bias_rad_s,
                mag_hard_iron_ut=self.calibration.mag_hard_iron_ut,
                mag_soft_iron=self.calibration.mag_soft_iron,
            )
        return estimate
