"""IMU against EM: alignment, the error measures and the online estimator fed by either
source, on synthetic data with known answers.

The synthetic rig is the sim profile: ideal EM sensors read a known tip path, and the
IMUs read the same bodies in their own earth frame (turned 40 degrees about the vertical
from the tracker's), plus whatever error a test puts on the tip IMU, as an earth-frame
rotation."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hydrojet_bench.analysis.sensors import (FRAME_RULE, TIME_RULE, DroppedSamples, align, compare_estimators,
                                            imu_profile, matched_steps, sensor_agreement, settled_holds, slerp)
from hydrojet_bench.model_choice import build_model
from hydrojet_bench.data.dataset import Dataset, SampleFlag
from hydrojet_bench.geometry import matrix_from_quat, quat_from_rotvec, quat_multiply, rotation_angle_deg
from hydrojet_bench.plans import calibration_plan, validation_sweeps
from hydrojet_bench.profile import load_profile
from hydrojet_bench.twin import DigitalTwin, TwinConfig

PROFILE = load_profile("sim")
RATE_HZ = 40.0
# The IMU filters' earth frame: z up like the tracker's, x towards magnetic north.
EARTH_FROM_TRACKER = quat_from_rotvec([0.0, 0.0, math.radians(40.0)])


def rotation_about(axis, angle_deg) -> np.ndarray:
    """Quaternions (n, 4) of rotations by angle_deg (n,) about a fixed axis."""
    angle = np.atleast_1d(np.radians(angle_deg))
    return quat_from_rotvec(np.asarray(axis, dtype=float)[None, :] * angle[:, None])


def bending_path(time_s: np.ndarray) -> np.ndarray:
    """A tip orientation in the base frame that keeps moving: bending about x and y."""
    return quat_multiply(rotation_about([1, 0, 0], 30.0 * np.sin(0.2 * time_s)),
                         rotation_about([0, 1, 0], 20.0 * np.sin(0.13 * time_s)))


def em_samples(time_s, tip_in_base, jet_forces_n=None, sweep=None, step=None, flags=None) -> Dataset:
    """What ideal EM sensors on the sim rig read for these tip orientations."""
    n = len(time_s)
    pose = np.tile(np.eye(4), (n, 1, 1))
    pose[:, :3, :3] = matrix_from_quat(tip_in_base)
    pose[:, :3, 3] = (0.0, 0.0, 0.07)
    poses = PROFILE.sensor_poses_in_tracker(pose)
    return Dataset(time_s=time_s, jet_forces_n=np.zeros((n, 3)) if jet_forces_n is None else jet_forces_n,
                   base_orientation=poses.base_orientation, tip_orientation=poses.tip_orientation,
                   base_position_m=poses.base_position_m, tip_position_m=poses.tip_position_m,
                   sweep=sweep, step=step, flags=flags, profile=PROFILE, source="ideal EM")


def imu_samples(em: Dataset, tip_error=None, base_error=None) -> Dataset:
    """The same bodies read by IMUs in their earth frame; *_error: (n, 4) earth-frame
    rotations applied on top (a heading offset, a drift)."""
    base = quat_multiply(EARTH_FROM_TRACKER, em.base_orientation)
    tip = quat_multiply(EARTH_FROM_TRACKER, em.tip_orientation)
    if base_error is not None:
        base = quat_multiply(base_error, base)
    if tip_error is not None:
        tip = quat_multiply(tip_error, tip)
    return Dataset(time_s=em.time_s, jet_forces_n=em.jet_forces_n, base_orientation=base, tip_orientation=tip,
                   sweep=em.sweep, step=em.step, profile=imu_profile(PROFILE), source="ideal IMU")


def session_times(seconds: float) -> np.ndarray:
    return np.arange(0.0, seconds, 1.0 / RATE_HZ)


# --- alignment -------------------------------------------------------------------------


def test_slerp_to_the_imu_stamps_is_exact_for_a_constant_rate_turn():
    em_time = session_times(5.0)
    rate_deg_s = 20.0
    em = em_samples(em_time, rotation_about([0.6, 0.8, 0.0], rate_deg_s * em_time))
    imu_time = em_time[:-1] + 0.5 / RATE_HZ  # half a period late: the worst case for the nearest sample
    imu = imu_samples(em_samples(imu_time, rotation_about([0.6, 0.8, 0.0], rate_deg_s * imu_time)))
    aligned = align(imu, em)
    assert len(aligned) == len(imu_time)
    # A constant-rate turn is a geodesic, which slerp follows exactly: only rounding is
    # left, which the arccos in rotation_angle_deg magnifies to ~sqrt(eps) rad (1e-6 deg).
    assert np.max(rotation_angle_deg(aligned.imu, aligned.em)) < 1e-5
    # The nearest EM sample would be off by the turn of half a period, 0.25 deg.
    nearest = em.tip_orientation_in_base()[:-1]
    assert np.allclose(rotation_angle_deg(aligned.imu, nearest), rate_deg_s * 0.5 / RATE_HZ, atol=1e-5)


def test_alignment_bridges_no_gap_and_no_end():
    em_time = session_times(10.0)
    keep = (em_time < 4.0) | (em_time >= 4.05)  # one lost frame: a gap of two periods
    keep &= (em_time < 6.0) | (em_time >= 7.0)
    flags = np.where(np.abs(em_time - 8.0) < 1e-9, int(SampleFlag.TIP_MISSING), 0)
    em = em_samples(em_time, bending_path(em_time), flags=flags).select(keep)
    imu_time = np.arange(-1.0, 11.0, 1.0 / RATE_HZ) + 0.01
    imu = imu_samples(em_samples(imu_time, bending_path(imu_time)))
    aligned = align(imu, em)
    t = aligned.time_s
    assert t.min() >= em.time_s[0] and t.max() <= em.time_s[-1]
    for start, stop in ((3.975, 4.05), (5.975, 7.0), (7.975, 8.025)):
        assert not np.any((t > start) & (t < stop)), f"interpolated across the gap {start}-{stop} s"
    # Every other stamp inside the record is kept: 0.01 s after each EM sample, none dropped.
    expected = np.sum((imu_time >= 0) & (imu_time <= em.time_s[-1]) & ~((imu_time > 3.975) & (imu_time < 4.05))
                      & ~((imu_time > 5.975) & (imu_time < 7.0)) & ~((imu_time > 7.975) & (imu_time < 8.025)))
    assert len(aligned) == expected
    assert aligned.max_gap_s == pytest.approx(1.5 / RATE_HZ)
    assert aligned.dropped == DroppedSamples(int(np.sum(imu_time < 0)), int(np.sum(imu_time > em.time_s[-1])),
                                             len(imu_time) - expected - int(np.sum(imu_time < 0))
                                             - int(np.sum(imu_time > em.time_s[-1])), 3)
    assert np.max(rotation_angle_deg(aligned.imu, aligned.em)) < 0.05  # slow path, 25 ms steps


def test_jittered_stamps_are_no_gap_when_no_tracker_frame_was_lost():
    """The host stamps each EM frame when it receives it: on a simulated rig at x25 the
    stamps of a 25 ms period came 1.7-60 ms apart with no frame lost, and a rule of 1.5
    periods on the stamps dropped the IMU samples in every long interval as lying in a
    gap. The tracker's frame numbers say what was lost: here frame 160 only."""
    rng = np.random.default_rng(3)
    frames = np.arange(400)
    em_time = frames / RATE_HZ + rng.uniform(0.0, 0.024, len(frames))  # received up to 24 ms late
    keep = frames != 160
    em = em_samples(em_time, bending_path(em_time)).select(keep)
    imu_time = np.arange(-0.5, 10.5, 0.1) + 0.003
    imu = imu_samples(em_samples(imu_time, bending_path(imu_time)))
    on_stamps = align(imu, em)
    assert on_stamps.gap_rule == TIME_RULE and on_stamps.dropped.em_gaps > 10  # jitter taken for gaps
    aligned = align(imu, em, em_frames=frames[keep])
    assert aligned.gap_rule == FRAME_RULE
    lost = (imu_time > em_time[159]) & (imu_time < em_time[161])
    before, after = imu_time < em.time_s[0], imu_time > em.time_s[-1]
    assert aligned.dropped == DroppedSamples(int(before.sum()), int(after.sum()), int(lost.sum()), 1)
    assert len(aligned) == len(imu_time) - aligned.dropped.total
    assert not np.any((aligned.time_s > em_time[159]) & (aligned.time_s < em_time[161]))
    assert aligned.max_gap_s == pytest.approx(np.diff(em.time_s)[np.diff(frames[keep]) == 1].max())
    # An EM pose the tracker could not measure is as lost as a frame: a gap.
    flags = np.where(frames[keep] == 300, int(SampleFlag.TIP_MISSING), 0)
    flagged = align(imu, em_samples(em.time_s, bending_path(em.time_s), flags=flags), em_frames=frames[keep])
    assert flagged.dropped.em_gaps == 2
    # --max-gap is a limit on the stamps, whatever the frame numbers say.
    assert align(imu, em, 0.0375, em_frames=frames[keep]).gap_rule == TIME_RULE


def test_stamps_equal_to_em_stamps_take_those_samples():
    em_time = session_times(2.0)
    em = em_samples(em_time, bending_path(em_time))
    aligned = align(imu_samples(em), em)
    assert len(aligned) == len(em_time)  # the last stamp too
    np.testing.assert_allclose(rotation_angle_deg(aligned.imu, aligned.em), 0.0, atol=1e-5)  # arccos rounding


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3).filter(lambda v: np.linalg.norm(v) > 1e-3),
       st.floats(0.0, 170.0), st.floats(0.0, 1.0))
def test_slerp_moves_along_the_shortest_arc(axis, angle_deg, fraction):
    start = quat_from_rotvec([0.3, -0.2, 0.9])
    turn = rotation_about(np.array(axis) / np.linalg.norm(axis), angle_deg)[0]
    end = quat_multiply(start, turn)
    middle = slerp(start[None], -end[None], np.array([fraction]))[0]  # -end: the same rotation
    # Rounding, magnified by the arccos near zero angles to ~1e-6 deg.
    assert rotation_angle_deg(start, middle) == pytest.approx(fraction * angle_deg, abs=1e-5)
    assert rotation_angle_deg(middle, end) == pytest.approx((1 - fraction) * angle_deg, abs=1e-5)


# --- the error measures ------------------------------------------------------------------


def test_a_constant_tip_heading_offset_is_that_rms_all_in_heading():
    time = session_times(30.0)
    em = em_samples(time, bending_path(time))
    offset_deg = 2.0
    imu = imu_samples(em, tip_error=rotation_about([0, 0, 1], np.full(len(time), offset_deg)))
    agreement = sensor_agreement(imu, em)
    assert agreement.overall.rms_deg == pytest.approx(offset_deg, abs=1e-9)
    assert agreement.overall.max_deg == pytest.approx(offset_deg, abs=1e-9)
    axes = agreement.axes
    assert axes.heading_mean_deg == pytest.approx(offset_deg, abs=1e-9)
    assert axes.tilt_rms_deg < 1e-9
    # Up is -z in the base frame of the sim rig (the rod hangs down its z axis).
    np.testing.assert_allclose(axes.mean_deg, (0.0, 0.0, -offset_deg), atol=1e-9)
    assert agreement.trend_deg_per_min == pytest.approx(0.0, abs=1e-9)
    (hold,) = agreement.holds  # one command all along
    assert hold.bias_deg == pytest.approx(offset_deg, abs=1e-6)


def test_a_heading_offset_common_to_both_imus_cancels():
    time = session_times(10.0)
    em = em_samples(time, bending_path(time))
    common = rotation_about([0, 0, 1], np.full(len(time), 7.0))
    agreement = sensor_agreement(imu_samples(em, tip_error=common, base_error=common), em)
    assert agreement.overall.max_deg < 1e-5  # arccos rounding


def test_a_tilt_offset_is_tilt():
    time = session_times(10.0)
    em = em_samples(time, bending_path(time))
    agreement = sensor_agreement(imu_samples(em, tip_error=rotation_about([1, 0, 0], np.full(len(time), 1.5))), em)
    assert agreement.axes.tilt_rms_deg == pytest.approx(1.5, abs=1e-9)
    assert agreement.axes.heading_rms_deg < 1e-9


def held_plan_samples(rate_deg_per_min: float) -> tuple[Dataset, Dataset]:
    """Two 20 s static poses, then a 10 s ramp of 0.5 s steps, with the tip IMU's
    heading drifting linearly from zero at ``rate_deg_per_min``."""
    time = session_times(50.0)
    pose = np.minimum(time // 20.0, 2.0)
    step = np.where(time < 40.0, pose, 2.0 + (time - 40.0) // 0.5).astype(int)
    sweep = np.where(time < 40.0, -1, 0)
    forces = np.zeros((len(time), 3))
    forces[:, 0] = 0.01 * (step + 1)
    tip_in_base = quat_multiply(rotation_about([1, 0, 0], 10.0 * step), bending_path(0.01 * time))
    em = em_samples(time, tip_in_base, forces, sweep, step)
    drift = rotation_about([0, 0, 1], rate_deg_per_min * time / 60.0)
    return em, imu_samples(em, tip_error=drift)


def test_a_linear_drift_is_that_trend_within_holds_across_them_and_over_the_session():
    em, imu = held_plan_samples(rate_deg_per_min=0.6)
    agreement = sensor_agreement(imu, em, min_hold_s=10.0, settle_s=2.5)
    # The angle is exactly 0.6 deg/min x t: every least-squares slope recovers it.
    assert agreement.trend_deg_per_min == pytest.approx(0.6, rel=1e-9)
    assert agreement.heading_trend_deg_per_min == pytest.approx(0.6, rel=1e-9)
    assert agreement.within_holds_deg_per_min == pytest.approx(0.6, rel=1e-9)
    assert agreement.across_holds_deg_per_min == pytest.approx(0.6, rel=1e-9)
    assert [hold.trend_deg_per_min for hold in agreement.holds] == pytest.approx([0.6, 0.6], rel=1e-9)
    first, second = agreement.holds
    # Settled parts: 2.5 s after each command to the end of the hold.
    assert (first.start_s, second.start_s) == pytest.approx((2.5, 22.5))
    assert first.end_s == pytest.approx(20.0 - 1 / RATE_HZ)
    assert first.angle.mean_deg == pytest.approx(0.6 * (2.5 + 20.0 - 1 / RATE_HZ) / 2 / 60, rel=1e-9)
    # Rotations about one axis average to about the mean angle (to the cube of the spread).
    assert first.bias_deg == pytest.approx(first.angle.mean_deg, rel=1e-4)
    assert agreement.held.count + agreement.moving.count == agreement.overall.count


def test_holds_are_runs_of_one_command_long_enough():
    em, imu = held_plan_samples(rate_deg_per_min=0.0)
    aligned = align(imu, em)
    assert [len(rows) for rows in settled_holds(aligned, min_hold_s=10.0, settle_s=2.5)] == [700, 700]
    assert settled_holds(aligned, min_hold_s=25.0) == []
    # The ramp's 0.5 s steps count as holds only when the bar is that low.
    assert len(settled_holds(aligned, min_hold_s=0.4, settle_s=0.0)) == 2 + 20


def test_no_overlap_is_an_error():
    time = session_times(2.0)
    em = em_samples(time, bending_path(time))
    later = em_samples(time + 10.0, bending_path(time))
    with pytest.raises(ValueError, match="no IMU sample"):
        sensor_agreement(imu_samples(later), em)


# --- online estimation fed by either source -------------------------------------------


def test_steps_are_paired_by_label_and_only_when_valid_in_both():
    time = session_times(6.0)
    step = (time // 1.0).astype(int)
    samples = em_samples(time, bending_path(time), step=step, sweep=np.zeros(len(time), int))
    flags = np.zeros(6, int)
    flags[2] = int(SampleFlag.BASE_MISSING)
    em = replace(samples.quasistatic_steps(), flags=flags)
    imu = imu_samples(samples).quasistatic_steps().select(np.array([0, 1, 2, 3, 5]))  # step 4 not settled
    em_rows, imu_rows = matched_steps(em, imu)
    assert em_rows.step.tolist() == imu_rows.step.tolist() == [0, 1, 3, 5]
    assert imu_rows.profile.gravity_in_tracker_m_s2 == (0.0, 0.0, -9.81)


def test_online_estimation_fed_by_imus_in_another_frame_equals_em_fed():
    profile = PROFILE
    twin = DigitalTwin(TwinConfig.from_profile(profile, seed=3))
    plan = calibration_plan(3, settle_s=1.0, seed=1) + validation_sweeps(steps_up=2, repetitions=1, settle_s=1.0)
    em = twin.run_plan(plan, record_window_s=0.5).to_dataset(profile)
    imu = imu_samples(em)  # the same bodies, read in the IMU earth frame with gravity from it
    model, _ = build_model("cosserat", [])
    comparison = compare_estimators(model, profile.model_parameters(), em.quasistatic_steps(),
                                    imu.quasistatic_steps())
    assert len(comparison.steps) == 3 * 5  # the sweeps' steps only
    em_fed, imu_fed = (comparison.results[k].orientation_error_deg for k in ("online_em", "online_imu"))
    # Same measurements in another earth frame: only rounding differs.
    np.testing.assert_allclose(imu_fed, em_fed, atol=1e-5)
    ref = comparison.results["ref"].overall.orientation_rmse_deg
    assert comparison.gain("online_imu") == pytest.approx(1 - comparison.results["online_imu"].overall
                                                          .orientation_rmse_deg / ref)
    assert comparison.gain("online_em") > 0.0  # the estimator corrects towards the measurement
