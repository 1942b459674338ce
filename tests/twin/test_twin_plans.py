"""Playing measurement plans on the twin: the paper's protocol in virtual time."""

from __future__ import annotations

import numpy as np
import pytest

from hydrojet_bench.geometry import matrix_from_quat, quat_from_matrix, quat_from_rotvec, rotation_angle_deg
from hydrojet_bench.models import CosseratModel
from hydrojet_bench.plans import Plan, PlanStep, paper_protocol, validation_sweeps
from hydrojet_bench.profile import profile_from_mapping
from hydrojet_bench.twin import DigitalTwin, SensorNoise, TwinConfig, TwinRecording


@pytest.fixture(scope="module")
def protocol_run():
    plan = paper_protocol()
    twin = DigitalTwin(TwinConfig(noise=SensorNoise.off(), seed=1))
    return plan, twin, twin.run_plan(plan)


def test_paper_protocol_recording_has_every_sample_labelled(protocol_run):
    plan, _, recording = protocol_run
    per_step = 200  # 5 s at 40 Hz
    assert len(recording) == 229 * per_step
    assert recording.time_s[0] == 0.0
    np.testing.assert_allclose(np.diff(recording.time_s), 1 / 40, rtol=1e-9)
    np.testing.assert_array_equal(recording.sweep, np.repeat(plan.sweeps, per_step))
    np.testing.assert_array_equal(recording.step, np.repeat(plan.step_indices, per_step))
    np.testing.assert_array_equal(recording.jet_forces_n, np.repeat(plan.jet_forces_n, per_step, axis=0))
    assert recording.has_positions and np.all(recording.flags == 0)
    assert not recording.time_s.flags.writeable


def test_settled_samples_are_the_true_equilibria(protocol_run):
    plan, twin, recording = protocol_run
    model = CosseratModel()
    base_rotation = matrix_from_quat(twin.config.base_orientation_in_tracker)
    last_of_step = np.arange(1, len(plan) + 1) * 200 - 1
    previous = None
    worst_deg, worst_m = 0.0, 0.0
    for index, row in enumerate(last_of_step):
        previous = model.solve(plan[index].jet_forces_n, twin.true_params, previous=previous)
        tip = quat_from_matrix(base_rotation @ previous.tip_rotation_in_base)
        worst_deg = max(worst_deg, float(rotation_angle_deg(recording.tip_orientation[row], tip)))
        worst_m = max(worst_m, float(np.linalg.norm(recording.tip_position_m[row]
                                                    - base_rotation @ previous.tip_position_in_base_m)))
    # 4.975 s after the command exp(-9.95) = 4.8e-5 of the move is left: under 180 deg
    # and 100 mm moves, < 9e-3 deg and 5e-3 mm.
    assert worst_deg < 9e-3 and worst_m < 5e-6
    # The plan bends the rod across Table II's bins, up to about 80 degrees.
    bends = [twin.equilibrium(t).bend_angle_deg for t in recording.time_s[last_of_step]]
    assert 70.0 < max(bends) < 90.0


def test_record_window_keeps_the_settled_end_of_each_step():
    twin = DigitalTwin(TwinConfig(seed=2))
    plan = validation_sweeps(steps_up=2, repetitions=1)
    recording = twin.run_plan(plan, sample_rate_hz=40.0, record_window_s=1.0)
    assert len(recording) == len(plan) * 40
    first_step = recording.time_s[recording.step == 0][:40]
    np.testing.assert_allclose(first_step, 4.0 + np.arange(40) / 40)


@pytest.mark.parametrize("settle_s, rate, count", [(0.1, 40.0, 4), (0.11, 40.0, 5), (5.0, 40.0, 200),
                                                   (1.0, 3.0, 3), (0.01, 40.0, 1)])
def test_samples_fill_the_step_at_the_sample_rate(settle_s, rate, count):
    twin = DigitalTwin(TwinConfig(noise=SensorNoise.off()))
    rows = twin.measure_step(PlanStep((0.01, 0.0, 0.0), 0, 0, settle_s), sample_rate_hz=rate)
    assert len(rows) == count
    assert rows.time_s[-1] < settle_s
    assert twin.plan_clock_s == pytest.approx(settle_s)


def test_consecutive_plans_continue_the_clock_and_the_motion():
    twin = DigitalTwin(TwinConfig(noise=SensorNoise.off()))
    plan = Plan((PlanStep((0.05, 0.0, 0.0), 0, 0, 2.0),))
    first = twin.run_plan(plan, sensors="truth")
    second = twin.run_plan(Plan((PlanStep((0.0, 0.05, 0.0), 1, 0, 2.0),)), sensors="truth")
    assert second.time_s[0] == pytest.approx(2.0)
    both = TwinRecording.concatenate([first, second])
    assert np.all(np.diff(both.time_s) > 0)
    # A direct command later than the plan clock moves the next plan's start.
    twin.command_jet_forces((0.0, 0.0, 0.0), 10.0)
    assert twin.plan_clock_s == 10.0


def test_imu_recordings_have_no_positions():
    twin = DigitalTwin(TwinConfig())
    recording = twin.run_plan(validation_sweeps(steps_up=1, repetitions=1, settle_s=0.5), sensors="imu")
    assert recording.base_position_m is None and recording.tip_position_m is None
    assert recording.tip_orientation.shape == (len(recording), 4)


@pytest.mark.parametrize("kwargs, message", [
    ({"sample_rate_hz": 0.0}, "sample_rate_hz"),
    ({"record_window_s": -1.0}, "record_window_s"),
    ({"sensors": "camera"}, "sensors must be one of"),
])
def test_bad_plan_options_are_named(kwargs, message):
    twin = DigitalTwin()
    with pytest.raises(ValueError, match=message):
        twin.run_plan(validation_sweeps(steps_up=1, repetitions=1), **kwargs)
    with pytest.raises(ValueError, match="plan must be a Plan"):
        twin.run_plan([PlanStep((0.0, 0.0, 0.0), 0, 0)])  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="no steps"):
        twin.run_plan(Plan(()))


def test_recordings_validate_shapes_and_position_pairs():
    n = 3
    good = dict(time_s=np.arange(n, dtype=float), jet_forces_n=np.zeros((n, 3)),
                base_orientation=np.tile([1.0, 0, 0, 0], (n, 1)), tip_orientation=np.tile([1.0, 0, 0, 0], (n, 1)),
                base_position_m=np.zeros((n, 3)), tip_position_m=np.zeros((n, 3)),
                sweep=np.zeros(n), step=np.zeros(n), flags=np.zeros(n))
    assert len(TwinRecording(**good)) == n
    with pytest.raises(ValueError, match=r"tip_orientation must have shape \(3, 4\)"):
        TwinRecording(**good | {"tip_orientation": np.zeros((n, 3))})
    with pytest.raises(ValueError, match="both be given or both None"):
        TwinRecording(**good | {"tip_position_m": None})
    without = TwinRecording(**good | {"tip_position_m": None, "base_position_m": None})
    with pytest.raises(ValueError, match="with and without positions"):
        TwinRecording.concatenate([TwinRecording(**good), without])


def test_recording_converts_to_a_dataset_that_recovers_the_base_frame_truth():
    profile = profile_from_mapping({
        "name": "twin-test", "gravity": {"in_tracker_m_s2": [0.0, -9.81, 0.0]},
        "base": {"orientation_in_tracker": quat_from_rotvec([0.9, 0.2, 0.0]).tolist(),
                 "position_in_tracker_m": [0.05, 0.0, 0.2]},
        "base_sensor": {"rotation_in_base": quat_from_rotvec([0.0, 0.0, 0.7]).tolist(),
                        "offset_in_base_m": [0.0, 0.01, 0.0]},
        "tip_sensor": {"rotation_in_tip": quat_from_rotvec([0.3, 0.0, 0.0]).tolist(),
                       "offset_in_tip_m": [0.0, 0.0, 0.014]}})
    twin = DigitalTwin(TwinConfig.from_profile(profile, noise=SensorNoise.off()))
    plan = Plan((PlanStep((0.06, 0.0, 0.0), -1, 0), PlanStep((0.0, 0.02, 0.07), 0, 0)))
    dataset = twin.run_plan(plan, record_window_s=0.5).to_dataset(profile, source="twin")
    assert len(dataset) == 40 and dataset.source == "twin" and dataset.has_positions
    np.testing.assert_array_equal(dataset.sweep, np.repeat([-1, 0], 20))
    for row in (19, 39):
        truth = twin.equilibrium(dataset.time_s[row])
        q = dataset.tip_orientation_in_base()[row]
        # Still settling by 4.8e-5 of the last move (< 90 deg, < 70 mm).
        assert rotation_angle_deg(q, quat_from_matrix(truth.tip_rotation_in_base)) < 5e-3
        np.testing.assert_allclose(dataset.tip_position_in_base_m()[row], truth.tip_position_in_base_m, atol=4e-6)
        # The solver leaves the rigid clamp's frame within ~2e-7 rad of the base frame.
        np.testing.assert_allclose(dataset.gravity_in_base_m_s2()[row], twin.true_params.gravity_in_base_m_s2,
                                   atol=1e-5)
