"""Dataset: validation, selection, frames through the rig profile, quasistatic averaging."""

from __future__ import annotations

import numpy as np
import pytest

from hydrojet_bench.data import Dataset, SampleFlag, average_quaternions, steps_from_runs
from hydrojet_bench.geometry import (matrix_from_quat, quat_from_rotvec, quat_multiply, rotation_angle_deg,
                                     rotvec_from_quat, se3)
from hydrojet_bench.profile import profile_from_mapping

PROFILE = profile_from_mapping({"name": "test", "gravity": {"in_tracker_m_s2": [0.0, 0.0, -9.81]}})
IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def simple(n: int = 6, **changes: object) -> Dataset:
    fields: dict[str, object] = dict(
        time_s=np.arange(n) * 0.1, jet_forces_n=np.zeros((n, 3)),
        base_orientation=np.tile(IDENTITY, (n, 1)), tip_orientation=np.tile(IDENTITY, (n, 1)),
        profile=PROFILE,
    )
    fields.update(changes)
    return Dataset(**fields)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("changes", "expected"),
    [
        ({"jet_forces_n": np.zeros((6, 2))}, r"jet_forces_n must have shape \('N', 3\)"),
        ({"jet_forces_n": np.zeros((5, 3))}, "jet_forces_n has 5 rows, time_s has 6"),
        ({"time_s": [0, 0.1, 0.2, 0.15, 0.3, 0.4]}, r"time_s row 3: time goes backwards"),
        ({"time_s": [0, 0.1, np.nan, 0.3, 0.4, 0.5]}, "time_s row 2 is not finite"),
        ({"tip_orientation": np.vstack([np.tile(IDENTITY, (4, 1)), [[1, 0, 0.1, 0]], [IDENTITY]])},
         "tip_orientation row 4 is not a unit quaternion"),
        ({"base_position_m": np.zeros((6, 2))}, "base_position_m must have shape"),
        ({"tip_position_m": np.vstack([np.zeros((5, 3)), [[0, np.inf, 0]]])}, "tip_position_m row 5 is not finite"),
        ({"tip_position_m": np.vstack([np.zeros((5, 3)), [[0, 1e200, 0]]])},
         "tip_position_m row 5 holds 1e[+]200 m, past the plausible 10 m in magnitude"),
        ({"jet_forces_n": np.vstack([np.zeros((5, 3)), [[1e308, 0, 0]]])}, "jet_forces_n row 5 holds 1e[+]308"),
        ({"time_s": [0, 0.1, 0.2, 0.3, 0.4, 2e10]}, "time_s row 5 holds 2e[+]10 s, past the plausible 1e[+]10 s"),
        ({"sweep": [-1, -1, -2, 0, 0, 0]}, "sweep row 2 is -2"),
        ({"step": [0, 0, 1.5, 2, 2, 2]}, "step row 2 is not an integer"),
        ({"flags": [0, 0, 0, 64, 0, 0]}, "flags row 3 has unknown bits"),
        ({"profile": "sim"}, "profile must be a RigProfile"),
    ],
)
def test_construction_validates_naming_field_and_row(changes: dict[str, object], expected: str) -> None:
    with pytest.raises(ValueError, match=expected):
        simple(**changes)


def test_arrays_are_read_only_copies_and_quaternions_renormalised() -> None:
    tip = np.tile([1.0005, 0.0, 0.0, 0.0], (6, 1))
    data = simple(tip_orientation=tip)
    tip[0, 0] = 7.0
    np.testing.assert_array_equal(data.tip_orientation, np.tile(IDENTITY, (6, 1)))
    with pytest.raises(ValueError):
        data.time_s[0] = 1.0
    assert data.sweep.tolist() == [-1] * 6 and data.step.tolist() == [0] * 6


def test_steps_from_runs_split_on_sweep_or_force_changes() -> None:
    sweep = [-1, -1, -1, 0, 0, 0, 0]
    forces = np.array([[0, 0, 0], [0, 0, 0], [0.1, 0, 0], [0.1, 0, 0], [0.1, 0, 0], [0.1, 0.05, 0], [0.1, 0.05, 0]])
    assert steps_from_runs(sweep, forces).tolist() == [0, 0, 1, 2, 2, 3, 3]


def test_selection_by_sweep_and_flags() -> None:
    sweep = np.array([-1, -1, 0, 0, 2, 2])
    flags = np.array([0, SampleFlag.TIP_MISSING, 0, SampleFlag.SATURATED | SampleFlag.OUT_OF_VOLUME, 0, 0])
    data = simple(sweep=sweep, flags=flags, source="unit")
    assert len(data) == 6
    assert data.calibration_rows().time_s.tolist() == pytest.approx([0.0, 0.1])
    assert data.sweep_ids() == (0, 2)
    assert {k: len(v) for k, v in data.sweeps().items()} == {0: 2, 2: 2}
    assert data.sweep_rows(2).time_s.tolist() == pytest.approx([0.4, 0.5])
    with pytest.raises(KeyError, match="no sweep 1"):
        data.sweep_rows(1)
    assert data.valid_mask().tolist() == [True, False, True, False, True, True]
    assert data.valid_mask(exclude=SampleFlag.TIP_MISSING).tolist() == [True, False, True, True, True, True]
    assert len(data.valid_rows()) == 4
    assert data.flag_counts() == {"BASE_MISSING": 0, "TIP_MISSING": 1, "OUT_OF_VOLUME": 1, "SATURATED": 1,
                                 "UNSETTLED": 0}
    picked = data.select([1, 4])
    assert picked.flags.tolist() == [SampleFlag.TIP_MISSING, 0] and picked.source == "unit"
    with pytest.raises(ValueError, match="time goes backwards"):
        data.select([4, 1])


def random_poses(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """n random rod-tip poses in the base frame (4x4) and random clamp orientations."""
    tips = np.array([se3(matrix_from_quat(quat_from_rotvec(rng.normal(size=3))), rng.normal(size=3) * 0.05)
                     for _ in range(n)])
    clamps = quat_from_rotvec(rng.normal(size=(n, 3)))
    return tips, clamps


def test_frames_undo_the_sensor_mountings() -> None:
    rng = np.random.default_rng(11)
    profile = profile_from_mapping({
        "gravity": {"in_tracker_m_s2": [1.0, -9.0, 3.0]},
        "base_sensor": {"rotation_in_base": quat_from_rotvec([0.3, -1.0, 0.2]).tolist(),
                        "offset_in_base_m": [0.012, -0.004, -0.008]},
        "tip_sensor": {"rotation_in_tip": quat_from_rotvec([-0.5, 0.1, 0.9]).tolist(),
                       "offset_in_tip_m": [0.001, 0.002, 0.010]},
    })
    tips, clamps = random_poses(rng, 25)
    clamp_positions = rng.normal(size=(25, 3)) * 0.1
    poses = profile.sensor_poses_in_tracker(tips, clamps, clamp_positions)
    data = Dataset(time_s=np.arange(25.0), jet_forces_n=np.zeros((25, 3)), profile=profile,
                   base_orientation=poses.base_orientation, tip_orientation=poses.tip_orientation,
                   base_position_m=poses.base_position_m, tip_position_m=poses.tip_position_m)
    # (1e-5 degrees is the floor of arccos near 1, not a loose tolerance.)
    assert np.max(rotation_angle_deg(data.clamp_orientation(), clamps)) < 1e-5
    recovered = matrix_from_quat(data.tip_orientation_in_base())
    np.testing.assert_allclose(recovered, tips[:, :3, :3], atol=1e-12)
    np.testing.assert_allclose(data.tip_position_in_base_m(), tips[:, :3, 3], atol=1e-12)
    # Gravity in the base frame is R_clamp^T g for each sample.
    expected = np.einsum("nji,j->ni", matrix_from_quat(clamps), profile.gravity_in_tracker_m_s2)
    np.testing.assert_allclose(data.gravity_in_base_m_s2(), expected, atol=1e-12)
    np.testing.assert_allclose(data.model_parameters(7).gravity_in_base_m_s2, expected[7], atol=1e-12)
    # The sensor-to-sensor rotation is what the sensors read, mountings included.
    relative = matrix_from_quat(data.tip_relative_to_base())
    base_sensor = matrix_from_quat(poses.base_orientation)
    tip_sensor = matrix_from_quat(poses.tip_orientation)
    np.testing.assert_allclose(relative, np.swapaxes(base_sensor, 1, 2) @ tip_sensor, atol=1e-12)
    assert simple().tip_position_in_base_m() is None


def test_markley_average_is_sign_blind_and_symmetric() -> None:
    about_z = quat_from_rotvec(np.array([[0, 0, 0.2], [0, 0, -0.2], [0, 0, 0.1], [0, 0, -0.1]]))
    about_z[1] *= -1.0  # the same rotation, other sign
    mean = average_quaternions(about_z)
    assert rotation_angle_deg(mean, IDENTITY) < 1e-9
    assert np.dot(mean, about_z[-1]) > 0  # sign follows the last sample
    assert np.dot(average_quaternions(about_z[:2]), about_z[1]) > 0
    weighted = rotvec_from_quat(average_quaternions(about_z[:2], weights=[3.0, 1.0]))
    assert 0.05 < weighted[2] < 0.2 and abs(weighted[0]) + abs(weighted[1]) < 1e-12  # towards +0.2 rad
    with pytest.raises(ValueError, match=r"\(n, 4\)"):
        average_quaternions(np.zeros((0, 4)))


def noisy_steps(rng: np.random.Generator) -> tuple[Dataset, list[tuple[np.ndarray, np.ndarray, np.ndarray]]]:
    """Five 5 s steps at 50 Hz (two calibration, three in sweep 0): a decaying 30 degree
    transient, then noise of 0.7 degrees and 0.5 mm rms around the settled truth."""
    rate_hz, duration_s = 50, 5.0
    per_step = int(rate_hz * duration_s)
    truths, columns = [], {k: [] for k in ("t", "q", "base", "tip", "bp", "tp", "sweep", "step")}
    for index, sweep in enumerate([-1, -1, 0, 0, 0]):
        base_truth = quat_from_rotvec(rng.normal(size=3))
        tip_truth = quat_from_rotvec(rng.normal(size=3))
        tip_pos_truth = rng.normal(size=3) * 0.05
        truths.append((base_truth, tip_truth, tip_pos_truth))
        local_t = np.arange(per_step) / rate_hz
        transient = np.radians(30.0) * np.exp(-local_t / 0.4)[:, None] * np.array([1.0, 0.0, 0.0])
        noise = np.radians(0.7) / np.sqrt(3) * rng.normal(size=(per_step, 3))
        columns["t"].append(index * duration_s + local_t)
        columns["q"].append(np.tile([0.02 * index, 0.0, 0.01], (per_step, 1)))
        columns["base"].append(quat_multiply(base_truth, quat_from_rotvec(
            np.radians(0.7) / np.sqrt(3) * rng.normal(size=(per_step, 3)))))
        columns["tip"].append(quat_multiply(tip_truth, quat_from_rotvec(transient + noise)))
        columns["bp"].append(np.zeros((per_step, 3)) + 0.0005 / np.sqrt(3) * rng.normal(size=(per_step, 3)))
        columns["tp"].append(tip_pos_truth + transient * 0.01 + 0.0005 / np.sqrt(3) * rng.normal(size=(per_step, 3)))
        columns["sweep"].append(np.full(per_step, sweep))
        columns["step"].append(np.full(per_step, index))
    stacked = {k: np.concatenate(v) for k, v in columns.items()}
    # Flip the sign of every other quaternion: the same rotations, a harder average.
    stacked["tip"][::2] *= -1.0
    data = Dataset(time_s=stacked["t"], jet_forces_n=stacked["q"], base_orientation=stacked["base"],
                   tip_orientation=stacked["tip"], base_position_m=stacked["bp"], tip_position_m=stacked["tp"],
                   sweep=stacked["sweep"], step=stacked["step"], profile=PROFILE, source="synthetic")
    return data, truths


def test_quasistatic_steps_average_noisy_samples_to_the_truth() -> None:
    rng = np.random.default_rng(2020)
    data, truths = noisy_steps(rng)
    steps = data.quasistatic_steps(window_s=1.0)
    assert len(steps) == 5
    assert steps.sweep.tolist() == [-1, -1, 0, 0, 0] and steps.step.tolist() == [0, 1, 2, 3, 4]
    np.testing.assert_allclose(steps.time_s, np.arange(1, 6) * 5.0 - 0.02)
    np.testing.assert_allclose(steps.jet_forces_n[:, 0], 0.02 * np.arange(5))
    for row, (base_truth, tip_truth, tip_pos_truth) in enumerate(truths):
        # 51 samples of 0.7 degree noise: the mean is good to about 0.1 degree.
        assert rotation_angle_deg(steps.tip_orientation[row], tip_truth) < 0.3
        assert rotation_angle_deg(steps.base_orientation[row], base_truth) < 0.3
        assert np.linalg.norm(steps.tip_position_m[row] - tip_pos_truth) < 0.3e-3
    np.testing.assert_array_equal(steps.flags, 0)
    assert "quasistatic" in steps.source
    # Averaging the whole step drags in the 30 degree transient, and says so.
    whole = data.quasistatic_steps(window_s=None)
    assert rotation_angle_deg(whole.tip_orientation[0], truths[0][1]) > 1.0
    assert np.all(whole.flags == SampleFlag.UNSETTLED)


def test_steps_whose_tip_still_turns_in_their_window_are_flagged_unsettled() -> None:
    """Commands held 0.6 s (the transient's time constant is 0.4 s): every step's window
    holds the rod still turning. A still tip, noisy or exact, is never flagged, nor a
    step too short to judge (two samples)."""
    rng = np.random.default_rng(11)
    data, _ = noisy_steps(rng)
    brief = data.select((data.time_s % 5.0) < 0.6)
    assert np.all(brief.quasistatic_steps().flags == SampleFlag.UNSETTLED)
    settled = data.select((data.time_s % 5.0) > 3.0)
    np.testing.assert_array_equal(settled.quasistatic_steps(window_s=None).flags, 0)
    still = simple(6)
    assert still.quasistatic_steps(window_s=None).flags.tolist() == [0]
    turning = simple(2, tip_orientation=quat_from_rotvec(np.outer([0.0, 0.5], [1.0, 0.0, 0.0])))
    assert turning.quasistatic_steps(window_s=None).flags.tolist() == [0]


def test_each_step_counts_the_samples_it_averages_through_selection_and_reduction() -> None:
    rng = np.random.default_rng(7)
    data, _ = noisy_steps(rng)
    assert data.samples is None
    steps = data.quasistatic_steps(window_s=1.0)
    in_window = [int(np.sum(data.time_s[start:stop] >= data.time_s[stop - 1] - 1.0))
                 for start, stop in data.step_runs()]
    assert steps.samples.tolist() == in_window and set(in_window) <= {50, 51}  # 50 Hz, 1 s
    assert data.quasistatic_steps(window_s=None).samples.tolist() == [250] * 5
    # Rows that are averages already add up their counts; selection and joins keep them.
    assert steps.quasistatic_steps(window_s=None).samples.tolist() == in_window
    merged = Dataset.concatenate([steps.select([0, 1]), steps.select([2, 3, 4])])
    assert merged.samples.tolist() == in_window
    assert merged.quasistatic_steps(window_s=None).samples.tolist() == in_window
    # Averages joined with raw samples (a count each, or none): no count at all.
    assert Dataset.concatenate([steps.select([0, 1]), data.select(data.time_s >= 10.0)]).samples is None
    # Jets that change at every row: each step is one sample.
    moving = simple(6, jet_forces_n=np.outer(np.arange(6), [0.01, 0.0, 0.0]))
    assert moving.quasistatic_steps().samples.tolist() == [1] * 6
    with pytest.raises(ValueError, match="samples row 2 is 0"):
        simple(3, samples=[1, 4, 0])


def test_quasistatic_steps_skip_flagged_samples_and_flag_unusable_steps() -> None:
    rng = np.random.default_rng(5)
    data, truths = noisy_steps(rng)
    flags = np.zeros(len(data), dtype=np.int64)
    tip = data.tip_orientation.copy()
    # Step 0: a wild sample in the window, marked missing (its value must not count).
    wild = 249 - 10
    tip[wild] = quat_from_rotvec([2.0, 0.0, 0.0])
    flags[wild] = SampleFlag.TIP_MISSING
    # Step 1: every sample in the window out of volume.
    flags[500 - 51:500] = SampleFlag.OUT_OF_VOLUME
    flagged = Dataset(time_s=data.time_s, jet_forces_n=data.jet_forces_n, base_orientation=data.base_orientation,
                      tip_orientation=tip, sweep=data.sweep, step=data.step, flags=flags, profile=PROFILE)
    steps = flagged.quasistatic_steps(window_s=1.0)
    assert rotation_angle_deg(steps.tip_orientation[0], truths[0][1]) < 0.3
    assert steps.flags.tolist() == [0, SampleFlag.OUT_OF_VOLUME, 0, 0, 0]
    assert steps.valid_mask().tolist() == [True, False, True, True, True]
    with pytest.raises(ValueError, match="window_s"):
        data.quasistatic_steps(window_s=-1.0)
