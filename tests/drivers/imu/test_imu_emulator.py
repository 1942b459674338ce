"""The bus emulator on its own: SMBus behaviour, register file, auxiliary master, AK09916."""

from __future__ import annotations

import errno
import struct

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from imu_test_support import VirtualClock
from smbus2 import i2c_msg

from drivers.imu import registers as reg
from drivers.imu.emulator import Icm20948BusEmulator, ImuErrorModel, _StandardNormals
from drivers.plant import StaticPlant

A = 0x68


def make(**kwargs: object) -> tuple[Icm20948BusEmulator, VirtualClock]:
    clock = VirtualClock()
    return Icm20948BusEmulator(StaticPlant(), clock, **kwargs), clock  # type: ignore[arg-type]


def bank(emu: Icm20948BusEmulator, b: int, address: int = A) -> None:
    emu.write_byte_data(address, 0x7F, b << 4)


def wake(emu: Icm20948BusEmulator, address: int = A) -> None:
    bank(emu, 0, address)
    emu.write_byte_data(address, reg.PWR_MGMT_1, 0x01)


def test_absent_address_raises_remote_io_error_on_every_method() -> None:
    emu, _ = make(sensors={A: "base"})
    calls = [
        lambda: emu.read_byte_data(0x69, 0),
        lambda: emu.write_byte_data(0x69, 0, 0),
        lambda: emu.read_i2c_block_data(0x69, 0, 4),
        lambda: emu.write_i2c_block_data(0x69, 0, [1]),
        lambda: emu.i2c_rdwr(i2c_msg.write(0x69, [0]), i2c_msg.read(0x69, 1)),
        lambda: emu.read_byte_data(0x0C, 0),  # the AK09916s are not on the host bus
    ]
    for call in calls:
        with pytest.raises(OSError) as info:
            call()
        assert info.value.errno == errno.EREMOTEIO
    assert emu.read_byte_data(A, 0) == 0xEA


def test_detach_and_attach() -> None:
    emu, _ = make()
    emu.detach(0x69)
    with pytest.raises(OSError):
        emu.read_byte_data(0x69, 0)
    emu.attach(0x69)
    assert emu.read_byte_data(0x69, 0) == 0xEA


def test_smbus_block_limit_is_enforced_like_smbus2() -> None:
    emu, _ = make()
    with pytest.raises(ValueError, match="over 32"):
        emu.read_i2c_block_data(A, 0x2D, 33)
    with pytest.raises(ValueError, match="exceed 32"):
        emu.write_i2c_block_data(A, 0x00, [0] * 33)
    assert len(emu.read_i2c_block_data(A, 0x2D, 32)) == 32


def test_bank_switching_and_reset_values() -> None:
    emu, _ = make()
    assert emu.read_byte_data(A, 0x00) == 0xEA  # bank 0 WHO_AM_I
    assert emu.read_byte_data(A, reg.PWR_MGMT_1) == 0x41
    bank(emu, 2)
    assert emu.read_byte_data(A, 0x7F) == 0x20
    assert emu.read_byte_data(A, 0x00) == 0x00  # bank 2 GYRO_SMPLRT_DIV
    assert emu.read_byte_data(A, 0x01) == 0x01  # GYRO_CONFIG_1 reset value
    emu.write_byte_data(A, 0x00, 0x0A)
    bank(emu, 0)
    assert emu.read_byte_data(A, 0x00) == 0xEA
    emu.write_byte_data(A, 0x00, 0x12)  # WHO_AM_I is read-only
    assert emu.read_byte_data(A, 0x00) == 0xEA


def test_device_reset_restores_defaults_after_it_completes() -> None:
    emu, clock = make()
    wake(emu)
    bank(emu, 2)
    emu.write_byte_data(A, 0x00, 0x0A)
    bank(emu, 0)
    emu.write_byte_data(A, reg.PWR_MGMT_1, 0x80)
    assert emu.read_byte_data(A, reg.PWR_MGMT_1) & 0x80  # still resetting
    clock.sleep(0.01)
    assert emu.read_byte_data(A, reg.PWR_MGMT_1) == 0x41
    bank(emu, 2)
    assert emu.read_byte_data(A, 0x00) == 0x00


def test_asleep_chip_produces_no_data_and_wakes_on_the_output_grid() -> None:
    emu, clock = make()
    clock.sleep(1.0)
    assert emu.read_i2c_block_data(A, 0x2D, 14) == [0] * 14
    wake(emu)
    clock.sleep(0.5 / 1125)  # less than one period (divider 0)
    assert emu.read_i2c_block_data(A, 0x2D, 14) == [0] * 14
    clock.sleep(1.0 / 1125)
    az = struct.unpack(">h", bytes(emu.read_i2c_block_data(A, 0x31, 2)))[0]
    assert az * 9.80665 / 16384 == pytest.approx(9.81, rel=0.02)  # reset range +-2 g


def test_long_combined_read_equals_two_block_reads_of_the_same_sample() -> None:
    emu, clock = make()
    wake(emu)
    clock.sleep(0.01)
    first = emu.read_i2c_block_data(A, 0x2D, 20) + emu.read_i2c_block_data(A, 0x2D + 20, 20)
    write, read = i2c_msg.write(A, [0x2D]), i2c_msg.read(A, 40)
    emu.i2c_rdwr(write, read)  # the clock has not moved: same sample
    assert list(read) == first
    assert any(first)


def test_combined_write_sets_consecutive_registers() -> None:
    emu, _ = make()
    bank(emu, 3)
    emu.i2c_rdwr(i2c_msg.write(A, [0x03, 0x8C, 0x10, 0x89]))
    assert emu.read_i2c_block_data(A, 0x03, 3) == [0x8C, 0x10, 0x89]
    emu.write_byte(A, 0x04)
    assert emu.read_byte(A) == 0x10
    assert emu.read_byte(A) == 0x89


def test_slv0_to_a_missing_aux_device_sets_nack_which_clears_on_read() -> None:
    emu, clock = make()
    wake(emu)
    emu.write_byte_data(A, reg.USER_CTRL, 0x20)
    bank(emu, 3)
    emu.write_i2c_block_data(A, reg.I2C_SLV0_ADDR, [0x80 | 0x0D, 0x10, 0x89])
    bank(emu, 0)
    clock.sleep(0.01)
    assert emu.read_byte_data(A, reg.I2C_MST_STATUS) & reg.I2C_MST_STATUS_SLV0_NACK
    assert emu.read_byte_data(A, reg.I2C_MST_STATUS) == 0
    assert emu.read_i2c_block_data(A, reg.EXT_SLV_SENS_DATA_00, 9) == [0] * 9


def _start_magnetometer(emu: Icm20948BusEmulator, clock: VirtualClock, divider: int) -> None:
    """Register-level start of the aux master, with SLV4 steps done by hand."""
    wake(emu)
    emu.write_byte_data(A, reg.LP_CONFIG, 0x00)  # the master follows the gyro's output rate
    emu.write_byte_data(A, reg.USER_CTRL, 0x20)
    bank(emu, 2)
    emu.write_byte_data(A, reg.GYRO_SMPLRT_DIV, divider)
    bank(emu, 3)
    emu.write_i2c_block_data(A, reg.I2C_SLV4_ADDR, [0x0C, reg.AK_CNTL2, 0x80, 0x08])  # ADDR REG CTRL DO
    clock.sleep(0.05)
    bank(emu, 0)
    assert emu.read_byte_data(A, reg.I2C_MST_STATUS) & reg.I2C_MST_STATUS_SLV4_DONE
    bank(emu, 3)
    assert emu.read_byte_data(A, reg.I2C_SLV4_CTRL) == 0x00  # EN cleared after one transfer
    emu.write_i2c_block_data(A, reg.I2C_SLV0_ADDR, [0x8C, 0x10, 0x89])
    bank(emu, 0)


def _mag_status(emu: Icm20948BusEmulator) -> tuple[int, int]:
    block = emu.read_i2c_block_data(A, reg.EXT_SLV_SENS_DATA_00, 9)
    return block[0], block[8]


def test_magnetometer_data_ready_follows_its_100_hz_rate() -> None:
    emu, clock = make()
    _start_magnetometer(emu, clock, divider=10)  # 102.3 Hz output: every mag sample read once
    ready = 0
    period = 11 / 1125
    for _ in range(300):
        clock.sleep(period)
        st1, _st2 = _mag_status(emu)
        assert not st1 & reg.AK_ST1_DOR
        ready += st1 & reg.AK_ST1_DRDY
    assert ready == pytest.approx(300 * 100 / (1125 / 11), abs=3)


def test_magnetometer_overrun_when_the_master_reads_slower_than_it_measures() -> None:
    emu, clock = make()
    _start_magnetometer(emu, clock, divider=30)  # 36 Hz < 100 Hz
    clock.sleep(0.1)
    st1, _ = _mag_status(emu)
    assert st1 & reg.AK_ST1_DRDY and st1 & reg.AK_ST1_DOR


def test_strong_disturbance_sets_hofl() -> None:
    emu, clock = make(magnetic_disturbance_ut={"base": (3000.0, 3000.0, 0.0)})
    _start_magnetometer(emu, clock, divider=10)
    clock.sleep(0.05)
    _, st2 = _mag_status(emu)
    assert st2 & reg.AK_ST2_HOFL


def test_same_seed_same_bytes_other_seed_other_noise() -> None:
    def run(seed: int) -> list[int]:
        emu, clock = make(seed=seed)
        wake(emu)
        out = []
        for _ in range(5):
            clock.sleep(0.01)
            out += emu.read_i2c_block_data(A, 0x2D, 14)
        return out

    assert run(3) == run(3)
    assert run(3) != run(4)


def test_scheduled_and_random_faults() -> None:
    emu, _ = make(seed=1, fault_probability=0.2)
    emu.fail_next(2, errno=errno.ETIMEDOUT, address=0x69)
    assert emu.chips[A].address == A
    outcomes = []
    for _ in range(200):
        try:
            emu.read_byte_data(A, 0)
            outcomes.append(True)
        except OSError as exc:
            assert exc.errno == errno.EIO
            outcomes.append(False)
    assert 20 <= outcomes.count(False) <= 60
    for _ in range(2):
        with pytest.raises(OSError) as info:
            emu.read_byte_data(0x69, 0)
        assert info.value.errno == errno.ETIMEDOUT


def test_parameters_are_validated() -> None:
    with pytest.raises(ValueError, match="fault_probability"):
        make(fault_probability=1.5)
    with pytest.raises(ValueError, match="gyro_noise_density"):
        ImuErrorModel(gyro_noise_density_rad_s_per_sqrt_hz=-1.0)
    with pytest.raises(ValueError, match="mag_soft_iron"):
        ImuErrorModel(mag_soft_iron=((1.0, 0.0), (0.0, 1.0)))  # type: ignore[arg-type]
    emu, _ = make()
    with pytest.raises(ValueError, match="disturbance"):
        emu.set_magnetic_disturbance("tip", (np.nan, 0.0, 0.0))
    with pytest.raises(ValueError, match="value"):
        emu.write_byte_data(A, 0x06, 256)
    with pytest.raises(KeyError, match="elbow"):
        emu.gyro_bias_rad_s("elbow")


def test_mounting_rotation_is_applied_between_plant_sensor_and_imu_frames() -> None:
    from hydrojet_bench.geometry import quat_from_rotvec

    # IMU mounted rotated +90 deg about the sensor's x axis: the IMU's +y points up
    emu, clock = make(mounting={"base": quat_from_rotvec([np.pi / 2, 0.0, 0.0])}, seed=9)
    wake(emu)
    clock.sleep(0.01)
    counts = struct.unpack(">3h", bytes(emu.read_i2c_block_data(A, 0x2D, 6)))
    accel = np.array(counts) * 9.80665 / 16384
    assert accel == pytest.approx([0.0, 9.81, 0.0], abs=0.1)
    # the tip, without a mounting entry, still reads +z up
    wake(emu, 0x69)
    clock.sleep(0.01)
    tip_counts = struct.unpack(">3h", bytes(emu.read_i2c_block_data(0x69, 0x2D, 6)))
    assert np.array(tip_counts) * 9.80665 / 16384 == pytest.approx([0.0, 0.0, 9.81], abs=0.1)


@given(st.lists(st.sampled_from([3, 6]), max_size=600), st.floats(1e-6, 10.0))
def test_noise_drawn_a_block_at_a_time_is_the_generators_sequence_call_for_call(counts, scale):
    """The chips draw their noise from `_StandardNormals`: what they get must be bit for
    bit what a ``normal`` call per sample would give (seeded runs stay comparable)."""
    from drivers.imu.emulator import _StandardNormals

    blocks = _StandardNormals(np.random.default_rng(11))
    calls = np.random.default_rng(11)
    for count in counts:  # up to 3600 draws: across several blocks
        assert np.array_equal(scale * blocks.take(count), calls.normal(0.0, scale, count))
