"""The twin's truth: equilibria of its own Cosserat model, hidden effects, settling."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import ClassVar

import numpy as np
import pytest

from drivers.plant import Plant, SensorTruth
from hydrojet_bench.effects import EffectParameter
from hydrojet_bench.geometry import (matrix_from_quat, quat_conjugate, quat_from_matrix, quat_from_rotvec,
                                     quat_multiply, rotation_angle_deg, rotvec_from_quat)
from hydrojet_bench.models import CosseratModel
from hydrojet_bench.params import ModelParameters, RodParameters
from hydrojet_bench.profile import SensorMounting
from hydrojet_bench.twin import DigitalTwin, SensorNoise, TwinConfig

# A clamp tilted and shifted in the tracker frame, so frame mistakes cannot cancel.
BASE_Q = tuple(quat_from_rotvec(np.array([2.6, 0.7, -0.4])))
BASE_P = (0.12, -0.05, 0.31)
TRUE = ModelParameters(rod=RodParameters(youngs_modulus_base_pa=3.4e5, youngs_modulus_tip_pa=1.8e5,
                                         length_m=0.068))


class CompliantClamp:
    """Hidden effect written by a test: the clamp yields rotationally."""

    name: ClassVar[str] = "compliant_clamp"
    explanation: ClassVar[str] = "the clamp rotates by compliance * base moment"
    parameters: ClassVar[tuple[EffectParameter, ...]] = (
        EffectParameter("compliance", 0.0, 0.0, 100.0, "rad/(N m)", "rotational clamp compliance"),)
    uses_actuation: ClassVar[bool] = False

    def apply(self, problem, values: Mapping[str, float]) -> None:
        problem.base_compliance_rad_per_nm = np.full(3, values["compliance"])


class StrainStiffening:
    name: ClassVar[str] = "stiffening"
    explanation: ClassVar[str] = "the elastomer stiffens with strain"
    parameters: ClassVar[tuple[EffectParameter, ...]] = (
        EffectParameter("beta", 0.0, 0.0, 1.0, "m^2", "cubic stiffening coefficient"),)
    uses_actuation: ClassVar[bool] = False

    def apply(self, problem, values: Mapping[str, float]) -> None:
        problem.cubic_stiffening_m2 = values["beta"]


class TiltedTipSensor:
    """Hidden effect: the tip sensor sits tilted about its x axis, unknown to the rig."""

    name: ClassVar[str] = "tilted_tip_sensor"
    explanation: ClassVar[str] = "the tip sensor is glued in at an angle"
    parameters: ClassVar[tuple[EffectParameter, ...]] = (
        EffectParameter("tilt", 0.0, -1.0, 1.0, "rad", "rotation about the tip x axis"),)
    uses_actuation: ClassVar[bool] = False

    def apply(self, problem, values: Mapping[str, float]) -> None:
        problem.tip_sensor_mounting = matrix_from_quat(quat_from_rotvec([values["tilt"], 0.0, 0.0]))


def quiet_twin(**changes) -> DigitalTwin:
    values = dict(true_params=TRUE, noise=SensorNoise.off(), base_orientation_in_tracker=BASE_Q,
                  base_position_in_tracker_m=BASE_P)
    values.update(changes)
    return DigitalTwin(TwinConfig(**values))


def tracker_pose(solution, node: int, mounting: np.ndarray = np.eye(3), offset=np.zeros(3)):
    """Independent composition: base pose in the tracker frame, body frame, mountings."""
    r_base = matrix_from_quat(BASE_Q)
    rotation = r_base @ solution.rotations_in_base[node] @ mounting
    body_position = solution.positions_in_base_m[node] + solution.rotations_in_base[node] @ offset
    position = np.array(BASE_P) + r_base @ body_position
    return quat_from_matrix(rotation), position


@pytest.mark.parametrize("forces", [(0.0, 0.0, 0.0), (0.06, 0.0, 0.0), (0.0, 0.03, 0.07), (0.09, 0.09, 0.0)])
def test_settled_truth_is_the_cosserat_equilibrium_at_the_true_parameters(forces):
    twin = quiet_twin()
    twin.command_jet_forces(forces, 1.0)
    expected = CosseratModel(effects=("gravity",)).solve(forces, TRUE)
    for sensor, node in (("base", 0), ("tip", -1)):
        q, p = twin.sensor_poses(sensor, 1000.0)
        q_expected, p_expected = tracker_pose(expected, node)
        assert rotation_angle_deg(q, q_expected) < 1e-6
        np.testing.assert_allclose(p, p_expected, atol=1e-10)
    base_q, _ = twin.sensor_poses("base", 1000.0)
    tip_q, _ = twin.sensor_poses("tip", 1000.0)
    relative = quat_multiply(quat_conjugate(base_q), tip_q)
    assert rotation_angle_deg(relative, expected.tip_sensor_quaternion()) < 1e-6


def test_gravity_in_tracker_follows_the_base_pose_or_overrides_the_params():
    twin = quiet_twin()
    np.testing.assert_allclose(twin.gravity_in_tracker_m_s2,
                               matrix_from_quat(BASE_Q) @ np.array(TRUE.gravity_in_base_m_s2))
    across = quiet_twin(gravity_in_tracker_m_s2=(0.0, 0.0, -9.81))
    np.testing.assert_allclose(across.gravity_in_tracker_m_s2, (0.0, 0.0, -9.81), atol=1e-12)
    np.testing.assert_allclose(across.true_params.gravity_in_base_m_s2,
                               matrix_from_quat(BASE_Q).T @ np.array([0.0, 0.0, -9.81]), atol=1e-12)
    # The default rig hangs: the rest tip is 68 mm straight below the clamp.
    hanging = DigitalTwin(TwinConfig(true_params=TRUE, noise=SensorNoise.off()))
    np.testing.assert_allclose(hanging.gravity_in_tracker_m_s2, (0.0, 0.0, -9.81), atol=1e-12)
    np.testing.assert_allclose(hanging.sensor_poses("tip", 0.0)[1], (0.0, 0.0, -0.068), atol=1e-12)


def test_mountings_rotate_and_offset_the_sensors_and_cancel_from_the_relative_rotation():
    base_mount = SensorMounting(tuple(quat_from_rotvec([0.0, 0.3, 0.1])), (0.0, 0.004, -0.002))
    tip_mount = SensorMounting(tuple(quat_from_rotvec([1.2, 0.0, -0.5])), (0.0, 0.0, 0.012))
    twin = quiet_twin(base_sensor=base_mount, tip_sensor=tip_mount)
    twin.command_jet_forces((0.0, 0.05, 0.0), 0.0)
    expected = CosseratModel().solve((0.0, 0.05, 0.0), TRUE)
    for sensor, node, mount in (("base", 0, base_mount), ("tip", -1, tip_mount)):
        q, p = twin.sensor_poses(sensor, 60.0)
        q_expected, p_expected = tracker_pose(expected, node, matrix_from_quat(mount.rotation_in_body),
                                            np.array(mount.offset_in_body_m))
        assert rotation_angle_deg(q, q_expected) < 1e-6
        np.testing.assert_allclose(p, p_expected, atol=1e-10)
    base_q, tip_q = twin.sensor_poses("base", 60.0)[0], twin.sensor_poses("tip", 60.0)[0]
    stripped = quat_multiply(quat_multiply(base_mount.rotation_in_body, quat_multiply(quat_conjugate(base_q), tip_q)),
                             quat_conjugate(tip_mount.rotation_in_body))
    assert rotation_angle_deg(stripped, expected.tip_sensor_quaternion()) < 1e-6


def test_a_hidden_mounting_sits_between_the_body_and_the_known_mounting():
    tip_mount = SensorMounting(tuple(quat_from_rotvec([0.0, 0.9, 0.0])), (0.0, 0.0, 0.0))
    twin = quiet_twin(tip_sensor=tip_mount, hidden_effects=(TiltedTipSensor(),),
                      hidden_effect_values={"tilted_tip_sensor.tilt": 0.2})
    twin.command_jet_forces((0.05, 0.0, 0.0), 0.0)
    # Removing the known mounting leaves what a model with the effect predicts.
    expected = CosseratModel(effects=("gravity", TiltedTipSensor())).solve((0.05, 0.0, 0.0), twin.true_params)
    base_q, tip_q = twin.sensor_poses("base", 60.0)[0], twin.sensor_poses("tip", 60.0)[0]
    stripped = quat_multiply(quat_multiply(quat_conjugate(base_q), tip_q), quat_conjugate(tip_mount.rotation_in_body))
    assert rotation_angle_deg(stripped, expected.tip_sensor_quaternion()) < 1e-6
    assert rotation_angle_deg(expected.tip_sensor_quaternion(),
                              quat_from_matrix(expected.tip_rotation_in_base)) == pytest.approx(np.degrees(0.2), abs=1e-3)


@pytest.mark.parametrize("effect, key, value", [
    (CompliantClamp(), "compliant_clamp.compliance", 60.0),
    (StrainStiffening(), "stiffening.beta", 1e-3),
])
def test_hidden_effects_make_the_truth_differ_from_the_nominal_model(effect, key, value):
    forces = (0.07, 0.0, 0.02)
    twin = quiet_twin(hidden_effects=(effect,), hidden_effect_values={key: value})
    twin.command_jet_forces(forces, 0.0)
    nominal = CosseratModel(effects=("gravity",)).solve(forces, TRUE)
    base_q, tip_q = twin.sensor_poses("base", 100.0)[0], twin.sensor_poses("tip", 100.0)[0]
    measured = quat_multiply(quat_conjugate(base_q), tip_q)
    assert rotation_angle_deg(measured, nominal.tip_sensor_quaternion()) > 2.0
    # ...and are exactly the hidden physics, nothing else.
    with_effect = CosseratModel(effects=("gravity", effect)).solve(forces, twin.true_params)
    assert twin.true_params.effect_value(key, 0.0) == value
    assert rotation_angle_deg(measured, with_effect.tip_sensor_quaternion()) < 1e-6


def test_the_truth_shares_no_state_with_a_model_under_evaluation():
    plan_forces = [(0.05, 0.0, 0.0), (0.0, 0.08, 0.0), (0.02, 0.0, 0.06)]
    alone, disturbed = quiet_twin(), quiet_twin()
    evaluated = CosseratModel(effects=("gravity",))
    wrong = ModelParameters(rod=RodParameters(youngs_modulus_base_pa=1e5))
    for i, forces in enumerate(plan_forces):
        alone.command_jet_forces(forces, float(i))
        evaluated.solve(forces, wrong)  # another model, other params, in between
        disturbed.command_jet_forces(forces, float(i))
        evaluated.solve(forces, TRUE)  # the same params object as the twin was given
    times = np.linspace(0.0, 5.0, 41)
    for sensor in ("base", "tip"):
        np.testing.assert_array_equal(alone.sensor_poses(sensor, times)[0], disturbed.sensor_poses(sensor, times)[0])
    assert alone.true_params is not TRUE and alone.true_params == TRUE
    assert alone.model is not disturbed.model


def test_settling_is_first_order_from_the_pose_at_the_command():
    tau = 0.4
    twin = quiet_twin(settle_time_constant_s=tau)
    rest_q, rest_p = twin.sensor_poses("tip", 0.0)
    twin.command_jet_forces((0.08, 0.0, 0.0), 2.0)
    final_q, final_p = twin.sensor_poses("tip", 1e3)
    angle0 = rotation_angle_deg(rest_q, final_q)
    distance0 = np.linalg.norm(rest_p - final_p)
    assert angle0 > 30.0
    times = 2.0 + np.array([0.0, 0.5 * tau, tau, 3 * tau, 12.5 * tau])
    q, p = twin.sensor_poses("tip", times)
    decay = np.exp(-(times - 2.0) / tau)
    np.testing.assert_allclose(rotation_angle_deg(q, final_q), angle0 * decay, rtol=1e-7, atol=2e-6)
    np.testing.assert_allclose(np.linalg.norm(p - final_p, axis=1), distance0 * decay, rtol=1e-7, atol=1e-12)
    # Before the command nothing moved; a 5 s step is settled to 4e-6 of the move.
    assert rotation_angle_deg(twin.sensor_poses("tip", 1.999)[0], rest_q) < 1e-9
    assert rotation_angle_deg(twin.sensor_poses("tip", 7.0)[0], final_q) < 1e-5 * angle0
    # The path is the slerp: every intermediate orientation lies on one rotation axis.
    axes = rotvec_from_quat(quat_multiply(quat_conjugate(final_q), q[:-1]))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    np.testing.assert_allclose(axes, np.repeat(axes[:1], len(axes), axis=0), atol=1e-9)


def test_a_command_while_settling_starts_from_where_the_rod_is():
    twin = quiet_twin(settle_time_constant_s=0.5)
    twin.command_jet_forces((0.08, 0.0, 0.0), 0.0)
    before_q, before_p = twin.sensor_poses("tip", 0.3)
    twin.command_jet_forces((0.0, 0.0, 0.08), 0.3)
    after_q, after_p = twin.sensor_poses("tip", 0.3)
    assert rotation_angle_deg(before_q, after_q) < 1e-9
    np.testing.assert_allclose(before_p, after_p, atol=1e-15)
    # Continuous across the command too (no jump just after it).
    assert rotation_angle_deg(twin.sensor_poses("tip", 0.3 + 1e-6)[0], after_q) < 1e-3
    # Earlier times still answer from the earlier segment.
    np.testing.assert_allclose(twin.sensor_poses("tip", 0.1)[1], _single_command_position(0.1), atol=1e-15)
    with pytest.raises(ValueError, match="precedes the last command"):
        twin.command_jet_forces((0.0, 0.0, 0.0), 0.2)


def _single_command_position(t_s: float) -> np.ndarray:
    twin = quiet_twin(settle_time_constant_s=0.5)
    twin.command_jet_forces((0.08, 0.0, 0.0), 0.0)
    return twin.sensor_poses("tip", t_s)[1]


def test_zero_time_constant_jumps_to_the_equilibrium():
    twin = quiet_twin(settle_time_constant_s=0.0)
    twin.command_jet_forces((0.0, 0.06, 0.0), 1.0)
    assert rotation_angle_deg(twin.sensor_poses("tip", 1.0)[0], twin.sensor_poses("tip", 50.0)[0]) < 1e-12
    truth = twin.sensor_truth("tip", 1.0)
    assert np.all(truth.angular_velocity_in_sensor_rad_s == 0.0)


def test_sensor_truth_rates_are_the_derivatives_of_the_settling_motion():
    twin = quiet_twin(settle_time_constant_s=0.5)
    twin.command_jet_forces((0.0, 0.08, 0.03), 0.0)
    t, h = 0.37, 1e-5
    for sensor in ("base", "tip"):
        truth = twin.sensor_truth(sensor, t)
        assert isinstance(truth, SensorTruth)
        q_minus, p_minus = twin.sensor_poses(sensor, t - h)
        q_plus, p_plus = twin.sensor_poses(sensor, t + h)
        np.testing.assert_allclose(truth.orientation_in_tracker, twin.sensor_poses(sensor, t)[0], atol=1e-15)
        omega = rotvec_from_quat(quat_multiply(quat_conjugate(q_minus), q_plus)) / (2 * h)
        np.testing.assert_allclose(truth.angular_velocity_in_sensor_rad_s, omega, atol=1e-6)
        acceleration = (p_plus - 2 * truth.position_in_tracker_m + p_minus) / h**2
        np.testing.assert_allclose(truth.linear_acceleration_in_tracker_m_s2, acceleration, atol=2e-4)
    assert np.linalg.norm(twin.sensor_truth("tip", t).angular_velocity_in_sensor_rad_s) > 0.1


def test_the_twin_is_a_plant():
    twin = quiet_twin()
    assert isinstance(twin, Plant)
    with pytest.raises(KeyError, match="no sensor 'middle'"):
        twin.sensor_truth("middle", 0.0)
    truth = twin.sensor_truth("base", 0.0)
    assert truth.orientation_in_tracker.shape == (4,) and truth.position_in_tracker_m.shape == (3,)


def test_equilibrium_reports_the_solution_being_approached():
    twin = quiet_twin()
    solution = twin.command_jet_forces((0.05, 0.0, 0.0), 3.0)
    assert twin.equilibrium(3.5) is solution
    assert np.all(twin.equilibrium(2.0).jet_forces_n == 0.0)
    np.testing.assert_array_equal(twin.jet_forces_n, (0.05, 0.0, 0.0))
    assert twin.last_command_s == 3.0
    assert math.isinf(quiet_twin().last_command_s)


@pytest.mark.parametrize("forces, message", [
    ((0.1, -0.01, 0.0), "jets only push"),
    ((0.1, float("nan"), 0.0), "finite"),
    ((0.1, 0.0), "3 forces"),
])
def test_bad_commands_are_refused(forces, message):
    with pytest.raises(ValueError, match=message):
        quiet_twin().command_jet_forces(forces, 0.0)


@pytest.mark.parametrize("tau", [0.0, 0.4])
def test_the_truth_at_one_instant_is_the_vectorised_pose(tau):
    # sensor_truth (one instant, a compiled kernel, what the emulators ask) and
    # sensor_poses (stacks of times, numpy) must be one law, before, during and after a move.
    twin = quiet_twin(settle_time_constant_s=tau)
    twin.command_jet_forces((0.08, 0.02, 0.0), 2.0)
    twin.command_jet_forces((0.0, 0.0, 0.11), 2.3)  # while the first move still settles
    times = np.array([0.0, 1.999, 2.0, 2.1, 2.3, 2.31, 2.5, 4.0, 50.0])
    for sensor in ("base", "tip"):
        orientations, positions = twin.sensor_poses(sensor, times)
        for t_s, q, p in zip(times, orientations, positions):
            truth = twin.sensor_truth(sensor, float(t_s))
            np.testing.assert_allclose(truth.orientation_in_tracker, q, rtol=0.0, atol=1e-15)
            np.testing.assert_allclose(truth.position_in_tracker_m, p, rtol=0.0, atol=1e-15)


@pytest.mark.parametrize("tau", [0.0, 0.4])
def test_the_truths_at_a_run_of_instants_are_the_single_instant_ones_bit_for_bit(tau):
    # What an emulated IMU's FIFO asks in one call must be what it would have asked one
    # instant at a time (its batched run is tested bit for bit against that), across
    # commands and with the instants in any order (motion, then magnetometer instants).
    twin = quiet_twin(settle_time_constant_s=tau)
    twin.command_jet_forces((0.08, 0.02, 0.0), 2.0)
    twin.command_jet_forces((0.0, 0.0, 0.11), 2.3)
    times = np.array([2.0, 2.1, 2.3, 2.31, 2.5, 4.0, 1.999, 0.0, 2.05])
    for sensor in ("base", "tip"):
        truths = twin.sensor_truths(sensor, times)
        for row, t_s in enumerate(times):
            truth = twin.sensor_truth(sensor, float(t_s))
            for name in ("orientation_in_tracker", "position_in_tracker_m", "angular_velocity_in_sensor_rad_s",
                         "linear_acceleration_in_tracker_m_s2"):
                assert getattr(truths, name)[row].tobytes() == getattr(truth, name).tobytes(), (name, t_s)
    with pytest.raises(ValueError, match="1-D array of finite times"):
        twin.sensor_truths("tip", np.array([1.0, np.nan]))
