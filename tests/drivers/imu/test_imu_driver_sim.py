"""The driver against the SIMULATION (bus emulator + plant), on virtual time: start-up,
absent devices, faults, bias estimation, iron correction, and fused orientation."""

from __future__ import annotations

import asyncio
import errno
import math
import threading
import time
from collections.abc import Callable, Sequence

import numpy as np
import pytest
from imu_test_support import VirtualClock

from drivers.imu import (
    AsyncIcm20948,
    Icm20948,
    Icm20948BusEmulator,
    ImuBusError,
    ImuCalibration,
    ImuErrorModel,
    ImuIdentityError,
    ImuMotionError,
    ImuNotFoundError,
    ImuPairFusion,
    ImuRanges,
    ImuTimeoutError,
)
from drivers.plant import SensorTruth, StaticPlant
from hydrojet_bench.geometry import matrix_from_quat, quat_from_rotvec, quat_multiply, rotation_angle_deg

FIELD_IN_TRACKER_UT = np.array([20.0, 0.0, -45.0])


def rig(
    plant: object | None = None, **emulator_kwargs: object
) -> tuple[Icm20948BusEmulator, VirtualClock, Callable[..., Icm20948]]:
    clock = VirtualClock()
    emulator = Icm20948BusEmulator(plant or StaticPlant(), clock, **emulator_kwargs)  # type: ignore[arg-type]

    def driver(address: int, **kwargs: object) -> Icm20948:
        return Icm20948(emulator, address, clock=clock, sleep=clock.sleep, **kwargs)  # type: ignore[arg-type]

    return emulator, clock, driver


def tilted_plant(q_base: Sequence[float], q_tip: Sequence[float]) -> StaticPlant:
    return StaticPlant({"base": (q_base, (0.0, 0.0, 0.0)), "tip": (q_tip, (0.0, 0.0, -0.07))})


class WobblingPlant:
    """Base still; tip still until start_s, then swinging +-0.2 rad about the axis
    (tip frame) at 2 Hz about a 20 degree tilt."""

    gravity_in_tracker_m_s2 = np.array([0.0, 0.0, -9.81])
    magnetic_field_in_tracker_ut = FIELD_IN_TRACKER_UT

    def __init__(self, start_s: float = 0.0, axis: Sequence[float] = (1.0, 0.0, 0.0)) -> None:
        self.start_s = start_s
        self.axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
        self.rest = quat_from_rotvec([0.0, math.radians(20.0), 0.0])

    def sensor_truth(self, sensor: str, t_s: float) -> SensorTruth:
        if sensor == "base":
            return SensorTruth(np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3))
        w = 2 * math.pi * 2.0
        elapsed = max(0.0, t_s - self.start_s)
        angle = 0.2 * math.sin(w * elapsed)
        rate = 0.2 * w * math.cos(w * elapsed) if t_s > self.start_s else 0.0
        # body-frame rotation after the rest tilt: q = q_rest * exp(angle * axis)
        q = quat_multiply(self.rest, quat_from_rotvec(angle * self.axis))
        return SensorTruth(q, np.zeros(3), rate * self.axis)

    def apply_valve_duties(self, duties_permille: Sequence[int], t_s: float) -> None:
        pass


def test_both_chips_start_and_report_physical_values() -> None:
    q_tip = quat_from_rotvec([math.radians(90.0), 0.0, 0.0])
    emulator, clock, driver = rig(tilted_plant((1, 0, 0, 0), q_tip), seed=2)
    base, tip = driver(0x68), driver(0x69, ranges=ImuRanges(accel_full_scale_g=8, gyro_full_scale_dps=2000))
    base.initialize()
    tip.initialize()
    clock.sleep(0.05)
    b, t = base.read_raw(), tip.read_raw()
    assert b.accel_m_s2 == pytest.approx((0.0, 0.0, 9.81), abs=0.1)
    # tip rotated +90 deg about x: tracker up (+z) is the tip's +y... R^T (0,0,g)
    assert t.accel_m_s2 == pytest.approx((0.0, 9.81, 0.0), abs=0.1)
    expected_tip_field = matrix_from_quat(q_tip).T @ FIELD_IN_TRACKER_UT
    assert t.mag_ut == pytest.approx(tuple(expected_tip_field), abs=2.0)
    assert b.mag_ut == pytest.approx(tuple(FIELD_IN_TRACKER_UT), abs=2.0)
    assert b.temperature_degc == pytest.approx(30.0, abs=0.01)
    assert emulator.gyro_bias_rad_s("base") == pytest.approx(b.gyro_rad_s, abs=0.01)


def test_absent_tip_is_reported_by_address() -> None:
    _, _, driver = rig(sensors={0x68: "base"})
    driver(0x68).initialize()
    with pytest.raises(ImuNotFoundError, match="0x69") as info:
        driver(0x69).initialize()
    assert info.value.errno == errno.EREMOTEIO


def test_foreign_part_at_an_address_is_an_identity_error() -> None:
    _, _, driver = rig(who_am_i={0x69: 0x71})
    with pytest.raises(ImuIdentityError, match="0x69: ICM-20948 WHO_AM_I reads 0x71"):
        driver(0x69).initialize()


def test_transient_faults_are_absorbed_by_retries() -> None:
    emulator, clock, driver = rig(seed=5, fault_probability=0.05)
    imu = driver(0x68, retries=3)
    imu.initialize()
    for _ in range(200):
        clock.sleep(imu.sample_period_s)
        assert imu.read_raw().accel_m_s2[2] == pytest.approx(9.81, abs=0.2)
    emulator.fail_next(3, errno=errno.ETIMEDOUT)
    assert imu.read_raw().accel_m_s2[2] == pytest.approx(9.81, abs=0.2)


def test_persistent_fault_raises_bus_error_after_bounded_retries() -> None:
    emulator, _, driver = rig()
    imu = driver(0x68, retries=2)
    imu.initialize()
    before = emulator.transaction_count
    emulator.fail_next(100, errno=errno.EIO, address=0x68)
    with pytest.raises(ImuBusError, match=r"0x68: read 23 bytes") as info:
        imu.read_raw()
    assert info.value.errno == errno.EIO
    assert emulator.transaction_count - before == 3  # 1 + 2 retries, then it gave up


def test_unplugged_chip_raises_bus_error_naming_it() -> None:
    emulator, _, driver = rig()
    imu = driver(0x69)
    imu.initialize()
    emulator.detach(0x69)
    with pytest.raises(ImuBusError, match="0x69") as info:
        imu.read_sample()
    assert info.value.errno == errno.EREMOTEIO


def test_gyro_bias_estimation_recovers_the_emulated_bias() -> None:
    models = {
        "base": ImuErrorModel(gyro_bias_rad_s=(0.02, -0.015, 0.008)),
        "tip": ImuErrorModel(gyro_bias_rad_s=(-0.01, 0.03, -0.02)),
    }
    emulator, clock, driver = rig(error_models=models, seed=7)
    for address, sensor in ((0x68, "base"), (0x69, "tip")):
        imu = driver(address)
        imu.initialize()
        estimate = imu.estimate_gyro_bias(200)
        truth = emulator.gyro_bias_rad_s(sensor)
        # noise 0.0022 rad/s (DLPF 3) over 200 samples: standard error 1.6e-4; plus one LSB (2.7e-4)
        assert estimate.bias_rad_s == pytest.approx(tuple(truth), abs=6e-4)
        assert imu.calibration.gyro_bias_rad_s == estimate.bias_rad_s
        corrected = []
        for _ in range(50):
            clock.sleep(imu.sample_period_s)  # a new sample each time, not one sample 50 times
            corrected.append(imu.read_sample().gyro_rad_s)
        assert np.linalg.norm(np.mean(corrected, axis=0)) < 1.5e-3


def test_gyro_bias_estimation_rejects_motion() -> None:
    _, _, driver = rig(WobblingPlant())  # swinging from the start
    tip = driver(0x69)
    tip.initialize()
    original = tip.calibration
    with pytest.raises(ImuMotionError, match="0x69"):
        tip.estimate_gyro_bias(100)
    assert tip.calibration == original


def test_hard_and_soft_iron_correction_recovers_the_field() -> None:
    distortion = np.array([[1.15, 0.08, 0.0], [0.08, 0.9, -0.05], [0.0, -0.05, 1.05]])
    hard_iron = np.array([35.0, -22.0, 14.0])
    q_tip = quat_from_rotvec([0.3, -0.5, 1.0])
    models = {"tip": ImuErrorModel(mag_hard_iron_ut=tuple(hard_iron), mag_soft_iron=tuple(map(tuple, distortion)))}
    _, clock, driver = rig(tilted_plant((1, 0, 0, 0), q_tip), error_models=models, seed=3)
    tip = driver(0x69)
    tip.initialize()
    truth = matrix_from_quat(q_tip).T @ FIELD_IN_TRACKER_UT

    def mean_field() -> np.ndarray:
        values = []
        for _ in range(100):
            clock.sleep(tip.sample_period_s)
            values.append(tip.read_sample().mag_ut)
        return np.mean(values, axis=0)

    assert np.linalg.norm(mean_field() - truth) > 20.0  # uncorrected: far off
    tip.calibration = ImuCalibration(mag_hard_iron_ut=hard_iron, mag_soft_iron=np.linalg.inv(distortion))
    assert mean_field() == pytest.approx(truth, abs=0.3)


def test_magnetic_overflow_reaches_the_sample_as_a_flag() -> None:
    emulator, clock, driver = rig()
    imu = driver(0x68)
    imu.initialize()
    emulator.set_magnetic_disturbance("base", (4000.0, 2000.0, 0.0))
    clock.sleep(0.05)
    sample = imu.read_sample()
    assert sample.mag_ut is None
    raw = imu.read_raw()
    assert raw.mag_overflow and raw.mag_ut is None


def run_fusion(
    plant: StaticPlant, seconds: float, seed: int = 11, **emulator_kwargs: object
) -> tuple[np.ndarray, ImuPairFusion]:
    _, clock, driver = rig(plant, seed=seed, **emulator_kwargs)
    base, tip = driver(0x68), driver(0x69)
    for imu in (base, tip):
        imu.initialize()
        imu.estimate_gyro_bias(150)
    fusion = ImuPairFusion(base.sample_rate_hz)
    q_rel = np.array([1.0, 0.0, 0.0, 0.0])
    for _ in range(int(seconds * base.sample_rate_hz)):
        clock.sleep(base.sample_period_s)
        q_rel = fusion.update(base.read_sample(), tip.read_sample())
    return q_rel, fusion


@pytest.mark.parametrize(
    ("base_rotvec", "tip_rotvec"),
    [
        ((0.0, 0.0, 0.0), (math.radians(30.0), 0.0, 0.0)),
        ((0.0, math.radians(20.0), math.radians(60.0)), (0.3, -0.6, 0.4)),
    ],
    ids=["tip-30deg-about-x", "base-tilted-and-turned"],
)
def test_fused_tip_relative_to_base_matches_the_truth(base_rotvec: tuple, tip_rotvec: tuple) -> None:
    q_base, q_tip = quat_from_rotvec(base_rotvec), quat_from_rotvec(tip_rotvec)
    truth = quat_multiply(np.asarray(q_base) * [1, -1, -1, -1], q_tip)
    q_rel, fusion = run_fusion(tilted_plant(q_base, q_tip), seconds=3.0)
    assert rotation_angle_deg(q_rel, truth) < 2.0
    # each absolute orientation too: Madgwick's earth frame is the tracker frame here,
    # because the tracker field's horizontal part points along +x
    assert rotation_angle_deg(fusion.base.quaternion, q_base) < 2.0
    assert rotation_angle_deg(fusion.tip.quaternion, q_tip) < 2.0


@pytest.mark.parametrize("axis", [(1.0, 0.0, 0.0), (0.2, -0.5, 1.0)], ids=["about-x", "oblique"])
def test_fused_orientation_tracks_a_swinging_tip(axis: tuple[float, float, float]) -> None:
    """Exercises the gyro path (signs, units, integration step), not only the start-up
    orientation from gravity and field: the tip swings +-11 deg at 2 Hz."""
    clock_start = VirtualClock().now_s
    plant = WobblingPlant(start_s=clock_start + 2.5, axis=axis)
    _, clock, driver = rig(plant, seed=13)
    base, tip = driver(0x68), driver(0x69)
    for imu in (base, tip):
        imu.initialize()
        imu.estimate_gyro_bias(100)
    assert clock() < plant.start_s
    fusion = ImuPairFusion(base.sample_rate_hz)
    errors = []
    while clock() < plant.start_s + 2.0:
        clock.sleep(base.sample_period_s)
        q_rel = fusion.update(base.read_sample(), tip.read_sample())
        errors.append(rotation_angle_deg(q_rel, plant.sensor_truth("tip", clock()).orientation_in_tracker))
    assert max(errors) < 3.0


def test_local_magnetic_disturbance_corrupts_the_relative_heading() -> None:
    q_tip = quat_from_rotvec([math.radians(30.0), 0.0, 0.0])
    plant = tilted_plant((1, 0, 0, 0), q_tip)
    disturbance = {"tip": (0.0, 40.0, 0.0)}  # a magnet near the tip, pulling the field sideways
    q_rel, _ = run_fusion(plant, seconds=1.0, magnetic_disturbance_ut=disturbance)
    assert rotation_angle_deg(q_rel, q_tip) > 20.0


class SlowBus:
    """A bus whose every transaction hangs (a wedged I2C adapter)."""

    def __init__(self, delay_s: float) -> None:
        self.delay_s = delay_s

    def read_i2c_block_data(self, *args: object) -> list[int]:
        time.sleep(self.delay_s)
        return [0] * 23

    def write_byte_data(self, *args: object) -> None:
        time.sleep(self.delay_s)

    def read_byte_data(self, *args: object) -> int:
        time.sleep(self.delay_s)
        return 0

    def i2c_rdwr(self, *args: object) -> None:
        time.sleep(self.delay_s)


def test_async_wrappers_share_the_bus_and_fuse(run_async: Callable[..., object]) -> None:
    q_tip = quat_from_rotvec([math.radians(30.0), 0.0, 0.0])
    _, clock, driver = rig(tilted_plant((1, 0, 0, 0), q_tip), seed=4)
    lock = threading.Lock()
    base = AsyncIcm20948(driver(0x68), bus_lock=lock)
    tip = AsyncIcm20948(driver(0x69), bus_lock=lock)

    async def main() -> float:
        await asyncio.gather(base.initialize(), tip.initialize())
        await asyncio.gather(base.estimate_gyro_bias(100), tip.estimate_gyro_bias(100))
        fusion = ImuPairFusion(base.driver.sample_rate_hz)
        q_rel = np.array([1.0, 0.0, 0.0, 0.0])
        for _ in range(100):
            clock.sleep(base.driver.sample_period_s)
            b, t = await asyncio.gather(base.read_sample(), tip.read_sample())
            q_rel = fusion.update(b, t)
        return float(rotation_angle_deg(q_rel, q_tip))

    assert run_async(main, timeout_s=20.0) < 2.0


def test_async_call_on_a_hung_bus_times_out(run_async: Callable[..., object]) -> None:
    imu = AsyncIcm20948(Icm20948(SlowBus(0.3), 0x68), timeout_s=0.05)  # type: ignore[arg-type]

    async def main() -> None:
        with pytest.raises(ImuTimeoutError, match="0x68: read_sample did not finish within 0.05 s"):
            await imu.read_sample()

    run_async(main)


class ThreadRecordingBus(Icm20948BusEmulator):
    """The emulator, noting which thread each burst read runs on."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.read_threads: list[int] = []

    def read_i2c_block_data(self, *args: object, **kwargs: object) -> list[int]:
        self.read_threads.append(threading.get_ident())
        return super().read_i2c_block_data(*args, **kwargs)  # type: ignore[arg-type]


class BlockingRecordingBus(ThreadRecordingBus):
    calls_block = True  # as a real bus: every call may wait on the wire


@pytest.mark.parametrize(("bus_class", "on_loop_thread"), [(ThreadRecordingBus, True), (BlockingRecordingBus, False)])
def test_sample_reads_take_a_worker_thread_unless_the_bus_never_blocks(
        run_async: Callable[..., object], bus_class: type[ThreadRecordingBus], on_loop_thread: bool) -> None:
    clock = VirtualClock()
    bus = bus_class(StaticPlant(), clock)
    imu = AsyncIcm20948(Icm20948(bus, 0x68, clock=clock, sleep=clock.sleep))

    async def main() -> int:
        await imu.initialize()
        bus.read_threads.clear()
        clock.sleep(imu.driver.sample_period_s)
        sample = await imu.read_sample()
        assert sample.mag_ut is not None
        return threading.get_ident()

    loop_thread = run_async(main)
    assert imu.reads_inline is on_loop_thread
    assert bus.read_threads and all((thread == loop_thread) is on_loop_thread for thread in bus.read_threads)
