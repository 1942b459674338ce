"""Read-only smoke checks of a rig's devices: `pytest --rig profiles/hydrojet-v1.toml`.

Skipped unless --rig names a profile. Nothing here opens a valve: the valve controller
is armed (as every session does), asked for its status and sent ALL_OFF on close. The
tracker and the IMUs are only read. A profile whose devices are "sim"/"pty" runs the same
checks against the emulators (`pytest --rig profiles/sim.toml tests/rig`), which is how
`make test` keeps these tests honest without hardware.
"""

from __future__ import annotations

import contextlib

import numpy as np
import pytest

from drivers.aurora.client import AuroraTracker
from drivers.imu import Icm20948
from drivers.valve.client import ValveController
from hydrojet_bench.bench.clock import ScaledClock
from hydrojet_bench.bench.simulated_rig import simulated_devices
from hydrojet_bench.config import SIM
from hydrojet_bench.profile import load_profile

pytestmark = pytest.mark.rig


@contextlib.asynccontextmanager
async def rig_devices(profile_spec: str):
    """(profile, settings, valves URL, tracker URL, I2C bus) of the rig under test."""
    profile = load_profile(profile_spec)
    settings = profile.config
    transports = settings.transports
    async with contextlib.AsyncExitStack() as stack:
        valves, tracker, bus = transports.valves, transports.tracker, None
        if transports.simulated:
            devices = await stack.enter_async_context(simulated_devices(profile, settings, ScaledClock()))
            valves, tracker, bus = devices.valves_url or valves, devices.tracker_url or tracker, devices.imu_bus
        if transports.imu_bus != SIM:
            import smbus2

            bus = stack.enter_context(smbus2.SMBus(transports.imu_bus))
        yield profile, settings, valves, tracker, bus


def test_valve_controller_answers_status_with_valves_closed(rig_profile, run_async):
    async def check():
        async with rig_devices(rig_profile) as (_, settings, valves_url, _, _):
            async with ValveController(valves_url, calibrations=settings.valve_calibrations()) as valves:
                status = await valves.status()
                assert status.armed and not status.faults
                assert status.duties_permille == (0, 0, 0), "valves open before any command"
                return status

    status = run_async(check, timeout_s=30.0)
    assert status.firmware_version >= (1, 0)


def test_tracker_sees_base_and_tip_and_counts_frames(rig_profile, run_async):
    async def check():
        async with rig_devices(rig_profile) as (_, settings, _, tracker_url, _):
            async with AuroraTracker(tracker_url, list(settings.tracker.tools)) as tracker:
                frames = [await tracker.read_frame() for _ in range(3)]
                return frames

    frames = run_async(check, timeout_s=30.0)
    for frame in frames:
        assert frame["base"].has_pose and frame["tip"].has_pose, frame
        # Base and tip sensors sit 5-15 cm apart on the HydroJet rig.
        distance_mm = np.linalg.norm(np.subtract(frame["tip"].position_mm, frame["base"].position_mm))
        assert 30.0 < distance_mm < 200.0, distance_mm


def test_both_imus_answer_and_measure_gravity(rig_profile, run_async):
    async def check():
        async with rig_devices(rig_profile) as (_, settings, _, _, bus):
            samples = []
            for address in (settings.imu.base_address, settings.imu.tip_address):
                chip = Icm20948(bus, address)
                chip.initialize()
                samples.append(chip.read_sample())
            return samples

    for sample in run_async(check, timeout_s=30.0):
        # At rest the accelerometer reads gravity alone: 9.81 m/s^2 within a few percent.
        assert abs(np.linalg.norm(sample.accel_m_s2) - 9.81) < 0.5, sample.accel_m_s2
        assert sample.mag_ut is not None and 10.0 < np.linalg.norm(sample.mag_ut) < 100.0, sample.mag_ut
