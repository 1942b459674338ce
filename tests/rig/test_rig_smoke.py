"""Read-only smoke checks of a rig's devices: `pytest tests/rig --rig profiles/hydrojet-v1.toml`.

Skipped unless --rig names a profile. Nothing here opens a valve: the rig is opened as
every session opens it (`bench.rig.open_rig`: valve controller armed, ALL_OFF on close),
the valve controller is asked for its status, the tracker and the IMUs are only read. A
profile whose devices are "sim"/"pty" runs the same checks against the emulators
(`pytest --rig profiles/sim.toml tests/rig`), which is how `make test` keeps these tests
honest without hardware.
"""

from __future__ import annotations

import contextlib

import numpy as np
import pytest

from hydrojet_bench.bench.clock import ScaledClock
from hydrojet_bench.bench.rig import open_rig
from hydrojet_bench.errors import UserError
from hydrojet_bench.profile import load_profile

pytestmark = pytest.mark.rig


@contextlib.asynccontextmanager
async def rig_under_test(profile_spec: str):
    # A profile that does not load or a device that is not there is the tester's set-up,
    # not a failed check: one line, as the bench would say it, not a traceback.
    problem = None
    try:
        profile = load_profile(profile_spec)
        # At the profile's time scale, as a session opens it: 1 on hardware; the simulated
        # rig's 25 turns its 20 s of IMU gyro-bias sampling (100 samples a chip at 10 Hz)
        # into 0.8 s.
        opened = open_rig(profile, profile.config, ScaledClock(profile.config.session.time_scale))
        rig = await opened.__aenter__()
    except UserError as error:
        problem = str(error)
    if problem is not None:
        pytest.fail(f"--rig {profile_spec}: cannot open the rig: {problem}", pytrace=False)
    async with contextlib.AsyncExitStack() as stack:
        stack.push_async_exit(opened)
        yield rig


def test_valve_controller_answers_status_with_valves_closed(rig_profile, run_async):
    async def check():
        async with rig_under_test(rig_profile) as rig:
            status = await rig.valves.status()
            assert status.armed and not status.faults
            assert status.duties_permille == (0, 0, 0), "valves open before any command"
            return status

    status = run_async(check, timeout_s=30.0)
    assert status.firmware_version >= (1, 0)


def test_tracker_sees_base_and_tip_and_counts_frames(rig_profile, run_async):
    async def check():
        async with rig_under_test(rig_profile) as rig:
            return [await rig.tracker.read_frame() for _ in range(3)]

    frames = run_async(check, timeout_s=30.0)
    for frame in frames:
        assert frame["base"].has_pose and frame["tip"].has_pose, frame
        # Base and tip sensors sit 5-15 cm apart on the HydroJet rig.
        distance_mm = np.linalg.norm(np.subtract(frame["tip"].position_mm, frame["base"].position_mm))
        assert 30.0 < distance_mm < 200.0, distance_mm


def test_both_imus_answer_and_measure_gravity(rig_profile, run_async):
    async def check():
        async with rig_under_test(rig_profile) as rig:
            assert rig.imus is not None, "the profile names no IMU bus"
            return [await chip.read_sample() for chip in (rig.imus.base, rig.imus.tip)]

    for sample in run_async(check, timeout_s=30.0):
        # At rest the accelerometer reads gravity alone: 9.81 m/s^2 within a few percent.
        assert abs(np.linalg.norm(sample.accel_m_s2) - 9.81) < 0.5, sample.accel_m_s2
        assert sample.mag_ut is not None and 10.0 < np.linalg.norm(sample.mag_ut) < 100.0, sample.mag_ut
