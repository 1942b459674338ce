"""Twin configuration, valve duties -> jet forces, and the valve emulator driving the twin."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.valve.calibration import JetCalibration
from drivers.valve.emulator import ValveEmulator
from drivers.valve.protocol import Arm, SetAll, encode_message
from hydrojet_bench.geometry import quat_from_rotvec
from hydrojet_bench.profile import profile_from_mapping
from hydrojet_bench.twin import DigitalTwin, JetResponse, SensorNoise, TwinConfig


def test_default_valve_response_is_linear_to_the_full_scale_force():
    twin = DigitalTwin(TwinConfig(max_force_n=0.12, noise=SensorNoise.off()))
    np.testing.assert_allclose(twin.duties_to_forces((0, 250, 1000)), (0.0, 0.03, 0.12))
    twin.apply_valve_duties((500, 0, 1000), 1.0)
    np.testing.assert_allclose(twin.jet_forces_n, (0.06, 0.0, 0.12))
    assert twin.last_command_s == 1.0
    # The same duties again change nothing: no new command, no new settling.
    twin.apply_valve_duties((500, 0, 1000), 2.0)
    assert twin.last_command_s == 1.0
    twin.apply_valve_duties((0, 0, 0), 3.0)  # the watchdog closing every valve
    np.testing.assert_array_equal(twin.jet_forces_n, (0.0, 0.0, 0.0))
    assert twin.last_command_s == 3.0


def test_per_jet_tables_with_a_dead_band():
    dead_band = JetResponse((150, 600, 1000), (0.0, 0.05, 0.08))
    assert dead_band.force_for_duty(0) == 0.0
    assert dead_band.force_for_duty(149) == 0.0
    assert dead_band.force_for_duty(375) == pytest.approx(0.025)
    assert dead_band.force_for_duty(1000) == pytest.approx(0.08)
    offset = JetResponse((100, 1000), (0.01, 0.1))
    assert offset.force_for_duty(99) == 0.0  # below the first calibrated duty: off
    assert offset.force_for_duty(100) == pytest.approx(0.01)
    twin = DigitalTwin(TwinConfig(jet_response=(dead_band, JetResponse.linear(0.1), offset)))
    np.testing.assert_allclose(twin.duties_to_forces((600, 600, 550)), (0.05, 0.06, 0.055))


def test_response_inverts_the_valve_clients_calibration():
    calibration = JetCalibration(force_n=(0.0, 0.02, 0.1), duty_permille=(120, 300, 1000))
    response = JetResponse.from_calibration(calibration)
    for force in np.linspace(0.0, 0.1, 23):
        # One per mille of duty is at most 1.1e-4 N on this table.
        assert response.force_for_duty(calibration.duty_for_force(force)) == pytest.approx(force, abs=1.2e-4)


@pytest.mark.parametrize("duties, message", [
    ((0, 0), "3 duties"),
    ((0, 1001, 0), r"integers in 0\.\.1000"),
    ((0, -1, 0), r"integers in 0\.\.1000"),
    ((0, 2.5, 0), r"integers in 0\.\.1000"),
])
def test_bad_duties_are_refused(duties, message):
    with pytest.raises(ValueError, match=message):
        DigitalTwin().apply_valve_duties(duties, 0.0)


def test_the_valve_emulator_drives_the_twin():
    now = [10.0]
    twin = DigitalTwin(TwinConfig(max_force_n=0.1, noise=SensorNoise.off()))
    emulator = ValveEmulator(twin, clock=lambda: now[0])
    emulator.receive(encode_message(1, Arm()))
    now[0] = 10.25  # within the 500 ms watchdog
    emulator.receive(encode_message(2, SetAll((800, 0, 0))))
    np.testing.assert_allclose(twin.jet_forces_n, (0.08, 0.0, 0.0))
    assert twin.last_command_s == 10.25
    # The rod bends away over the following seconds.
    rest = twin.sensor_truth("tip", 10.25).position_in_tracker_m
    bent = twin.sensor_truth("tip", 20.0).position_in_tracker_m
    assert np.linalg.norm(bent - rest) > 0.02


@pytest.mark.parametrize("kwargs, message", [
    ({"hidden_effect_values": {"gravity.mass": 1.0}}, "key 'gravity.mass' is no parameter"),
    ({"hidden_effect_values": {"gravity.weight_scale": 7.0}}, "outside"),
    ({"hidden_effects": ("gravity", "gravity")}, "twice"),
    ({"hidden_effects": (object(),)}, "is not an Effect"),
    ({"hidden_effects": "gravity"}, "must be a sequence"),
    ({"seed": -3}, "seed"),
    ({"base_orientation_in_tracker": (1.0, 1.0, 0.0, 0.0)}, "base_orientation_in_tracker must be a unit quaternion"),
    ({"base_position_in_tracker_m": (0.0, float("nan"), 0.0)}, r"base_position_in_tracker_m\[1\] must be finite"),
    ({"gravity_in_tracker_m_s2": (0.0, -9.81)}, "gravity_in_tracker_m_s2 must have 3"),
    ({"settle_time_constant_s": -0.1}, "settle_time_constant_s must be >= 0"),
    ({"max_force_n": 0.0}, "max_force_n must be > 0"),
    ({"jet_response": (JetResponse.linear(0.1),)}, "jet_response must be 3"),
    ({"noise": 0.5}, "noise must be a SensorNoise"),
    ({"resolution": 0}, "resolution"),
    ({"base_sensor": (1.0, 0.0, 0.0, 0.0)}, "base_sensor must be a SensorMounting"),
])
def test_bad_configs_name_their_field(kwargs, message):
    with pytest.raises(ValueError, match=message):
        TwinConfig(**kwargs)


@pytest.mark.parametrize("kwargs, message", [
    ({"duty_permille": (0, 0), "force_n": (0.0, 0.1)}, "strictly increasing"),
    ({"duty_permille": (0, 1000), "force_n": (0.1, 0.0)}, "non-decreasing"),
    ({"duty_permille": (0, 1000), "force_n": (-0.1, 0.0)}, "jets only push"),
    ({"duty_permille": (0, 1200), "force_n": (0.0, 0.1)}, r"0\.\.1000"),
    ({"duty_permille": (0,), "force_n": (0.0,)}, "at least 2"),
    ({"duty_permille": (0, 500, 1000), "force_n": (0.0, 0.1)}, "has 2 points"),
])
def test_bad_jet_responses_name_their_field(kwargs, message):
    with pytest.raises(ValueError, match=message):
        JetResponse(**kwargs)


def test_bad_noise_and_history_limits():
    with pytest.raises(ValueError, match=r"em_position_rms_m must be >= 0"):
        SensorNoise(em_position_rms_m=-1e-3)
    with pytest.raises(ValueError, match="history_limit"):
        DigitalTwin(history_limit=1)


def test_history_is_bounded_and_old_times_are_refused():
    twin = DigitalTwin(TwinConfig(noise=SensorNoise.off()), history_limit=3)
    for i in range(5):
        twin.command_jet_forces((0.01 * i, 0.0, 0.0), float(i))
    assert twin.sensor_poses("tip", 2.5)[0].shape == (4,)
    with pytest.raises(ValueError, match="precedes the twin's kept history"):
        twin.sensor_poses("tip", 1.5)
    with pytest.raises(ValueError, match="precedes the twin's kept history"):
        twin.sensor_truth("tip", 0.5)


def test_config_from_a_rig_profile():
    profile = profile_from_mapping({
        "name": "bench", "gravity": {"in_tracker_m_s2": [9.81, 0.0, 0.0]},
        "base": {"orientation_in_tracker": quat_from_rotvec([0.0, 1.2, 0.0]).tolist(),
                 "position_in_tracker_m": [0.1, 0.2, 0.3]},
        "base_sensor": {"offset_in_base_m": [0.0, 0.01, 0.0]},
        "tip_sensor": {"rotation_in_tip": quat_from_rotvec([0.0, 0.0, 0.5]).tolist(),
                       "offset_in_tip_m": [0.0, 0.0, 0.014]},
        "jets": {"max_force_n": [0.1, 0.12, 0.08]}})
    config = TwinConfig.from_profile(profile, seed=4)
    assert config.seed == 4
    assert config.base_sensor == profile.base_sensor and config.tip_sensor == profile.tip_sensor
    assert config.base_position_in_tracker_m == (0.1, 0.2, 0.3)
    twin = DigitalTwin(config)
    np.testing.assert_allclose(twin.gravity_in_tracker_m_s2, (9.81, 0.0, 0.0), atol=1e-12)
    np.testing.assert_allclose(twin.true_params.gravity_in_base_m_s2, profile.gravity_in_base_m_s2(), atol=1e-12)
    np.testing.assert_allclose(twin.duties_to_forces((1000, 1000, 1000)), (0.1, 0.12, 0.08))
    assert twin.true_params.rod == profile.rod
    with pytest.raises(ValueError, match="profile must be a RigProfile"):
        TwinConfig.from_profile("sim")  # type: ignore[arg-type]
