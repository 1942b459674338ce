"""The FIFO against the SIMULATION (bus emulator + plant, virtual time): every sample
instant is queued and sampled at its own instant, a late host loses nothing within the
FIFO's depth and is told when it loses more, and stamps stay one period apart."""

from __future__ import annotations

import errno
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from imu_test_support import VirtualClock
from test_imu_driver_sim import WobblingPlant, rig

from drivers.imu import FifoRead, Icm20948, Icm20948BusEmulator, ImuBusError, sample_rate_divider_for
from drivers.imu import registers as reg


def started(plant: object | None = None, **emulator_kwargs: object) -> tuple[Icm20948BusEmulator, VirtualClock,
                                                                          Icm20948]:
    emulator, clock, driver = rig(plant, **emulator_kwargs)
    imu = driver(0x69)
    imu.initialize()
    imu.enable_fifo()
    return emulator, clock, imu


def test_every_instant_since_the_last_read_is_delivered_in_order() -> None:
    emulator, clock, imu = started()
    period = imu.sample_period_s
    delivered = []
    for wait in (0.0331, 0.1, 0.0079, 0.0512, 0.2):  # all within the FIFO's 22 records
        clock.sleep(wait)
        read = imu.read_fifo()
        assert not read.overflowed
        delivered.extend(read.samples)
    elapsed = 0.0331 + 0.1 + 0.0079 + 0.0512 + 0.2
    assert abs(len(delivered) - elapsed / period) <= 1.0
    # stamped within half a period of the instant each was sampled at
    stamps = np.array([s.t_s for s in delivered])
    grid = emulator.chips[0x69].gyro_grid
    true_instants = grid.origin_s + (grid.index - np.arange(len(stamps))[::-1]) * period
    assert np.all(np.diff(stamps) > 0)
    assert np.max(np.abs(stamps - true_instants)) <= period / 2 + 1e-9
    assert all(s.accel_m_s2[2] == pytest.approx(9.81, abs=0.1) for s in delivered)


class _SlowBus:
    """The emulated bus with transfers that take ``transfer_s`` of the virtual clock: the
    chip answers at the end of each (a 400 kHz bus; or the simulated rig at x25, where
    0.2 ms of the host's time is 5 ms of the chip's)."""

    def __init__(self, bus: Icm20948BusEmulator, clock: VirtualClock, transfer_s: float) -> None:
        self._bus, self._clock, self.transfer_s = bus, clock, transfer_s

    def __getattr__(self, name: str) -> object:
        attribute = getattr(self._bus, name)
        if not callable(attribute):
            return attribute

        def transfer(*args: object, **kwargs: object) -> object:
            self._clock.now_s += self.transfer_s
            return attribute(*args, **kwargs)
        return transfer


@pytest.mark.parametrize("transfer_periods", [0.0, 0.3, 0.6, 0.9])
def test_stamps_hold_when_the_chip_samples_during_the_read(transfer_periods: float) -> None:
    """The chip goes on sampling while the host reads the status and the count: a stamp
    taken before those transfers put the newest records after the host's time."""
    emulator, clock, _ = rig()
    bus = _SlowBus(emulator, clock, 0.0)
    imu = Icm20948(bus, 0x69, clock=clock, sleep=clock.sleep)
    imu.initialize()
    imu.enable_fifo()
    period = imu.sample_period_s
    bus.transfer_s = transfer_periods * period
    delivered = []
    for wait in (0.0331, 0.05, 0.0079, 0.0512, 0.031, 0.02, 0.0605):
        clock.sleep(wait)
        read = imu.read_fifo()
        assert not read.overflowed
        delivered.extend(read.samples)
    stamps = np.array([s.t_s for s in delivered])
    grid = emulator.chips[0x69].gyro_grid
    true_instants = grid.origin_s + (grid.index - np.arange(len(stamps))[::-1]) * period
    assert np.all(np.diff(stamps) > 0)
    assert np.max(np.abs(stamps - true_instants)) <= period / 2 + 1e-9


def test_each_record_is_sampled_at_its_own_instant() -> None:
    # A 2 Hz swing read every 0.15 s: if the emulator sampled at the read, the gyro would
    # be the same across a batch; it must follow the plant's rate sample by sample.
    plant = WobblingPlant(start_s=0.0)
    _, clock, imu = started(plant, error_models=None, seed=3)
    samples = []
    for _ in range(8):
        clock.sleep(0.15)
        samples.extend(imu.read_fifo().samples)
    gyro = np.array([s.gyro_rad_s[0] for s in samples])
    truth = np.array([plant.sensor_truth("tip", s.t_s).angular_velocity_in_sensor_rad_s[0] for s in samples])
    # bias (~0.006 rad/s), noise and DLPF-free sampling: within 0.05 of a 2.5 rad/s swing
    assert np.max(np.abs(gyro - truth)) < 0.05 + imu.sample_period_s * 0.2 * (2 * math.pi * 2) ** 2


def test_a_host_later_than_the_fifo_is_told_and_recovers() -> None:
    _, clock, imu = started()
    clock.sleep(1.0)  # 102 instants, 22 records fit
    read = imu.read_fifo()
    assert read.overflowed and read.samples == ()
    clock.sleep(0.05)
    after = imu.read_fifo()
    assert not after.overflowed and 4 <= len(after.samples) <= 6
    assert after.samples[-1].t_s <= clock()


def test_a_larger_fifo_holds_more() -> None:
    _, clock, imu = started(fifo_size_bytes=4096)
    clock.sleep(1.0)
    read = imu.read_fifo()
    assert not read.overflowed and len(read.samples) == pytest.approx(102, abs=1)


def test_stream_mode_keeps_the_newest_bytes_and_flags_the_overflow() -> None:
    emulator, clock, imu = started()
    imu.write_register(0, reg.FIFO_MODE, 0x00)
    clock.sleep(1.0)
    assert emulator.read_byte_data(0x69, reg.INT_STATUS_2) & 0x01
    assert emulator.read_byte_data(0x69, reg.INT_STATUS_2) == 0  # read to clear
    count = emulator.read_i2c_block_data(0x69, reg.FIFO_COUNTH, 2)
    assert (count[0] << 8) | count[1] == reg.FIFO_SIZE_BYTES


def test_fifo_r_w_pops_and_an_empty_fifo_repeats_its_last_byte() -> None:
    emulator, clock, imu = started()
    clock.sleep(imu.sample_period_s * 1.5)
    record = emulator.read_i2c_block_data(0x69, reg.FIFO_R_W, 23)
    assert emulator.read_i2c_block_data(0x69, reg.FIFO_R_W, 3) == [record[-1]] * 3
    assert emulator.read_i2c_block_data(0x69, reg.FIFO_COUNTH, 2) == [0, 0]


def test_fifo_reset_empties_it_and_holding_it_stops_writes() -> None:
    emulator, clock, imu = started()
    clock.sleep(0.1)
    emulator.write_byte_data(0x69, reg.FIFO_RST, reg.FIFO_RST_ASSERT)
    assert emulator.read_i2c_block_data(0x69, reg.FIFO_COUNTH, 2) == [0, 0]
    clock.sleep(0.1)
    assert emulator.read_i2c_block_data(0x69, reg.FIFO_COUNTH, 2) == [0, 0]
    emulator.write_byte_data(0x69, reg.FIFO_RST, 0)
    clock.sleep(0.1)
    assert emulator.read_i2c_block_data(0x69, reg.FIFO_COUNTH, 2)[1] > 0


def test_a_bus_fault_mid_drain_costs_that_batch_only() -> None:
    emulator, clock, imu = started()
    clock.sleep(0.1)
    imu.read_fifo()
    clock.sleep(0.1)
    transfer = emulator.i2c_rdwr

    def failing_once(*messages: object) -> None:
        emulator.i2c_rdwr = transfer  # type: ignore[method-assign]
        raise OSError(errno.EIO, "I/O error")

    emulator.i2c_rdwr = failing_once  # type: ignore[method-assign]
    with pytest.raises(ImuBusError, match="0x69: read .* FIFO bytes"):
        imu.read_fifo()
    clock.sleep(0.1)
    read = imu.read_fifo()
    assert not read.overflowed and len(read.samples) >= 9


@pytest.mark.parametrize(("rate_hz", "expected_hz"), [(100.0, 102.27), (10.0, 10.04), (1125.0, 1125.0), (1.0, 4.39)])
def test_rate_divider_gives_at_least_the_rate_asked(rate_hz: float, expected_hz: float) -> None:
    divider = sample_rate_divider_for(rate_hz)
    assert reg.BASE_SAMPLE_RATE_HZ / (1 + divider) == pytest.approx(expected_hz, abs=0.01)
    with pytest.raises(ValueError, match="IMU rate"):
        sample_rate_divider_for(0.0)


def test_records_written_after_a_pop_behind_a_cut_record_are_never_decoded() -> None:
    # The race of a full snapshot FIFO: the host counts 22 whole records, the chip writes
    # the cut 23rd during the transfer, the host pops the 22 and the cut bytes lead the
    # FIFO; records written next follow them. The next read must drop, not misread, them.
    emulator, clock, imu = started()
    chip = emulator.chips[0x69]
    clock.sleep(reg.FIFO_RECORDS * imu.sample_period_s + 1e-4)
    whole = imu.read_fifo()
    assert not whole.overflowed and len(whole.samples) == reg.FIFO_RECORDS
    chip.fifo[:0] = bytes(6)  # the cut record's tail now leads
    chip.banks[0][reg.INT_STATUS_2] |= 0x01
    clock.sleep(0.05)
    assert imu.read_fifo() == FifoRead((), overflowed=True)
    clock.sleep(0.05)
    again = imu.read_fifo()
    assert not again.overflowed and 4 <= len(again.samples) <= 6


@settings(max_examples=25, deadline=None)
@given(gaps=st.lists(st.tuples(st.floats(0.0, 0.25), st.lists(st.floats(0.0, 1.0), max_size=4)),
                     min_size=1, max_size=6), accel_late_s=st.sampled_from([0.0, 0.0013, 0.0061]))
# Found by hypothesis: the chips ran once while the FIFO overflowed, and the noise of the
# next read differed.
@example(gaps=[(0.25, [0.9375]), (0.125, [])], accel_late_s=0.0)
# The simulated rig's grids: the host's divider writes are real time apart.
@example(gaps=[(0.1, [0.31, 0.77]), (0.05, [0.5])], accel_late_s=0.0013)
def test_chips_sampling_between_reads_change_nothing_a_read_finds(gaps, accel_late_s) -> None:
    # `run_chips` (a look at the chips between reads, as silicon samples on its own)
    # only moves the sampling work earlier: the same reads, of a moving tip, get the same samples, stamps and
    # overflows (waits up to 0.25 s: past the FIFO's 22 records), also when the accel's
    # grid lags the gyro's. Once a FIFO has overflowed the noise may differ: instants a
    # full FIFO drops are not sampled, so how many noise draws they cost depends on when
    # the chip was looked at.
    lazy, lazy_clock, lazy_imu = started(WobblingPlant(start_s=100.0))
    busy, busy_clock, busy_imu = started(WobblingPlant(start_s=100.0))
    for clock, imu in ((lazy_clock, lazy_imu), (busy_clock, busy_imu)):
        if accel_late_s:
            clock.sleep(accel_late_s)
            imu.write_register(2, reg.ACCEL_SMPLRT_DIV_2, imu.sample_rate_divider)
    overflowed = False
    for wait_s, run_fractions in gaps:
        done = 0.0
        for fraction in sorted(run_fractions):
            busy_clock.sleep(fraction * wait_s - done)
            done = fraction * wait_s
            busy.run_chips()
        busy_clock.sleep(wait_s - done)
        lazy_clock.sleep(wait_s)
        assert busy_clock() == pytest.approx(lazy_clock(), abs=1e-12)
        expected, got = lazy_imu.read_fifo(), busy_imu.read_fifo()
        assert got.overflowed == expected.overflowed
        assert [s.t_s for s in got.samples] == pytest.approx([s.t_s for s in expected.samples], abs=1e-12)
        if not overflowed:
            assert [replace(s, t_s=0.0) for s in got.samples] == [replace(s, t_s=0.0) for s in expected.samples]
        overflowed = overflowed or expected.overflowed


def test_with_the_fifo_on_a_register_read_still_shows_the_newest_accel_sample() -> None:
    # Looks at the chip make FIFO records at gyro instants only; an accel instant after
    # the newest of them is latched when the sample registers are read.
    emulator, clock, imu = started(WobblingPlant(start_s=100.0))
    clock.sleep(0.0013)
    imu.write_register(2, reg.ACCEL_SMPLRT_DIV_2, imu.sample_rate_divider)
    chip = emulator.chips[0x69]
    clock.sleep(0.1)
    emulator.run_chips()
    newest_accel = math.floor((clock() - chip.accel_grid.origin_s) / chip.accel_period_s + 1e-9)
    assert chip.accel_grid.index == newest_accel - 1  # its newest instant is after the gyro's
    imu.read_fifo()  # the FIFO's registers: still not latched
    assert chip.accel_grid.index == newest_accel - 1
    imu.read_registers(0, reg.ACCEL_XOUT_H, 6)
    assert chip.accel_grid.index == newest_accel


# --- the batched run against instant by instant --------------------------------------------

_SETUPS = {
    # name: (bank, register, value) writes after `enable_fifo`, as a host could make them
    # ("divider": the example's), or ("sleep", seconds) between them
    "driver's": (),
    "accel off": ((0, reg.PWR_MGMT_2, reg.PWR_MGMT_2_DISABLE_ACCEL),),
    "gyro off": ((0, reg.PWR_MGMT_2, reg.PWR_MGMT_2_DISABLE_GYRO),),
    "stream mode": ((0, reg.FIFO_MODE, 0x00),),
    "copy without ST1": ((3, reg.I2C_SLV0_REG, reg.AK_HXL), (3, reg.I2C_SLV0_CTRL, reg.I2C_SLV_EN | 8)),
    "copy stops before ST2": ((3, reg.I2C_SLV0_CTRL, reg.I2C_SLV_EN | 4),),
    "no copy": ((3, reg.I2C_SLV0_CTRL, 0x00),),
    "master off": ((0, reg.USER_CTRL, reg.USER_CTRL_FIFO_EN),),
    "accel on its own grid": ((2, reg.ACCEL_SMPLRT_DIV_2, 7),),
    # The session's case: the host's writes are real time apart, so the accel's grid,
    # restarted by its divider's write, lags the gyro's by a fraction of a period.
    "accel grid a little late": (("sleep", 0.0013), (2, reg.ACCEL_SMPLRT_DIV_2, "divider")),
    "master on its own clock": ((0, reg.LP_CONFIG, reg.LP_CONFIG_I2C_MST_CYC), (3, reg.I2C_MST_ODR_CONFIG, 3)),
    "gyro only in the FIFO": ((0, reg.FIFO_EN_2, reg.FIFO_EN_2_GYRO_X | reg.FIFO_EN_2_GYRO_Z),),
}


def _chip_state(emulator: Icm20948BusEmulator, address: int) -> tuple:
    chip = emulator.chips[address]
    return (bytes(chip.fifo), [bytes(bank) for bank in chip.banks], bytes(chip.ak.regs), chip.ak.last_index,
            chip.ak.locked, chip.bias_drift_rad_s.tobytes(), chip.gyro_grid.index, chip.accel_grid.index)


@settings(max_examples=40, deadline=None)
@given(setup=st.sampled_from(sorted(_SETUPS)), divider=st.sampled_from([4, 10, 22]),
       ak_mode=st.sampled_from([reg.AK_MODE_CONTINUOUS_100HZ, 0x06, 0x02]),
       looks=st.lists(st.tuples(st.floats(0.0, 0.3), st.sampled_from(["run", "read", "reset"])),
                      min_size=3, max_size=25))
@example(setup="driver's", divider=10, ak_mode=reg.AK_MODE_CONTINUOUS_100HZ,
         looks=[(0.02, "run"), (0.05, "read"), (0.5, "run"), (0.001, "read")])
# A stream-mode FIFO that the host leaves for longer than it holds: the run starts past
# the instants it would overwrite, with the drift's step over all of them.
@example(setup="stream mode", divider=4, ak_mode=0x06, looks=[(0.3, "run"), (0.01, "read"), (0.02, "run")])
# Accel instants of their own in the run, and magnetometer instants after them.
@example(setup="accel grid a little late", divider=4, ak_mode=reg.AK_MODE_CONTINUOUS_100HZ, looks=[(0.25, "run")])
def test_a_batched_run_of_instants_is_bit_for_bit_the_instant_by_instant_one(setup, divider, ak_mode, looks) -> None:
    """The FIFO's batched run (one plant call and one kernel per look) against the
    reference, every instant through the register model, on a moving plant: the same
    FIFO bytes, registers, magnetometer state and gyro drift after every look, whatever
    the host configured (the runs it cannot make fall back to the reference)."""
    rigs = []
    for batched in (True, False):
        emulator, clock, driver = rig(WobblingPlant(start_s=100.05), seed=5)
        imu = driver(0x69, sample_rate_divider=divider)
        imu.initialize()
        imu.aux_write(reg.AK_CNTL2, ak_mode)
        imu.enable_fifo()
        for action in _SETUPS[setup]:
            if action[0] == "sleep":
                clock.sleep(action[1])
            else:
                bank, register, value = action
                imu.write_register(bank, register, divider if value == "divider" else value)
        emulator.chips[0x69].batched = batched
        rigs.append((emulator, clock, imu))
    for wait_s, action in looks:
        for emulator, clock, imu in rigs:
            clock.sleep(wait_s)
            if action == "run":
                emulator.run_chips()
            elif action == "read":
                count = emulator.read_i2c_block_data(0x69, reg.FIFO_COUNTH, 2)
                length = min(((count[0] & 0x1F) << 8) | count[1], reg.SMBUS_BLOCK_MAX)
                if length:
                    emulator.read_i2c_block_data(0x69, reg.FIFO_R_W, length)
            else:
                imu.reset_fifo()
        assert _chip_state(rigs[0][0], 0x69) == _chip_state(rigs[1][0], 0x69)
