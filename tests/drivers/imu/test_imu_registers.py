"""Every register the project's driver, Pimoroni's `icm20948` or Adafruit's `adafruit_icm20x`
touch, table-driven: reset value, access, and side effects (DS = ICM-20948 datasheet
DS-000189; AK = AK09916 datasheet)."""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest
from imu_test_support import VirtualClock

from drivers.imu import registers as reg
from drivers.imu.emulator import Icm20948BusEmulator
from drivers.plant import StaticPlant

A = 0x68
RW, RO, RC = "read/write", "read-only", "read-to-clear"


@dataclass(frozen=True)
class Row:
    bank: int
    register: int
    name: str
    reset: int
    access: str
    probe: int = 0x0A  # a value whose write has no side effect worth noting
    reads_back: int | None = None  # what a probe write reads back as (None: the probe)


CHIP = [
    Row(0, reg.WHO_AM_I, "WHO_AM_I", 0xEA, RO),
    Row(0, reg.USER_CTRL, "USER_CTRL", 0x00, RW, probe=0x22, reads_back=0x20),  # I2C_MST_RST self-clears
    Row(0, reg.LP_CONFIG, "LP_CONFIG", 0x40, RW),
    Row(0, reg.PWR_MGMT_1, "PWR_MGMT_1", 0x41, RW, probe=0x01),
    Row(0, reg.PWR_MGMT_2, "PWR_MGMT_2", 0x00, RW),
    Row(0, reg.INT_PIN_CFG, "INT_PIN_CFG", 0x00, RW, probe=0x30),
    Row(0, reg.I2C_MST_STATUS, "I2C_MST_STATUS", 0x00, RC),
    Row(0, reg.INT_STATUS_1, "INT_STATUS_1", 0x00, RC),
    *[Row(0, r, f"sensor data 0x{r:02X}", 0x00, RO) for r in range(reg.ACCEL_XOUT_H, reg.EXT_SLV_SENS_DATA_00)],
    *[Row(0, reg.EXT_SLV_SENS_DATA_00 + i, f"EXT_SLV_SENS_DATA_{i:02d}", 0x00, RO)
      for i in range(reg.EXT_SLV_SENS_DATA_COUNT)],
    Row(2, reg.GYRO_SMPLRT_DIV, "GYRO_SMPLRT_DIV", 0x00, RW),
    Row(2, reg.GYRO_CONFIG_1, "GYRO_CONFIG_1", 0x01, RW),
    Row(2, reg.ACCEL_SMPLRT_DIV_1, "ACCEL_SMPLRT_DIV_1", 0x00, RW),
    Row(2, reg.ACCEL_SMPLRT_DIV_2, "ACCEL_SMPLRT_DIV_2", 0x00, RW),
    Row(2, reg.ACCEL_CONFIG, "ACCEL_CONFIG", 0x01, RW),
    Row(3, reg.I2C_MST_ODR_CONFIG, "I2C_MST_ODR_CONFIG", 0x00, RW),
    Row(3, reg.I2C_MST_CTRL, "I2C_MST_CTRL", 0x00, RW),
    Row(3, reg.I2C_MST_DELAY_CTRL, "I2C_MST_DELAY_CTRL", 0x00, RW),
    Row(3, reg.I2C_SLV0_ADDR, "I2C_SLV0_ADDR", 0x00, RW),
    Row(3, reg.I2C_SLV0_REG, "I2C_SLV0_REG", 0x00, RW),
    Row(3, reg.I2C_SLV0_CTRL, "I2C_SLV0_CTRL", 0x00, RW),
    Row(3, reg.I2C_SLV0_DO, "I2C_SLV0_DO", 0x00, RW),
    Row(3, reg.I2C_SLV4_ADDR, "I2C_SLV4_ADDR", 0x00, RW),
    Row(3, reg.I2C_SLV4_REG, "I2C_SLV4_REG", 0x00, RW),
    Row(3, reg.I2C_SLV4_CTRL, "I2C_SLV4_CTRL", 0x00, RW),
    Row(3, reg.I2C_SLV4_DO, "I2C_SLV4_DO", 0x00, RW),
    Row(3, reg.I2C_SLV4_DI, "I2C_SLV4_DI", 0x00, RO),
]


def make() -> tuple[Icm20948BusEmulator, VirtualClock]:
    clock = VirtualClock()
    return Icm20948BusEmulator(StaticPlant(), clock, sensors={A: "base"}), clock


def select(emu: Icm20948BusEmulator, bank: int) -> None:
    emu.write_byte_data(A, reg.REG_BANK_SEL, bank << 4)


def read(emu: Icm20948BusEmulator, bank: int, register: int) -> int:
    select(emu, bank)
    return emu.read_byte_data(A, register)


def write(emu: Icm20948BusEmulator, bank: int, register: int, value: int) -> None:
    select(emu, bank)
    emu.write_byte_data(A, register, value)


@pytest.mark.parametrize("row", CHIP, ids=lambda row: row.name)
def test_reset_value_and_access(row: Row) -> None:
    emu, clock = make()  # asleep after power-on: nothing is sampled, the master is idle
    assert read(emu, row.bank, row.register) == row.reset
    write(emu, row.bank, row.register, row.probe)
    expected = row.reset if row.access in (RO, RC) else (row.probe if row.reads_back is None else row.reads_back)
    assert read(emu, row.bank, row.register) == expected
    assert read(emu, 0, reg.REG_BANK_SEL) == 0x00  # REG_BANK_SEL reads back in every bank


# --- side effects ------------------------------------------------------------------


def wake(emu: Icm20948BusEmulator) -> None:
    write(emu, 0, reg.PWR_MGMT_1, reg.PWR_MGMT_1_CLKSEL_AUTO)


def slv4(emu: Icm20948BusEmulator, ak_register: int, value: int | None = None) -> None:
    """Start one SLV4 transfer (a read if value is None); the master runs it later."""
    select(emu, 3)
    emu.write_byte_data(A, reg.I2C_SLV4_ADDR, reg.AK09916_ADDRESS | (reg.I2C_SLV_READ if value is None else 0))
    emu.write_byte_data(A, reg.I2C_SLV4_REG, ak_register)
    if value is not None:
        emu.write_byte_data(A, reg.I2C_SLV4_DO, value)
    emu.write_byte_data(A, reg.I2C_SLV4_CTRL, reg.I2C_SLV_EN)


def ak(emu: Icm20948BusEmulator, clock: VirtualClock, ak_register: int, value: int | None = None) -> int:
    slv4(emu, ak_register, value)
    clock.sleep(0.002)
    assert read(emu, 0, reg.I2C_MST_STATUS) & reg.I2C_MST_STATUS_SLV4_DONE
    return read(emu, 3, reg.I2C_SLV4_DI)


def master_on(emu: Icm20948BusEmulator) -> None:
    wake(emu)
    write(emu, 0, reg.USER_CTRL, reg.USER_CTRL_I2C_MST_EN)


def effect_device_reset(emu: Icm20948BusEmulator, clock: VirtualClock) -> None:
    write(emu, 2, reg.GYRO_SMPLRT_DIV, 7)
    write(emu, 0, reg.PWR_MGMT_1, 0x80)
    assert read(emu, 0, reg.PWR_MGMT_1) & 0x80  # DEVICE_RESET self-clears after ~1 ms
    clock.sleep(0.002)
    assert read(emu, 0, reg.PWR_MGMT_1) == 0x41
    assert read(emu, 2, reg.GYRO_SMPLRT_DIV) == 0


def effect_lp_config_master_clock(emu: Icm20948BusEmulator, clock: VirtualClock) -> None:
    # I2C_MST_CYC (reset): the master runs at 1.1 kHz however slow the gyro is and however
    # often GYRO_SMPLRT_DIV is written
    master_on(emu)
    write(emu, 2, reg.GYRO_SMPLRT_DIV, 255)  # 4.4 Hz
    for _ in range(5):
        slv4(emu, reg.AK_WIA2)
        clock.sleep(0.002)
        write(emu, 2, reg.GYRO_SMPLRT_DIV, 255)
        assert read(emu, 3, reg.I2C_SLV4_DI) == reg.AK_WIA2_VALUE
        assert read(emu, 0, reg.I2C_MST_STATUS) & reg.I2C_MST_STATUS_SLV4_DONE
    # cleared: the master waits for the next gyro sample
    write(emu, 0, reg.LP_CONFIG, 0x00)
    slv4(emu, reg.AK_WIA1)
    clock.sleep(0.002)
    assert read(emu, 3, reg.I2C_SLV4_DI) == reg.AK_WIA2_VALUE  # not yet
    clock.sleep(256 / 1125)
    assert read(emu, 3, reg.I2C_SLV4_DI) == reg.AK_WIA1_VALUE


def effect_master_odr(emu: Icm20948BusEmulator, clock: VirtualClock) -> None:
    master_on(emu)
    write(emu, 3, reg.I2C_MST_ODR_CONFIG, 4)  # 1125 / 16 = 70 Hz
    clock.sleep(20 / 1125)  # a quarter period past the master's first instant
    read(emu, 0, reg.I2C_MST_STATUS)
    slv4(emu, reg.AK_WIA2)
    clock.sleep(6 / 1125)
    assert read(emu, 3, reg.I2C_SLV4_DI) == 0
    clock.sleep(8 / 1125)
    assert read(emu, 3, reg.I2C_SLV4_DI) == reg.AK_WIA2_VALUE


def effect_user_ctrl_master_enable(emu: Icm20948BusEmulator, clock: VirtualClock) -> None:
    wake(emu)
    slv4(emu, reg.AK_WIA2)
    clock.sleep(0.01)
    assert read(emu, 3, reg.I2C_SLV4_DI) == 0  # I2C_MST_EN clear: no transfer
    write(emu, 0, reg.USER_CTRL, reg.USER_CTRL_I2C_MST_EN)
    clock.sleep(0.002)
    assert read(emu, 3, reg.I2C_SLV4_DI) == reg.AK_WIA2_VALUE
    assert read(emu, 3, reg.I2C_SLV4_CTRL) == 0  # SLV4's EN clears after its one transfer


def effect_mst_status_read_to_clear(emu: Icm20948BusEmulator, clock: VirtualClock) -> None:
    master_on(emu)
    slv4(emu, reg.AK_WIA2)
    clock.sleep(0.002)
    assert read(emu, 0, reg.I2C_MST_STATUS) == reg.I2C_MST_STATUS_SLV4_DONE
    assert read(emu, 0, reg.I2C_MST_STATUS) == 0


def effect_raw_data_ready(emu: Icm20948BusEmulator, clock: VirtualClock) -> None:
    wake(emu)
    write(emu, 2, reg.GYRO_SMPLRT_DIV, 10)
    clock.sleep(11 / 1125)
    assert read(emu, 0, reg.INT_STATUS_1) == reg.INT_STATUS_1_RAW_DATA_0_RDY
    assert read(emu, 0, reg.INT_STATUS_1) == 0  # cleared by reading it
    clock.sleep(11 / 1125)
    emu.read_i2c_block_data(A, reg.ACCEL_XOUT_H, 12)  # another read does not clear it...
    assert read(emu, 0, reg.INT_STATUS_1) == reg.INT_STATUS_1_RAW_DATA_0_RDY
    write(emu, 0, reg.INT_PIN_CFG, reg.INT_PIN_CFG_INT_ANYRD_2CLEAR)
    clock.sleep(11 / 1125)
    emu.read_i2c_block_data(A, reg.ACCEL_XOUT_H, 12)  # ...unless INT_ANYRD_2CLEAR
    assert read(emu, 0, reg.INT_STATUS_1) == 0


def _updates_per_second(emu: Icm20948BusEmulator, clock: VirtualClock, register: int) -> int:
    previous, changes = None, 0
    for _ in range(1000):
        clock.sleep(0.001)
        value = bytes(emu.read_i2c_block_data(A, register, 6))
        changes += previous is not None and value != previous
        previous = value
    return changes


def effect_sample_rate_dividers(emu: Icm20948BusEmulator, clock: VirtualClock) -> None:
    wake(emu)
    write(emu, 2, reg.GYRO_SMPLRT_DIV, 22)  # 48.9 Hz
    emu.write_byte_data(A, reg.ACCEL_SMPLRT_DIV_1, 0x00)
    emu.write_byte_data(A, reg.ACCEL_SMPLRT_DIV_2, 111)  # 10.0 Hz
    select(emu, 0)
    assert _updates_per_second(emu, clock, reg.ACCEL_XOUT_H) == pytest.approx(10, abs=1)
    assert _updates_per_second(emu, clock, reg.GYRO_XOUT_H) == pytest.approx(49, abs=1)
    write(emu, 2, reg.ACCEL_SMPLRT_DIV_1, 0x04)  # 12-bit divider: 0x400 + 111 -> 0.84 Hz
    select(emu, 0)
    assert _updates_per_second(emu, clock, reg.ACCEL_XOUT_H) <= 1


def _noise(emu: Icm20948BusEmulator, clock: VirtualClock) -> tuple[float, float]:
    """Standard deviation of accel (LSB) and gyro (LSB) z over 300 samples."""
    select(emu, 0)
    samples = []
    for _ in range(300):
        clock.sleep(0.01)
        samples.append(struct.unpack(">6h", bytes(emu.read_i2c_block_data(A, reg.ACCEL_XOUT_H, 12))))
    data = np.array(samples, dtype=float)
    return float(np.std(data[:, 2])), float(np.std(data[:, 5]))


def effect_dlpf_noise(emu: Icm20948BusEmulator, clock: VirtualClock) -> None:
    wake(emu)
    write(emu, 2, reg.GYRO_CONFIG_1, 0x01 | (6 << 3))  # DLPFCFG 6, +-250 dps
    emu.write_byte_data(A, reg.ACCEL_CONFIG, 0x01 | (6 << 3))  # DLPFCFG 6, +-2 g
    narrow = _noise(emu, clock)
    write(emu, 2, reg.GYRO_CONFIG_1, 0x00)  # FCHOICE 0: filter bypassed
    emu.write_byte_data(A, reg.ACCEL_CONFIG, 0x00)
    wide = _noise(emu, clock)
    # DS 3: 230 ug/sqrt(Hz) and 0.015 dps/sqrt(Hz); DS 10: NBW 8.3/8.9 Hz (DLPFCFG 6), 1248/12316 Hz (bypass)
    assert narrow[0] == pytest.approx(230e-6 * math.sqrt(8.3) * 16384, rel=0.2)
    assert wide[0] == pytest.approx(230e-6 * math.sqrt(1248) * 16384, rel=0.15)
    assert wide[1] == pytest.approx(0.015 * math.sqrt(12316) * 131, rel=0.15)
    assert narrow[1] < wide[1] / 20


def effect_full_scale(emu: Icm20948BusEmulator, clock: VirtualClock) -> None:
    wake(emu)
    for fs_sel, (_, lsb_per_g) in reg.ACCEL_FULL_SCALES.items():
        write(emu, 2, reg.ACCEL_CONFIG, 0x01 | fs_sel << 1)
        clock.sleep(0.002)
        select(emu, 0)
        az = struct.unpack(">h", bytes(emu.read_i2c_block_data(A, reg.ACCEL_XOUT_H + 4, 2)))[0]
        assert az / lsb_per_g == pytest.approx(9.81 / reg.STANDARD_GRAVITY_M_S2, abs=0.01)


def effect_power_mgmt_2(emu: Icm20948BusEmulator, clock: VirtualClock) -> None:
    wake(emu)
    clock.sleep(0.002)
    write(emu, 0, reg.PWR_MGMT_2, reg.PWR_MGMT_2_DISABLE_ACCEL)
    frozen = emu.read_i2c_block_data(A, reg.ACCEL_XOUT_H, 12)
    clock.sleep(0.05)
    now = emu.read_i2c_block_data(A, reg.ACCEL_XOUT_H, 12)
    assert now[:6] == frozen[:6] and now[6:] != frozen[6:]


def effect_slv0_copies(emu: Icm20948BusEmulator, clock: VirtualClock) -> None:
    master_on(emu)
    ak(emu, clock, reg.AK_CNTL2, reg.AK_MODE_CONTINUOUS_100HZ)
    select(emu, 3)
    emu.write_i2c_block_data(A, reg.I2C_SLV0_ADDR, [0x80 | reg.AK09916_ADDRESS, reg.AK_ST1, 0x80 | 9])
    clock.sleep(0.02)
    select(emu, 0)
    block = emu.read_i2c_block_data(A, reg.EXT_SLV_SENS_DATA_00, 9)
    x, y, z = struct.unpack("<3h", bytes(block[1:7]))
    assert (x * 0.15, -y * 0.15, -z * 0.15) == pytest.approx((20.0, 0.0, -45.0), abs=1.5)
    assert not block[8] & reg.AK_ST2_HOFL


SIDE_EFFECTS: dict[str, Callable[[Icm20948BusEmulator, VirtualClock], None]] = {
    "PWR_MGMT_1 DEVICE_RESET": effect_device_reset,
    "PWR_MGMT_2 disables accel": effect_power_mgmt_2,
    "LP_CONFIG I2C_MST_CYC": effect_lp_config_master_clock,
    "I2C_MST_ODR_CONFIG": effect_master_odr,
    "USER_CTRL I2C_MST_EN / I2C_SLV4_CTRL": effect_user_ctrl_master_enable,
    "I2C_MST_STATUS": effect_mst_status_read_to_clear,
    "INT_STATUS_1 / INT_PIN_CFG": effect_raw_data_ready,
    "GYRO_SMPLRT_DIV / ACCEL_SMPLRT_DIV_1/2": effect_sample_rate_dividers,
    "GYRO_CONFIG_1 / ACCEL_CONFIG DLPF": effect_dlpf_noise,
    "ACCEL_CONFIG FS_SEL": effect_full_scale,
    "I2C_SLV0_* / EXT_SLV_SENS_DATA": effect_slv0_copies,
}


@pytest.mark.parametrize("name", SIDE_EFFECTS)
def test_side_effect(name: str) -> None:
    emu, clock = make()
    SIDE_EFFECTS[name](emu, clock)


# --- the AK09916 behind the master -----------------------------------------------------

AK_ROWS = [
    Row(0, reg.AK_WIA1, "WIA1", reg.AK_WIA1_VALUE, RO),
    Row(0, reg.AK_WIA2, "WIA2", reg.AK_WIA2_VALUE, RO),
    Row(0, reg.AK_ST1, "ST1", 0x00, RO),
    *[Row(0, r, f"data 0x{r:02X}", 0x00, RO) for r in range(reg.AK_HXL, reg.AK_ST2 + 1)],
    Row(0, reg.AK_CNTL2, "CNTL2", 0x00, RW, probe=reg.AK_MODE_CONTINUOUS_100HZ),
    Row(0, reg.AK_CNTL3, "CNTL3", 0x00, RW, probe=reg.AK_CNTL3_SRST, reads_back=0x00),  # SRST self-clears
]


@pytest.mark.parametrize("row", AK_ROWS, ids=lambda row: row.name)
def test_ak09916_reset_value_and_access(row: Row) -> None:
    emu, clock = make()
    master_on(emu)
    assert ak(emu, clock, row.register) == row.reset
    ak(emu, clock, row.register, row.probe)
    expected = row.reset if row.access == RO else (row.probe if row.reads_back is None else row.reads_back)
    assert ak(emu, clock, row.register) == expected


def test_ak09916_single_measurement_and_st2() -> None:
    emu, clock = make()
    master_on(emu)
    ak(emu, clock, reg.AK_CNTL2, reg.AK_MODE_SINGLE)
    assert ak(emu, clock, reg.AK_ST1) == 0  # measuring (up to ~8 ms)
    clock.sleep(0.008)
    assert ak(emu, clock, reg.AK_ST1) == reg.AK_ST1_DRDY
    assert ak(emu, clock, reg.AK_CNTL2) == reg.AK_MODE_POWER_DOWN  # back to power-down by itself
    first = ak(emu, clock, reg.AK_HXL)
    assert ak(emu, clock, reg.AK_ST1) == 0  # reading data clears DRDY
    ak(emu, clock, reg.AK_ST2)  # releases the data
    # Pimoroni's pattern: a 14-byte SLV0 read from HXL (ends on HXL, past ST2), then the
    # next single measurement command: it must arrive, and without DOR
    select(emu, 3)
    emu.write_i2c_block_data(A, reg.I2C_SLV0_ADDR, [0x80 | reg.AK09916_ADDRESS, reg.AK_HXL, 0x80 | 14])
    clock.sleep(0.005)
    emu.write_byte_data(A, reg.I2C_SLV0_CTRL, 0x00)
    for step in range(5):
        emu.set_magnetic_disturbance("base", (10.0 * (step + 1), 0.0, 0.0))  # a new value each time
        ak(emu, clock, reg.AK_CNTL2, reg.AK_MODE_SINGLE)
        clock.sleep(0.009)
        assert ak(emu, clock, reg.AK_ST1) == reg.AK_ST1_DRDY
        value = ak(emu, clock, reg.AK_HXL)
        ak(emu, clock, reg.AK_ST2)
        assert value != first
        first = value


def test_ak09916_continuous_data_held_until_st2() -> None:
    emu, clock = make()
    master_on(emu)
    ak(emu, clock, reg.AK_CNTL2, reg.AK_MODE_CONTINUOUS_100HZ)
    clock.sleep(0.011)
    held = ak(emu, clock, reg.AK_HXL)  # starts a read: the data are now protected
    emu.set_magnetic_disturbance("base", (100.0, 0.0, 0.0))
    clock.sleep(0.03)
    assert ak(emu, clock, reg.AK_ST1) & reg.AK_ST1_DOR  # measurements were skipped meanwhile
    assert ak(emu, clock, reg.AK_HXL) == held
    ak(emu, clock, reg.AK_ST2)
    clock.sleep(0.011)
    assert ak(emu, clock, reg.AK_HXL) != held
