"""Calibration data: validation, the correction arithmetic, rest-bias estimation; and the
fusion helpers that need no bus."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.imu.calibration import ImuCalibration, estimate_gyro_bias
from drivers.imu.codec import RawImuSample
from drivers.imu.errors import ImuMotionError
from drivers.imu.fusion import ImuOrientationFilter, orientation_from_gravity_and_field, tip_relative_to_base
from hydrojet_bench.geometry import matrix_from_quat, quat_from_rotvec, rotation_angle_deg


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"gyro_bias_rad_s": (0.0, 0.0)}, "gyro_bias_rad_s"),
        ({"gyro_bias_rad_s": (0.0, math.inf, 0.0)}, "gyro_bias_rad_s"),
        ({"mag_hard_iron_ut": "abc"}, "mag_hard_iron_ut"),
        ({"mag_soft_iron": np.eye(2)}, "mag_soft_iron"),
        ({"mag_soft_iron": np.diag([1.0, 1.0, -1.0])}, "mag_soft_iron"),  # reflection
        ({"mag_soft_iron": np.zeros((3, 3))}, "mag_soft_iron"),
        ({"mag_soft_iron": np.diag([1.0, 1.0, 1e-3])}, "mag_soft_iron"),  # ill-conditioned
        ({"mag_soft_iron": [[1, 0, 0], [0, 1, 0], [0, 0, math.nan]]}, "mag_soft_iron"),
    ],
)
def test_invalid_calibration_raises_value_error_naming_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=field):
        ImuCalibration(**kwargs)


def test_calibration_normalises_to_hashable_tuples() -> None:
    calibration = ImuCalibration(gyro_bias_rad_s=np.array([1, 2, 3]), mag_soft_iron=np.eye(3) * 2)
    assert calibration.gyro_bias_rad_s == (1.0, 2.0, 3.0)
    assert calibration.mag_soft_iron[2] == (0.0, 0.0, 2.0)
    assert hash(calibration) == hash(ImuCalibration((1, 2, 3), (0, 0, 0), np.eye(3) * 2))


def _raw(gyro=(0.0, 0.0, 0.0), accel=(0.0, 0.0, 9.81), mag=(20.0, 0.0, -45.0)) -> RawImuSample:
    return RawImuSample(accel, gyro, 25.0, mag)


def test_apply_corrects_gyro_and_both_iron_effects() -> None:
    soft_distortion = np.array([[1.2, 0.1, 0.0], [0.1, 0.9, 0.05], [0.0, 0.05, 1.1]])
    hard = np.array([12.0, -30.0, 7.0])
    true_field = np.array([18.0, -5.0, -44.0])
    raw = _raw(gyro=(0.1, -0.2, 0.3), mag=tuple(soft_distortion @ true_field + hard))
    calibration = ImuCalibration((0.1, -0.1, 0.0), hard, np.linalg.inv(soft_distortion))
    sample = calibration.apply(raw, t_s=5.0)
    assert sample.t_s == 5.0
    assert sample.gyro_rad_s == pytest.approx((0.0, -0.1, 0.3))
    assert sample.mag_ut == pytest.approx(tuple(true_field))
    assert sample.accel_m_s2 == raw.accel_m_s2
    overflowed = RawImuSample((0, 0, 9.8), (0, 0, 0), 25.0, None, mag_overflow=True)
    assert calibration.apply(overflowed, 0.0).mag_ut is None


def test_gyro_bias_is_the_mean_at_rest_and_motion_is_rejected() -> None:
    rng = np.random.default_rng(0)
    bias = np.array([0.01, -0.02, 0.005])
    rest = [_raw(gyro=tuple(bias + rng.normal(0, 0.002, 3))) for _ in range(300)]
    estimate = estimate_gyro_bias(rest, address=0x69)
    assert estimate.bias_rad_s == pytest.approx(tuple(bias), abs=5 * 0.002 / math.sqrt(300))
    assert estimate.sample_count == 300
    waved = [_raw(gyro=(0.3 * math.sin(i / 10), 0.0, 0.0)) for i in range(300)]
    with pytest.raises(ImuMotionError, match=r"0x69: .*gyro std"):
        estimate_gyro_bias(waved, address=0x69)
    shaken = [_raw(accel=(0.0, 0.0, 9.81 + (i % 2))) for i in range(300)]
    with pytest.raises(ImuMotionError, match="accel std"):
        estimate_gyro_bias(shaken)
    with pytest.raises(ValueError, match="at least 10"):
        estimate_gyro_bias(rest[:5])


quaternions = st.tuples(*[st.floats(-1.0, 1.0)] * 4).filter(lambda q: np.linalg.norm(q) > 0.1)


@settings(max_examples=200, deadline=None)
@given(quaternions)
def test_gravity_and_field_give_back_the_orientation(q_tuple: tuple[float, ...]) -> None:
    q = np.asarray(q_tuple) / np.linalg.norm(q_tuple)
    rotation = matrix_from_quat(q)
    field_in_tracker = np.array([20.0, 0.0, -45.0])  # horizontal part along +x: Madgwick's frame
    accel = rotation.T @ np.array([0.0, 0.0, 9.81])
    mag = rotation.T @ field_in_tracker
    # (arccos of a dot product near 1 limits the resolution to ~1e-6 deg)
    assert rotation_angle_deg(orientation_from_gravity_and_field(accel, mag), q) < 1e-4


def test_tip_relative_to_base_composes_rotations() -> None:
    q_base = quat_from_rotvec([0.0, 0.3, 0.0])
    q_rel = quat_from_rotvec([0.5, 0.0, 0.2])
    from hydrojet_bench.geometry import quat_multiply

    q_tip = quat_multiply(q_base, q_rel)
    assert rotation_angle_deg(tip_relative_to_base(q_base, q_tip), q_rel) < 1e-9


def test_filter_validates_and_falls_back_to_imu_update_without_field() -> None:
    with pytest.raises(ValueError, match="sample_rate_hz"):
        ImuOrientationFilter(0.0)
    with pytest.raises(ValueError, match="gain"):
        ImuOrientationFilter(100.0, gain=0.0)
    from drivers.imu.calibration import ImuSample

    tilted = quat_from_rotvec([0.4, 0.0, 0.0])
    accel = tuple(matrix_from_quat(tilted).T @ np.array([0.0, 0.0, 9.81]))
    f = ImuOrientationFilter(100.0, use_magnetometer=False)
    q = None
    for i in range(50):
        q = f.update(ImuSample(i * 0.01, accel, (1e-4, -1e-4, 1e-4), (20.0, 0.0, -45.0), 25.0, True))
    # without a field the heading is arbitrary: compare the tilt (the gravity direction)
    up_in_sensor = matrix_from_quat(q).T @ np.array([0.0, 0.0, 1.0])
    assert up_in_sensor == pytest.approx(np.asarray(accel) / 9.81, abs=1e-3)


def test_filter_restarts_from_gravity_after_a_gap_instead_of_integrating_across_it() -> None:
    from drivers.imu.calibration import ImuSample

    level = (0.0, 0.0, 9.81)
    field = (20.0, 0.0, -45.0)
    filter_ = ImuOrientationFilter(10.0)
    start = filter_.update(ImuSample(0.0, level, (0.0, 0.0, 0.0), field, 25.0, True))
    # One sample of a fast turn (2 rad/s) arriving 1 s (ten periods) later, at rest again
    # by the accelerometer and magnetometer: integrating it over the gap would turn the
    # estimate by 2 rad; restarting keeps it level, where the sensor actually is.
    after_gap = filter_.update(ImuSample(1.0, level, (0.0, 0.0, 2.0), field, 25.0, True))
    assert rotation_angle_deg(start, after_gap) < 1.0
    # Within the normal period the gyro is integrated as usual.
    turned = filter_.update(ImuSample(1.1, level, (0.0, 0.0, 2.0), field, 25.0, True))
    assert rotation_angle_deg(after_gap, turned) > 5.0
