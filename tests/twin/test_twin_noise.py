"""Sensor noise of the twin: EM and IMU statistics, and seeded determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hydrojet_bench.geometry import quat_conjugate, quat_multiply, rotation_angle_deg, rotvec_from_quat
from hydrojet_bench.plans import validation_sweeps
from hydrojet_bench.twin import DigitalTwin, SensorNoise, TwinConfig

SAMPLES = 20000  # rms estimates good to ~0.5 %; the tolerance below is 3 %


def bent_twin(noise: SensorNoise, seed: int = 0) -> DigitalTwin:
    twin = DigitalTwin(TwinConfig(noise=noise, seed=seed))
    twin.command_jet_forces((0.05, 0.0, 0.03), 0.0)
    return twin


def test_em_noise_has_the_trackers_rms_in_total_and_is_isotropic():
    twin = bent_twin(SensorNoise())
    times = np.full(SAMPLES, 30.0)
    measured = twin.measure_em(times)
    for sensor in ("base", "tip"):
        true_q, true_p = twin.sensor_poses(sensor, 30.0)
        position_error = getattr(measured, f"{sensor}_position_m") - true_p
        assert math.sqrt(np.mean(np.sum(position_error**2, axis=1))) == pytest.approx(0.48e-3, rel=0.03)
        np.testing.assert_allclose(np.std(position_error, axis=0), 0.48e-3 / math.sqrt(3), rtol=0.03)
        np.testing.assert_allclose(np.mean(position_error, axis=0), 0.0, atol=1e-5)
        orientation = getattr(measured, f"{sensor}_orientation")
        angle = rotation_angle_deg(orientation, true_q)
        assert math.sqrt(np.mean(angle**2)) == pytest.approx(0.70, rel=0.03)
        # Body-frame error vectors, equal spread on every axis.
        body_error = np.degrees(rotvec_from_quat(quat_multiply(quat_conjugate(true_q), orientation)))
        np.testing.assert_allclose(np.std(body_error, axis=0), 0.70 / math.sqrt(3), rtol=0.03)


def test_noise_off_measures_the_truth_and_scalars_keep_their_shape():
    twin = bent_twin(SensorNoise.off())
    sample = twin.measure_em(0.2)
    assert sample.tip_orientation.shape == (4,) and sample.tip_position_m.shape == (3,)
    true_q, true_p = twin.sensor_poses("tip", 0.2)
    assert rotation_angle_deg(sample.tip_orientation, true_q) < 1e-6
    np.testing.assert_allclose(sample.tip_position_m, true_p, atol=1e-15)
    imu = twin.measure_imu([0.2, 0.3])
    assert imu.base_position_m is None and imu.tip_orientation.shape == (2, 4)
    assert np.all(rotation_angle_deg(imu.tip_orientation, twin.sensor_poses("tip", [0.2, 0.3])[0]) < 1e-6)


def test_imu_white_noise_rms():
    twin = bent_twin(SensorNoise(imu_orientation_rms_deg=0.4, imu_drift_deg_per_sqrt_s=0.0))
    times = np.full(SAMPLES, 40.0)
    measured = twin.measure_imu(times)
    angle = rotation_angle_deg(measured.tip_orientation, twin.sensor_poses("tip", 40.0)[0])
    assert math.sqrt(np.mean(angle**2)) == pytest.approx(0.4, rel=0.03)


def test_imu_drift_is_a_tracker_side_random_walk():
    drift = 0.05  # deg / sqrt(s)
    twin = bent_twin(SensorNoise(imu_orientation_rms_deg=0.0, imu_drift_deg_per_sqrt_s=drift))
    dt = 0.1
    times = 10.0 + dt * np.arange(SAMPLES)
    measured = twin.measure_imu(times)
    true_q = twin.sensor_poses("base", times)[0]
    # Tracker-side: q_meas = d q_true, so q_meas conj(q_true) is the drift itself.
    walk = quat_multiply(measured.base_orientation, quat_conjugate(true_q))
    steps = rotation_angle_deg(walk[1:], walk[:-1])
    assert math.sqrt(np.mean(steps**2)) == pytest.approx(drift * math.sqrt(dt), rel=0.03)
    # Increments are independent: no correlation between successive steps.
    increments = np.diff(rotvec_from_quat(walk), axis=0)
    correlation = np.corrcoef(increments[1:, 0], increments[:-1, 0])[0, 1]
    assert abs(correlation) < 0.05
    # The walk carries over to the next call, and time may not run backwards.
    later = twin.measure_imu(times[-1] + 1e-9)
    later_walk = quat_multiply(later.base_orientation, quat_conjugate(true_q[-1]))
    assert rotation_angle_deg(later_walk, walk[-1]) < 1e-3
    with pytest.raises(ValueError, match="precedes the previous IMU measurement"):
        twin.measure_imu(5.0)
    with pytest.raises(ValueError, match="non-decreasing"):
        bent_twin(SensorNoise()).measure_imu([1.0, 0.5])


def _record(seed: int, sensors: str = "em"):
    twin = DigitalTwin(TwinConfig(seed=seed))
    return twin.run_plan(validation_sweeps(steps_up=2, repetitions=1, settle_s=1.0), sensors=sensors)


@pytest.mark.parametrize("sensors", ["em", "imu"])
def test_same_seed_same_recording_other_seed_other_noise(sensors):
    first, again, other = _record(11, sensors), _record(11, sensors), _record(12, sensors)
    for name in ("time_s", "jet_forces_n", "base_orientation", "tip_orientation", "base_position_m",
                 "tip_position_m", "sweep", "step", "flags"):
        a, b, c = getattr(first, name), getattr(again, name), getattr(other, name)
        if a is None:
            assert b is None and c is None and sensors == "imu"
            continue
        np.testing.assert_array_equal(a, b)
        if name in ("base_orientation", "tip_orientation", "base_position_m", "tip_position_m"):
            assert not np.array_equal(a, c)
        else:
            np.testing.assert_array_equal(a, c)


def test_em_and_imu_noise_draw_from_separate_streams():
    plain = DigitalTwin(TwinConfig(seed=5))
    with_imu = DigitalTwin(TwinConfig(seed=5))
    with_imu.measure_imu(np.linspace(0.0, 1.0, 50))
    np.testing.assert_array_equal(plain.measure_em(2.0).tip_position_m, with_imu.measure_em(2.0).tip_position_m)
