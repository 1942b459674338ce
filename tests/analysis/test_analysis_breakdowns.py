"""Where-the-model-fails breakdowns, on synthetic steps with a known answer.

The steps are built in the base frame (a bend towards an azimuth) and turned into sensor
readings with the sim profile, so the profile's mountings are exercised; predictions
are the measurements moved by a chosen residual rotation vector (tip frame) and position
offset, so every breakdown's right answer is known.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hydrojet_bench.analysis.breakdowns import (NOISE_GAP_PER_FLOOR, break_down, direction_labels,
                                                disturbance_by_sweep, driving_jet_labels, drift, hysteresis_gaps,
                                                load_phases, loading_split, noise_only_gap, orientation_residuals_deg,
                                                per_step, worst_poses)
from hydrojet_bench.analysis.compare import compare
from hydrojet_bench.estimation.path import Predictions
from hydrojet_bench.data.dataset import Dataset
from hydrojet_bench.geometry import quat_from_rotvec, quat_multiply, se3, so3_exp
from hydrojet_bench.plans import validation_sweeps
from hydrojet_bench.profile import load_profile

PROFILE = load_profile("sim")
ROD_M = 0.07
# Residuals pass through quaternion products and the profile's mountings in float64:
# agreement to 1e-9 deg is far below anything physical yet above round-off.
ROUND_OFF_DEG = 1e-9


def make_steps(bend_deg, azimuth_deg, *, forces=None, sweep=None, step=None, time_s=None,
               positions=True) -> Dataset:
    """Steps whose tip (base frame) bends ``bend_deg`` towards ``azimuth_deg``."""
    bend, azimuth = np.radians(bend_deg), np.radians(azimuth_deg)
    count = len(bend)
    axis = np.column_stack([-np.sin(azimuth), np.cos(azimuth), np.zeros(count)])  # z x (bend direction)
    rotation = so3_exp(axis * bend[:, None])
    poses = np.array([se3(r, ROD_M * r[:, 2]) for r in rotation])
    readings = PROFILE.sensor_poses_in_tracker(poses)
    return Dataset(
        time_s=np.arange(count) * 5.0 if time_s is None else time_s,
        jet_forces_n=np.zeros((count, 3)) if forces is None else forces,
        base_orientation=readings.base_orientation, tip_orientation=readings.tip_orientation,
        base_position_m=readings.base_position_m if positions else None,
        tip_position_m=readings.tip_position_m if positions else None,
        sweep=np.zeros(count, dtype=int) if sweep is None else sweep,
        step=np.arange(count) if step is None else step, profile=PROFILE, source="synthetic")


def predictions_with(steps: Dataset, residual_deg, offset_mm=None, moment_nm=None) -> Predictions:
    """Predictions such that rotvec(R_pred^T R_meas) = residual_deg and p_pred - p_meas = offset_mm."""
    count = len(steps)
    residual = np.broadcast_to(np.asarray(residual_deg, dtype=float), (count, 3))
    measured = steps.tip_orientation_in_base()
    predicted = quat_multiply(measured, quat_from_rotvec(-np.radians(residual)))
    positions = steps.tip_position_in_base_m()
    positions = np.zeros((count, 3)) if positions is None else positions
    offset = np.zeros((count, 3)) if offset_mm is None else np.broadcast_to(offset_mm, (count, 3))
    moment = np.zeros((count, 3)) if moment_nm is None else np.asarray(moment_nm, dtype=float)
    return Predictions(predicted, positions + offset / 1e3, np.zeros(count), moment)


def sweep_steps(steps_up: int = 4) -> Dataset:
    """The paper's three single-jet sweeps (0 -> max -> 0), each jet bending towards its own azimuth."""
    plan = validation_sweeps(0.1, steps_up=steps_up, repetitions=1)
    forces = plan.jet_forces_n
    jet = np.argmax(forces.sum(axis=0) * (plan.sweeps[:, None] == np.arange(3)), axis=1)
    # With the ring at 0, jets 1, 2, 3 push towards 30, 270 and 150 deg; 0.1 N bends ~80 deg.
    azimuth = np.array([30.0, 270.0, 150.0])[jet]
    return make_steps(forces.max(axis=1) * 800.0 + 1.0, azimuth, forces=forces, sweep=plan.sweeps,
                      step=plan.step_indices)


def test_residual_vectors_are_recovered_through_the_profile_mountings():
    steps = make_steps(np.array([0.0, 30.0, 80.0]), np.array([0.0, 100.0, 250.0]))
    residual = np.array([[1.0, 0.0, 0.0], [0.0, -2.0, 0.5], [3.0, 4.0, -1.0]])
    comparison = compare(predictions_with(steps, residual, offset_mm=[0.0, 2.0, 0.0]), steps)
    np.testing.assert_allclose(orientation_residuals_deg(comparison.predictions, steps), residual,
                               atol=ROUND_OFF_DEG)
    np.testing.assert_allclose(comparison.orientation_error_deg, np.linalg.norm(residual, axis=1), atol=1e-6)
    np.testing.assert_allclose(comparison.position_error_mm, 2.0, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-100.0, 100.0), min_size=3, max_size=3),
       st.floats(0.0, 120.0), st.floats(0.0, 360.0))
def test_any_residual_is_recovered_as_a_tip_frame_rotation_vector(residual, bend, azimuth):
    steps = make_steps(np.array([bend]), np.array([azimuth]))
    recovered = orientation_residuals_deg(predictions_with(steps, residual), steps)
    # Rotation vectors up to 173 deg: atan2-based logs stay accurate to round-off there.
    np.testing.assert_allclose(recovered[0], residual, atol=1e-7)


def test_load_phases_follow_the_ramp_within_each_sweep():
    steps = sweep_steps(steps_up=4)
    phases = load_phases(steps)
    one_sweep = ["loading"] * 5 + ["unloading"] * 4  # the peak is reached while loading
    assert phases.tolist() == one_sweep * 3
    flat = make_steps(np.zeros(3), np.zeros(3))
    assert load_phases(flat).tolist() == ["hold"] * 3


def test_error_only_on_unloading_shows_in_the_split_and_the_gap():
    steps = sweep_steps()
    unloading = load_phases(steps) == "unloading"
    residual = np.where(unloading[:, None], [3.0, 0.0, 0.0], 0.0)
    split = loading_split(compare(predictions_with(steps, residual), steps), steps)
    assert split.loading.orientation_rmse_deg == pytest.approx(0.0, abs=1e-6)
    assert split.unloading.orientation_rmse_deg == pytest.approx(3.0)
    assert split.matched_pairs == 12  # four unloading steps per sweep, each at a loading step's force
    assert split.hysteresis_gap_deg == pytest.approx(3.0)


def test_hysteresis_gap_sees_a_model_midway_between_the_branches():
    """Equal error magnitudes on both branches, opposite directions: RMS cannot tell the
    branches apart, the gap between error vectors does."""
    steps = sweep_steps()
    sign = np.where(load_phases(steps) == "unloading", -1.0, 1.0)[:, None]
    predictions = predictions_with(steps, sign * [0.0, 1.5, 0.0], sign * [0.5, 0.0, 0.0])
    split = loading_split(compare(predictions, steps), steps)
    assert split.loading.orientation_rmse_deg == pytest.approx(split.unloading.orientation_rmse_deg)
    assert split.hysteresis_gap_deg == pytest.approx(3.0)
    assert split.hysteresis_gap_mm == pytest.approx(1.0)
    # The gaps alone, as a diagnosis asks for them per candidate: the split's own figures.
    assert hysteresis_gaps(predictions, steps) == (split.hysteresis_gap_deg, split.hysteresis_gap_mm)
    flat = make_steps(np.zeros(3), np.zeros(3))
    assert hysteresis_gaps(predictions_with(flat, [1.0, 0.0, 0.0]), flat) == (None, None)


def test_error_in_one_bending_direction_shows_in_its_sector_and_region():
    azimuth = np.tile(np.arange(30.0, 360.0, 60.0), 2)
    bend = np.concatenate([np.full(6, 30.0), np.full(6, 60.0)])
    steps = make_steps(np.append(bend, 1.0), np.append(azimuth, 90.0))
    in_sector = np.append((azimuth > 60.0) & (azimuth < 120.0), False)
    residual = np.where(in_sector[:, None], [0.0, 0.0, 2.0], 0.0)
    parts = break_down(compare(predictions_with(steps, residual), steps), steps)
    assert list(parts.by_direction) == ["0-60", "60-120", "120-180", "180-240", "240-300", "300-360", "straight"]
    assert parts.by_direction["60-120"].orientation_rmse_deg == pytest.approx(2.0)
    assert parts.by_direction["60-120"].count == 2
    others = [s.orientation_rmse_deg for key, s in parts.by_direction.items() if key != "60-120"]
    assert max(others) == pytest.approx(0.0, abs=1e-6)
    assert parts.by_direction["straight"].count == 1  # 1 deg of bend: its azimuth is noise
    assert list(parts.by_region) == ["10", "50", "75"]
    assert parts.by_region["50"]["60-120"].orientation_rmse_deg == pytest.approx(2.0)
    assert parts.by_region["75"]["60-120"].orientation_rmse_deg == pytest.approx(2.0)
    assert parts.by_region["50"]["0-60"].orientation_rmse_deg == pytest.approx(0.0, abs=1e-6)


def test_sectors_split_at_their_edges():
    steps = make_steps(np.full(4, 20.0), np.array([59.0, 61.0, 359.0, 1.0]))
    assert direction_labels(steps).tolist() == ["0-60", "60-120", "300-360", "0-60"]


def test_linear_drift_is_recovered_as_the_trend():
    time_s = np.arange(40) * 30.0
    errors = 1.0 + 0.5 * time_s / 60.0  # 0.5 deg per minute
    result = drift(errors, 2.0 * errors, time_s, blocks=4)
    assert result.trend_deg_per_min == pytest.approx(0.5)
    assert result.trend_mm_per_min == pytest.approx(1.0)
    rms = [block.summary.orientation_rmse_deg for block in result.blocks]
    assert len(rms) == 4 and rms == sorted(rms) and rms[0] < rms[-1]
    assert (result.blocks[0].start_s, result.blocks[-1].end_s) == (0.0, time_s[-1])
    assert sum(block.summary.count for block in result.blocks) == 40
    assert drift(errors[:1], None, time_s[:1]).trend_deg_per_min is None


@pytest.mark.parametrize("clock_s", [0.0, 1.7e9, -3.0e9])
def test_the_trend_is_the_same_on_any_clock_and_absent_under_a_second(clock_s):
    # A Unix clock shifts the times by 1e9 s; steps 1e-300 s apart made the fit fail.
    time_s = clock_s + np.arange(40) * 30.0
    errors = 1.0 + 0.5 * np.arange(40) * 30.0 / 60.0
    assert drift(errors, None, time_s).trend_deg_per_min == pytest.approx(0.5, rel=1e-6)
    assert drift(errors, errors, np.arange(40) * 1e-300).trend_deg_per_min is None
    assert drift(errors, errors, np.arange(40) * (0.99 / 39)).trend_mm_per_min is None


def test_worst_poses_are_ordered_worst_first_with_ties_in_time_order():
    errors = np.array([1.0, 5.0, 3.0, 5.0, 0.5, 2.0, 4.0, 0.1, 0.2, 0.3, 0.4, 6.0])
    steps = make_steps(np.full(12, 20.0), np.zeros(12), forces=np.tile([0.01, 0.0, 0.0], (12, 1)))
    comparison = compare(predictions_with(steps, errors[:, None] * [1.0, 0.0, 0.0]), steps)
    worst = worst_poses(comparison, steps, count=10)
    assert [pose.index for pose in worst] == [11, 1, 3, 6, 2, 5, 0, 4, 10, 9]
    assert worst[0].orientation_error_deg == pytest.approx(6.0)
    assert worst[0].bend_deg == pytest.approx(20.0)
    assert worst[0].jet_forces_n == (0.01, 0.0, 0.0)
    assert worst[0].position_error_mm == pytest.approx(0.0, abs=1e-9)


def test_driving_jet_covers_a_sweep_s_zero_ends_and_single_steps():
    sweeps = sweep_steps()
    labels = driving_jet_labels(sweeps)
    assert labels.tolist() == ["jet 1"] * 9 + ["jet 2"] * 9 + ["jet 3"] * 9
    poses = make_steps(np.full(3, 10.0), np.zeros(3), forces=[[0.0, 0.0, 0.02], [0.0, 0.0, 0.0], [0.01, 0.02, 0]],
                       sweep=np.full(3, -1))
    assert driving_jet_labels(poses).tolist() == ["jet 3", "none", "jet 2"]


def test_disturbance_by_sweep_and_json_ready_breakdowns():
    steps = sweep_steps()
    moment = np.zeros((len(steps), 3))
    moment[steps.sweep == 1, 0] = 3e-4
    comparison = compare(predictions_with(steps, [0.0, 1.0, 0.0], moment_nm=moment), steps)
    series = disturbance_by_sweep(comparison.predictions, steps)
    assert list(series) == [0, 1, 2]
    assert series[1]["mean_norm_nm"] == pytest.approx(3e-4) and series[0]["peak_norm_nm"] == 0.0
    assert series[1]["step"] == list(range(9))
    document = json.loads(json.dumps(break_down(comparison, steps).as_dict()))
    assert set(document) == {"by_jet", "by_direction", "by_region", "loading_unloading", "over_time",
                             "worst_poses"}
    assert set(document["by_jet"]) == {"jet 1", "jet 2", "jet 3"}
    assert set(document["loading_unloading"]) == {"loading", "unloading", "matched_pairs", "hysteresis_gap_deg",
                                                  "hysteresis_gap_mm"}
    assert set(document["over_time"]) == {"blocks", "trend_deg_per_min", "trend_mm_per_min"}
    assert len(document["worst_poses"]) == 10
    assert set(document["worst_poses"][0]) == {"index", "sweep", "step", "time_s", "jet_forces_n", "bend_deg",
                                               "azimuth_deg", "orientation_error_deg", "position_error_mm"}
    series = json.loads(json.dumps(per_step(comparison, steps)))
    assert len(series["orientation_residual_deg"]) == len(steps)
    assert series["orientation_residual_deg"][0] == pytest.approx([0.0, 1.0, 0.0])


def test_without_positions_the_position_figures_are_none():
    steps = sweep_steps()
    no_positions = make_steps(np.full(len(steps), 20.0), np.zeros(len(steps)), forces=steps.jet_forces_n,
                              sweep=steps.sweep, step=steps.step, positions=False)
    comparison = compare(predictions_with(no_positions, [0.5, 0.0, 0.0]), no_positions)
    parts = break_down(comparison, no_positions)
    assert parts.loading.hysteresis_gap_mm is None and parts.drift.trend_mm_per_min is None
    assert parts.worst[0].position_error_mm is None
    assert math.isclose(parts.by_jet["jet 2"].orientation_rmse_deg, 0.5)
    assert per_step(comparison, no_positions)["position_residual_mm"] is None


def test_a_gap_of_pure_noise_is_judged_noise_and_a_real_gap_is_not():
    """Pairs of isotropic noise vectors of RMS norm ``floor`` leave a mean gap of
    NOISE_GAP_PER_FLOOR x floor; the judgement allows for the mean over the pairs."""
    rng = np.random.default_rng(5)
    floor, pairs = 0.15, 60
    for trial in range(20):
        noise = rng.normal(scale=floor / math.sqrt(3.0), size=(2, pairs, 3))
        gap = float(np.mean(np.linalg.norm(noise[0] - noise[1], axis=1)))
        assert not noise_only_gap(gap, pairs, floor).beyond_noise, trial
    verdict = noise_only_gap(gap, pairs, floor)
    assert verdict.noise_only_deg == pytest.approx(NOISE_GAP_PER_FLOOR * floor)
    assert verdict.noise_only_deg < verdict.limit_deg < 1.2 * verdict.noise_only_deg
    # A clamp with play moves the unloading branch by 0.2 deg: no longer noise.
    shifted = noise[0] + np.array([0.2, 0.0, 0.0])
    assert noise_only_gap(float(np.mean(np.linalg.norm(shifted - noise[1], axis=1))), pairs, floor).beyond_noise
