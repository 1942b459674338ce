"""The driver against the MOCK bus: exact register transactions, typed errors, retries."""

from __future__ import annotations

import errno
import math
import struct

import pytest
from imu_test_support import VirtualClock, init_script

from drivers.imu.driver import Icm20948
from drivers.imu.errors import (
    ImuAuxBusError,
    ImuBusError,
    ImuConfigError,
    ImuIdentityError,
    ImuNotFoundError,
    ImuProtocolError,
)
from drivers.testing import B, F, R, RW, ScriptedBus, W, eio, nack


def make(bus: ScriptedBus, address: int = 0x68, **kwargs: object) -> tuple[Icm20948, VirtualClock]:
    clock = VirtualClock()
    return Icm20948(bus, address, clock=clock, sleep=clock.sleep, **kwargs), clock  # type: ignore[arg-type]


GOOD_BURST = struct.pack(">7h", 0, 0, 8192, 0, 0, 0, 0) + struct.pack("<BhhhBB", 1, 100, 0, -300, 0, 0)


@pytest.mark.parametrize("address", [0x68, 0x69])
def test_initialize_issues_exactly_the_datasheet_sequence(address: int) -> None:
    bus = ScriptedBus(init_script(address))
    driver, clock = make(bus, address)
    driver.initialize()
    bus.assert_done()
    assert driver.initialized
    # the waits happened on the injected sleep: reset (0.1 s) and wake (0.05 s) included
    assert 0.1 in clock.sleeps and 0.05 in clock.sleeps


def test_sample_is_one_block_read_of_23_bytes_from_0x2d() -> None:
    bus = ScriptedBus(init_script() + [B(0x68, 0x2D, 23, GOOD_BURST), B(0x68, 0x2D, 23, GOOD_BURST)])
    driver, _ = make(bus)
    driver.initialize()
    sample = driver.read_raw()
    assert sample.accel_m_s2[2] == pytest.approx(9.80665)
    assert sample.mag_ut == pytest.approx((15.0, 0.0, 45.0))
    stamped = driver.read_sample()
    assert stamped.t_s == driver.clock()
    bus.assert_done()


def test_wrong_who_am_i_raises_identity_error_and_touches_nothing_else() -> None:
    bus = ScriptedBus([W(0x69, 0x7F, 0x00), R(0x69, 0x00, 0x71)])  # an MPU-9250 answers
    driver, _ = make(bus, 0x69)
    with pytest.raises(ImuIdentityError, match=r"0x69: ICM-20948 WHO_AM_I reads 0x71, expected 0xEA"):
        driver.initialize()
    bus.assert_done()  # in particular: no reset written to a part we do not know
    assert not driver.initialized


def test_no_ack_raises_not_found_naming_the_address_after_bounded_retries() -> None:
    probe = W(0x69, 0x7F, 0x00)
    bus = ScriptedBus([F(probe, nack())] * 3)
    driver, _ = make(bus, 0x69, retries=2)
    with pytest.raises(ImuNotFoundError, match="0x69") as info:
        driver.initialize()
    assert info.value.errno == errno.EREMOTEIO
    bus.assert_done()


def test_transient_error_is_retried_and_the_bank_is_reselected() -> None:
    burst = B(0x68, 0x2D, 23, GOOD_BURST)
    script = init_script() + [F(burst, eio()), W(0x68, 0x7F, 0x00), burst]
    bus = ScriptedBus(script)
    driver, _ = make(bus)
    driver.initialize()
    assert driver.read_raw().mag_data_ready
    bus.assert_done()


def test_persistent_read_error_raises_bus_error_after_retries() -> None:
    burst = B(0x68, 0x2D, 23, GOOD_BURST)
    retry = [W(0x68, 0x7F, 0x00), F(burst, eio())]
    bus = ScriptedBus(init_script() + [F(burst, eio())] + retry * 3)
    driver, clock = make(bus, retries=3)
    driver.initialize()
    with pytest.raises(ImuBusError, match=r"0x68: read 23 bytes .* \(errno 5\)") as info:
        driver.read_raw()
    assert info.value.errno == errno.EIO
    bus.assert_done()
    assert clock.sleeps[-3:] == [0.001] * 3  # back-off between attempts


def test_garbage_burst_is_reread_then_raises_protocol_error() -> None:
    garbage = B(0x68, 0x2D, 23, bytes([0xFF] * 23))
    bus = ScriptedBus(init_script() + [garbage, garbage])
    driver, _ = make(bus, retries=1)
    driver.initialize()
    with pytest.raises(ImuProtocolError, match="reserved bits"):
        driver.read_raw()
    bus.assert_done()


def test_short_block_read_is_a_protocol_error() -> None:
    bus = ScriptedBus(init_script() + [B(0x68, 0x2D, 23, GOOD_BURST[:20])])
    driver, _ = make(bus, retries=0)
    driver.initialize()
    with pytest.raises(ImuProtocolError, match="23 bytes, got 20"):
        driver.read_raw()


def test_reset_that_never_clears_raises_config_error() -> None:
    a = 0x68
    script = [W(a, 0x7F, 0x00), R(a, 0x00, 0xEA), W(a, 0x06, 0x80), W(a, 0x7F, 0x00)]
    script += [R(a, 0x06, 0xC1)] * 10
    bus = ScriptedBus(script)
    driver, _ = make(bus)
    with pytest.raises(ImuConfigError, match="DEVICE_RESET did not clear"):
        driver.initialize()
    bus.assert_done()


def test_register_that_does_not_read_back_raises_config_error() -> None:
    script = init_script()[:11]  # up to GYRO_SMPLRT_DIV write
    script.append(R(0x68, 0x00, 0x00))
    bus = ScriptedBus(script)
    driver, _ = make(bus)
    with pytest.raises(ImuConfigError, match="GYRO_SMPLRT_DIV reads back 0x00 after writing 0x0A"):
        driver.initialize()
    bus.assert_done()


def _until_wia2_poll() -> list:
    script = init_script()
    # cut after the WIA2 SLV4_CTRL enable and its bank-0 select
    index = script.index(W(0x68, 0x14, 0x01)) + 3
    return script[:index]


def test_magnetometer_nack_raises_aux_bus_error() -> None:
    bus = ScriptedBus(_until_wia2_poll() + [R(0x68, 0x17, 0x50)])  # SLV4_DONE | SLV4_NACK
    driver, _ = make(bus)
    with pytest.raises(ImuAuxBusError, match="0x68: .*no ACK from 0x0C"):
        driver.initialize()
    bus.assert_done()


def test_magnetometer_transfer_that_never_completes_raises_aux_bus_error() -> None:
    bus = ScriptedBus(_until_wia2_poll() + [R(0x68, 0x17, 0x00)] * 50)
    driver, _ = make(bus)
    with pytest.raises(ImuAuxBusError, match="never completed"):
        driver.initialize()
    bus.assert_done()


def test_wrong_magnetometer_identity_raises_identity_error() -> None:
    script = _until_wia2_poll() + [R(0x68, 0x17, 0x40), W(0x68, 0x7F, 0x30), R(0x68, 0x17, 0x05)]
    bus = ScriptedBus(script)
    driver, _ = make(bus)
    with pytest.raises(ImuIdentityError, match="AK09916 WIA2 reads 0x05, expected 0x09"):
        driver.initialize()
    bus.assert_done()


def test_reads_longer_than_an_smbus_block_use_one_combined_transfer() -> None:
    bus = ScriptedBus([W(0x68, 0x7F, 0x00), (("i2c_rdwr", ((0x68, 0, 1), (0x68, 1, 40))), None)])
    driver, _ = make(bus)
    assert driver.read_registers(0, 0x2D, 40) == bytes(40)
    bus.assert_done()


def test_constructor_validates_its_arguments() -> None:
    bus = ScriptedBus([])
    with pytest.raises(ValueError, match="0x68 or 0x69"):
        Icm20948(bus, 0x0C)
    with pytest.raises(ValueError, match="sample_rate_divider"):
        Icm20948(bus, sample_rate_divider=256)
    with pytest.raises(ValueError, match="dlpf_config"):
        Icm20948(bus, dlpf_config=8)
    with pytest.raises(ValueError, match="retries"):
        Icm20948(bus, retries=-1)
    assert Icm20948(bus, sample_rate_divider=10).sample_rate_hz == pytest.approx(1125 / 11)
    bus.assert_done()


def fifo_records(count: int) -> bytes:
    return b"".join(struct.pack(">7h", 0, 0, 8192, index, 0, 0, 0) + struct.pack("<BhhhBB", 1, 100, 0, -300, 0, 0)
                    for index in range(count))


def enable_fifo_script(a: int = 0x68) -> list:
    return [
        W(a, 0x67, 0x1F),  # FIFO_EN_2: accel, gyro X/Y/Z, temperature
        W(a, 0x66, 0x01),  # FIFO_EN_1: SLV0
        W(a, 0x69, 0x1F),  # FIFO_MODE: snapshot
        W(a, 0x03, 0x60),  # USER_CTRL: FIFO_EN | I2C_MST_EN
        W(a, 0x68, 0x1F), W(a, 0x68, 0x00),  # FIFO_RST assert, release
        R(a, 0x1B, 0x00),  # INT_STATUS_2: clear a stale overflow
    ]


def fifo_driver(after_enable: list):
    """A driver initialized with its FIFO on, over a bus scripted with ``after_enable``
    next: (bus, driver, clock)."""
    bus = ScriptedBus(init_script() + enable_fifo_script() + after_enable)
    driver, clock = make(bus)
    driver.initialize()
    driver.enable_fifo()
    return bus, driver, clock


def test_fifo_read_is_status_count_then_one_transfer_of_whole_records() -> None:
    bus, driver, clock = fifo_driver([
        R(0x68, 0x1B, 0x00),  # no overflow
        B(0x68, 0x70, 2, bytes([0x00, 3 * 23])),  # FIFO_COUNTH/L: 69 bytes
        RW(0x68, 0x72, 3 * 23, fifo_records(3)),  # FIFO_R_W, one transfer
    ])
    read = driver.read_fifo()
    bus.assert_done()
    assert not read.overflowed
    assert [s.gyro_rad_s[0] for s in read.samples] == pytest.approx([math.radians(i / 65.5) for i in range(3)])
    # oldest first, one output period apart, the newest half a period before the read
    stamps = [s.t_s for s in read.samples]
    assert stamps[-1] == pytest.approx(clock() - driver.sample_period_s / 2)
    assert stamps[1] - stamps[0] == pytest.approx(driver.sample_period_s)


@pytest.mark.parametrize(("status", "count"), [(0x01, 512), (0x01, 23), (0x00, 23 + 5)])
def test_fifo_overflow_or_a_cut_record_empties_the_fifo_unread(status: int, count: int) -> None:
    bus, driver, _ = fifo_driver([
        R(0x68, 0x1B, status),  # FIFO_OVERFLOW_INT
        B(0x68, 0x70, 2, bytes([count >> 8, count & 0xFF])),
        W(0x68, 0x68, 0x1F), W(0x68, 0x68, 0x00), R(0x68, 0x1B, 0x00),  # reset, no FIFO_R_W read
    ])
    read = driver.read_fifo()
    bus.assert_done()
    assert read.overflowed and read.samples == ()


def test_failed_fifo_transfer_resets_the_fifo_and_names_the_address() -> None:
    bus, driver, _ = fifo_driver([
        R(0x68, 0x1B, 0x00),
        B(0x68, 0x70, 2, bytes([0x00, 46])),
        F(RW(0x68, 0x72, 46, b""), eio()),
        W(0x68, 0x7F, 0x00), W(0x68, 0x68, 0x1F), W(0x68, 0x68, 0x00), R(0x68, 0x1B, 0x00),
    ])
    with pytest.raises(ImuBusError, match=r"0x68: read 46 FIFO bytes"):
        driver.read_fifo()
    bus.assert_done()
