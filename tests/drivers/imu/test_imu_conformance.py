"""Third-party ICM-20948 drivers, unmodified, on our emulator.

Pimoroni's `icm20948` takes any smbus2-like object (`i2c_bus=`); Adafruit's
`adafruit_icm20x` talks to a `busio.I2C`, replaced here by `BusioI2C` below. Both drivers
sleep between transactions; their `time` is pointed at the emulator's virtual clock, so a
run neither waits nor depends on how fast the host is. One test per driver runs on wall
time as a user would.

Every reading is checked against the plant's truth within what the datasheet allows: one
LSB of the configured full scale plus five standard deviations of the noise the emulator's
DLPF setting lets through (bias and scale errors are zero in `EXACT`).
"""

from __future__ import annotations

import math
import time
import types
from collections.abc import Iterator

import adafruit_icm20x
import icm20948
import numpy as np
import pytest
from imu_test_support import VirtualClock
from smbus2 import i2c_msg

from drivers.imu import registers as reg
from drivers.imu.emulator import Icm20948BusEmulator, ImuErrorModel
from drivers.plant import SensorTruth
from drivers.rotations import matrix_from_quat, quat_normalize

G = reg.STANDARD_GRAVITY_M_S2
EXACT = ImuErrorModel(gyro_bias_rad_s=(0.0, 0.0, 0.0), gyro_bias_random_walk_rad_s_per_sqrt_s=0.0,
                      accel_scale_error=(0.0, 0.0, 0.0), gyro_scale_error=(0.0, 0.0, 0.0))
MAG_TOLERANCE_UT = 5 * EXACT.mag_noise_ut + reg.MAG_UT_PER_LSB
# Pimoroni computes (raw - 21) / 333.87 + 21: its offset of 21 LSB is 0.063 degC
TEMPERATURE_TOLERANCE_DEGC = 0.1


class HeldPlant:
    """Both sensors held at one tilt while their gyros read a constant body rate. Each
    channel is compared with its own truth, so the pose need not follow the rate."""

    gravity_in_tracker_m_s2 = np.array([0.0, 0.0, -9.81])
    magnetic_field_in_tracker_ut = np.array([20.0, 0.0, -45.0])
    orientation = quat_normalize(np.array([0.9, 0.2, -0.3, 0.25]))
    rate_rad_s = np.array([0.5, -0.3, 0.8])

    def sensor_truth(self, sensor: str, t_s: float) -> SensorTruth:
        return SensorTruth(self.orientation, np.zeros(3), self.rate_rad_s)

    def apply_valve_duties(self, duties_permille: object, t_s: float) -> None:
        """No valves on this bus."""

    def accel_g(self) -> np.ndarray:
        return matrix_from_quat(self.orientation).T @ -self.gravity_in_tracker_m_s2 / G

    def mag_die_ut(self) -> np.ndarray:
        """The field on the AK09916's own axes, as both drivers report it."""
        field = matrix_from_quat(self.orientation).T @ self.magnetic_field_in_tracker_ut
        return field * np.asarray(reg.MAG_AXIS_SIGNS_IN_IMU_FRAME)


def tolerances(emulator: Icm20948BusEmulator, address: int) -> tuple[float, float]:
    """(accel g, gyro dps): one LSB at the chip's full scale plus five noise sigmas."""
    chip = emulator.chips[address]
    ranges = chip.ranges()
    accel_sigma, gyro_sigma = chip.noise_std()
    accel_lsb = 1.0 / reg.ACCEL_FULL_SCALES[ranges.accel_fs_sel][1]
    gyro_lsb = 1.0 / reg.GYRO_FULL_SCALES[ranges.gyro_fs_sel][1]
    return accel_lsb + 5 * accel_sigma / G, gyro_lsb + 5 * math.degrees(gyro_sigma)


def make_emulator(clock: object, seed: int = 0) -> Icm20948BusEmulator:
    return Icm20948BusEmulator(HeldPlant(), clock, error_models={"base": EXACT, "tip": EXACT},  # type: ignore[arg-type]
                               seed=seed)


# --- Pimoroni ----------------------------------------------------------------------


@pytest.fixture
def virtual_pimoroni(monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[VirtualClock, Icm20948BusEmulator]]:
    clock = VirtualClock()
    monkeypatch.setattr(icm20948, "time", types.SimpleNamespace(sleep=clock.sleep, time=clock))
    yield clock, make_emulator(clock)


def test_pimoroni_initialises_every_time(monkeypatch: pytest.MonkeyPatch) -> None:
    for seed in range(5):
        clock = VirtualClock(start_s=10.0 + 0.37 * seed)  # a different phase of every clock each time
        monkeypatch.setattr(icm20948, "time", types.SimpleNamespace(sleep=clock.sleep, time=clock))
        imu = icm20948.ICM20948(i2c_addr=0x68, i2c_bus=make_emulator(clock, seed))
        assert imu.read_magnetometer_data() == pytest.approx(tuple(HeldPlant().mag_die_ut()), abs=MAG_TOLERANCE_UT)


def test_pimoroni_reads_match_the_plant(virtual_pimoroni: tuple[VirtualClock, Icm20948BusEmulator]) -> None:
    clock, emulator = virtual_pimoroni
    imu = icm20948.ICM20948(i2c_addr=0x69, i2c_bus=emulator)
    accel_tol, gyro_tol = tolerances(emulator, 0x69)
    plant = HeldPlant()
    for _ in range(5):
        clock.sleep(0.02)
        motion = imu.read_accelerometer_gyro_data()
        assert motion[:3] == pytest.approx(tuple(plant.accel_g()), abs=accel_tol)
        assert motion[3:] == pytest.approx(tuple(np.degrees(plant.rate_rad_s)), abs=gyro_tol)
        assert imu.read_temperature() == pytest.approx(EXACT.temperature_degc, abs=TEMPERATURE_TOLERANCE_DEGC)
    # repeated single measurements: each one arrives (no 1 s timeouts) and is new
    singles = [imu.read_magnetometer_data() for _ in range(10)]
    assert singles == [pytest.approx(tuple(plant.mag_die_ut()), abs=MAG_TOLERANCE_UT)] * 10
    assert len(set(singles)) > 5


def test_pimoroni_continuous_magnetometer(virtual_pimoroni: tuple[VirtualClock, Icm20948BusEmulator]) -> None:
    clock, emulator = virtual_pimoroni
    imu = icm20948.ICM20948(i2c_addr=0x68, i2c_bus=emulator)
    imu.mag_write(icm20948.AK09916_CNTL2, icm20948.AK09916_CNTL2_MODE_CONT4)  # 100 Hz
    readings = []
    for _ in range(10):
        clock.sleep(0.01)
        assert imu.magnetometer_ready()
        data = imu.mag_read_bytes(icm20948.AK09916_HXL, 8)  # through ST2: releases the next one
        readings.append(np.array(np.frombuffer(bytes(data[:6]), "<i2"), dtype=float) * reg.MAG_UT_PER_LSB)
        assert not data[7] & reg.AK_ST2_HOFL
    assert np.max(np.abs(np.array(readings) - HeldPlant().mag_die_ut())) <= MAG_TOLERANCE_UT
    assert len({r.tobytes() for r in readings}) > 5


@pytest.mark.parametrize("scale", [2, 4, 8, 16])
def test_pimoroni_accelerometer_full_scale(virtual_pimoroni: tuple[VirtualClock, Icm20948BusEmulator],
                                            scale: int) -> None:
    clock, emulator = virtual_pimoroni
    imu = icm20948.ICM20948(i2c_addr=0x68, i2c_bus=emulator)
    imu.set_accelerometer_full_scale(scale)
    clock.sleep(0.02)
    assert emulator.chips[0x68].ranges().accel_full_scale_g == scale
    accel_tol, _ = tolerances(emulator, 0x68)
    assert imu.read_accelerometer_gyro_data()[:3] == pytest.approx(tuple(HeldPlant().accel_g()), abs=accel_tol)


@pytest.mark.parametrize("scale", [250, 500, 1000, 2000])
def test_pimoroni_gyro_full_scale(virtual_pimoroni: tuple[VirtualClock, Icm20948BusEmulator], scale: int) -> None:
    clock, emulator = virtual_pimoroni
    imu = icm20948.ICM20948(i2c_addr=0x68, i2c_bus=emulator)
    imu.set_gyro_full_scale(scale)
    clock.sleep(0.02)
    assert emulator.chips[0x68].ranges().gyro_full_scale_dps == scale
    _, gyro_tol = tolerances(emulator, 0x68)
    assert imu.read_accelerometer_gyro_data()[3:] == pytest.approx(tuple(np.degrees(HeldPlant.rate_rad_s)),
                                                                     abs=gyro_tol)


def _distinct_readings(clock: VirtualClock, read: object, duration_s: float, step_s: float = 0.001) -> int:
    """How many different values `read()` returns when polled every step_s until duration_s
    of clock time has passed (the drivers' own sleeps count too). Noise makes every new
    sample differ from the previous one."""
    end = clock() + duration_s
    values = []
    while clock() < end:
        values.append(read())  # type: ignore[operator]
        clock.sleep(step_s)
    return 1 + sum(a != b for a, b in zip(values, values[1:]))


def test_pimoroni_sample_rates_are_delivered(virtual_pimoroni: tuple[VirtualClock, Icm20948BusEmulator]) -> None:
    clock, emulator = virtual_pimoroni
    imu = icm20948.ICM20948(i2c_addr=0x68, i2c_bus=emulator)
    imu.set_accelerometer_sample_rate(10)  # divider 111: 10.04 Hz
    imu.set_gyro_sample_rate(50)  # divider 21: 51.1 Hz
    accel = _distinct_readings(clock, lambda: imu.read_accelerometer_gyro_data()[:3], 1.0)
    gyro = _distinct_readings(clock, lambda: imu.read_accelerometer_gyro_data()[3:], 1.0)
    assert accel == pytest.approx(10, abs=1)
    assert gyro == pytest.approx(51, abs=1)


def test_pimoroni_low_pass_settings_shape_the_noise(virtual_pimoroni: tuple[VirtualClock, Icm20948BusEmulator]) -> None:
    clock, emulator = virtual_pimoroni
    imu = icm20948.ICM20948(i2c_addr=0x68, i2c_bus=emulator)
    imu.set_accelerometer_full_scale(2)  # 61 ug LSB: the noise is resolved

    def spread() -> tuple[float, float]:
        samples = []
        for _ in range(400):
            clock.sleep(0.01)
            samples.append(imu.read_accelerometer_gyro_data())
        return float(np.mean(np.std(np.array(samples)[:, :3], axis=0))), float(
            np.mean(np.std(np.array(samples)[:, 3:], axis=0))
        )

    filtered = spread()  # Pimoroni's init: DLPF on
    imu.set_accelerometer_low_pass(enabled=False)
    imu.set_gyro_low_pass(enabled=False)
    bypassed = spread()
    chip = emulator.chips[0x68]
    accel_sigma, gyro_sigma = chip.noise_std()
    assert bypassed == pytest.approx((accel_sigma / G, math.degrees(gyro_sigma)), rel=0.15)
    # DS 10: bypass noise bandwidths 1248 Hz (accel) and 12316 Hz (gyro); Pimoroni's mode 5
    # lands in DLPFCFG 2 (it shifts the mode by 4, not 3): 136 Hz and 154.3 Hz.
    assert bypassed[0] / filtered[0] == pytest.approx(math.sqrt(1248 / 136), rel=0.15)
    assert bypassed[1] / filtered[1] == pytest.approx(math.sqrt(12316 / 154.3), rel=0.15)


def test_pimoroni_on_wall_time() -> None:
    emulator = make_emulator(time.monotonic)
    imu = icm20948.ICM20948(i2c_addr=0x68, i2c_bus=emulator)
    assert imu.read_magnetometer_data() == pytest.approx(tuple(HeldPlant().mag_die_ut()), abs=MAG_TOLERANCE_UT)
    accel_tol, _ = tolerances(emulator, 0x68)
    assert imu.read_accelerometer_gyro_data()[:3] == pytest.approx(tuple(HeldPlant().accel_g()), abs=accel_tol)


# --- Adafruit ----------------------------------------------------------------------


class BusioI2C:
    """The part of `busio.I2C` that adafruit_bus_device uses, on an smbus2-like bus."""

    def __init__(self, bus: Icm20948BusEmulator) -> None:
        self.bus = bus
        self._locked = False

    def try_lock(self) -> bool:
        if self._locked:
            return False
        self._locked = True
        return True

    def unlock(self) -> None:
        self._locked = False

    def writeto(self, address: int, buffer: bytes, *, start: int = 0, end: int | None = None) -> None:
        self.bus.i2c_rdwr(i2c_msg.write(address, bytes(buffer[start:end])))

    def readfrom_into(self, address: int, buffer: bytearray, *, start: int = 0, end: int | None = None) -> None:
        end = len(buffer) if end is None else end
        message = i2c_msg.read(address, end - start)
        self.bus.i2c_rdwr(message)
        buffer[start:end] = bytes(message)

    def writeto_then_readfrom(self, address: int, buffer_out: bytes, buffer_in: bytearray, *, out_start: int = 0,
                              out_end: int | None = None, in_start: int = 0, in_end: int | None = None) -> None:
        in_end = len(buffer_in) if in_end is None else in_end
        write = i2c_msg.write(address, bytes(buffer_out[out_start:out_end]))
        read = i2c_msg.read(address, in_end - in_start)
        self.bus.i2c_rdwr(write, read)
        buffer_in[in_start:in_end] = bytes(read)


@pytest.fixture
def virtual_adafruit(monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[VirtualClock, Icm20948BusEmulator]]:
    clock = VirtualClock()
    monkeypatch.setattr(adafruit_icm20x, "sleep", clock.sleep)
    yield clock, make_emulator(clock)


def test_adafruit_initialises_every_time(monkeypatch: pytest.MonkeyPatch) -> None:
    for seed in range(5):
        clock = VirtualClock(start_s=10.0 + 0.37 * seed)
        monkeypatch.setattr(adafruit_icm20x, "sleep", clock.sleep)
        icm = adafruit_icm20x.ICM20948(BusioI2C(make_emulator(clock, seed)), 0x69)
        clock.sleep(0.02)
        assert icm.magnetic == pytest.approx(tuple(HeldPlant().mag_die_ut()), abs=MAG_TOLERANCE_UT)


def test_adafruit_reads_match_the_plant(virtual_adafruit: tuple[VirtualClock, Icm20948BusEmulator]) -> None:
    clock, emulator = virtual_adafruit
    icm = adafruit_icm20x.ICM20948(BusioI2C(emulator), 0x68)
    accel_tol, gyro_tol = tolerances(emulator, 0x68)
    plant = HeldPlant()
    magnetic = []
    for _ in range(10):
        clock.sleep(0.011)  # longer than the magnetometer's 100 Hz period: a new value each time
        assert icm.acceleration == pytest.approx(tuple(plant.accel_g() * G), abs=accel_tol * G)
        assert icm.gyro == pytest.approx(tuple(plant.rate_rad_s), abs=math.radians(gyro_tol))
        magnetic.append(icm.magnetic)
    assert magnetic == [pytest.approx(tuple(plant.mag_die_ut()), abs=MAG_TOLERANCE_UT)] * 10
    assert len(set(magnetic)) > 5


def test_adafruit_data_ready_follows_the_samples(virtual_adafruit: tuple[VirtualClock, Icm20948BusEmulator]) -> None:
    clock, emulator = virtual_adafruit
    icm = adafruit_icm20x.ICM20948(BusioI2C(emulator), 0x68)
    clock.sleep(0.02)
    assert icm.data_ready()
    assert not icm.data_ready()  # INT_STATUS_1 clears on read
    clock.sleep(1.0 / icm.gyro_data_rate)
    assert icm.data_ready()


def test_adafruit_configuration_calls(virtual_adafruit: tuple[VirtualClock, Icm20948BusEmulator]) -> None:
    clock, emulator = virtual_adafruit
    icm = adafruit_icm20x.ICM20948(BusioI2C(emulator), 0x68)
    chip = emulator.chips[0x68]
    plant = HeldPlant()
    for accel_range, gyro_range in zip(
        (adafruit_icm20x.AccelRange.RANGE_2G, adafruit_icm20x.AccelRange.RANGE_4G,  # type: ignore[attr-defined]
         adafruit_icm20x.AccelRange.RANGE_8G, adafruit_icm20x.AccelRange.RANGE_16G),  # type: ignore[attr-defined]
        (adafruit_icm20x.GyroRange.RANGE_250_DPS, adafruit_icm20x.GyroRange.RANGE_500_DPS,  # type: ignore[attr-defined]
         adafruit_icm20x.GyroRange.RANGE_1000_DPS, adafruit_icm20x.GyroRange.RANGE_2000_DPS),  # type: ignore[attr-defined]
    ):
        icm.accelerometer_range = accel_range
        icm.gyro_range = gyro_range
        assert icm.accelerometer_range == accel_range and icm.gyro_range == gyro_range
        clock.sleep(0.02)
        accel_tol, gyro_tol = tolerances(emulator, 0x68)
        assert icm.acceleration == pytest.approx(tuple(plant.accel_g() * G), abs=accel_tol * G)
        assert icm.gyro == pytest.approx(tuple(plant.rate_rad_s), abs=math.radians(gyro_tol))
    icm.accelerometer_data_rate = 10  # divider 111
    icm.gyro_data_rate = 50
    assert icm.accelerometer_data_rate == pytest.approx(1125 / 113, rel=0.02)
    assert chip.accel_period_s == pytest.approx(1 / icm.accelerometer_data_rate)
    assert _distinct_readings(clock, lambda: icm.acceleration, 1.0) == pytest.approx(10, abs=1)
    icm.accel_dlpf_cutoff = adafruit_icm20x.AccelDLPFFreq.FREQ_5_7HZ_3DB  # type: ignore[attr-defined]
    icm.gyro_dlpf_cutoff = adafruit_icm20x.GyroDLPFFreq.FREQ_5_7HZ_3DB  # type: ignore[attr-defined]
    assert icm.accel_dlpf_cutoff == adafruit_icm20x.AccelDLPFFreq.FREQ_5_7HZ_3DB  # type: ignore[attr-defined]
    # DS 10: DLPFCFG 6 has noise bandwidths 8.3 Hz (accel) and 8.9 Hz (gyro)
    accel_sigma, gyro_sigma = chip.noise_std()
    assert accel_sigma == pytest.approx(EXACT.accel_noise_density_m_s2_per_sqrt_hz * math.sqrt(8.3))
    assert gyro_sigma == pytest.approx(EXACT.gyro_noise_density_rad_s_per_sqrt_hz * math.sqrt(8.9))
    icm.gyro_dlpf_cutoff = adafruit_icm20x.GyroDLPFFreq.DISABLED  # type: ignore[attr-defined]
    assert chip.noise_std()[1] == pytest.approx(EXACT.gyro_noise_density_rad_s_per_sqrt_hz * math.sqrt(12316))
    icm.magnetometer_data_rate = adafruit_icm20x.MagDataRate.RATE_10HZ  # type: ignore[attr-defined]
    clock.sleep(0.2)
    assert _distinct_readings(clock, lambda: icm.magnetic, 1.0, step_s=0.005) == pytest.approx(10, abs=1)


def test_adafruit_on_wall_time() -> None:
    emulator = make_emulator(time.monotonic)
    icm = adafruit_icm20x.ICM20948(BusioI2C(emulator), 0x69)
    time.sleep(0.02)
    assert icm.magnetic == pytest.approx(tuple(HeldPlant().mag_die_ut()), abs=MAG_TOLERANCE_UT)
    assert icm.data_ready()
