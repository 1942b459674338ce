"""Online disturbance estimation (eq. 4) against a truth the model does not contain."""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

import numpy as np
import pytest

from hydrojet_bench.effects import EffectParameter
from hydrojet_bench.estimation import OnlineDisturbanceEstimator, OnlineSettings
from hydrojet_bench.geometry import rotation_angle_deg, so3_exp
from hydrojet_bench.models import CosseratModel, PrbModel
from hydrojet_bench.effects.problem import RodProblem
from hydrojet_bench.params import ModelParameters

PARAMS = ModelParameters(gravity_in_base_m_s2=(-9.81, 0.0, 0.0))


class StiffTip:
    """Hidden physics for the truth: the distal half of the rod 60 % stiffer."""

    name: ClassVar[str] = "stiff_tip"
    explanation: ClassVar[str] = "test only"
    parameters: ClassVar[tuple[EffectParameter, ...]] = ()
    uses_actuation: ClassVar[bool] = False

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        factor = np.where(problem.arc_length_m > 0.5 * problem.arc_length_m[-1], 1.6, 1.0)
        problem.bending_stiffness_x_nm2 = problem.bending_stiffness_x_nm2 * factor
        problem.bending_stiffness_y_nm2 = problem.bending_stiffness_y_nm2 * factor


def sweep():
    up = np.linspace(0.0, 0.12, 9)
    return [np.array([q, 0.0, 0.0]) for q in np.concatenate([up, up[-2::-1]])]


def truth_measurements():
    truth = CosseratModel(effects=("gravity", StiffTip()))
    return [truth.solve(q, PARAMS) for q in sweep()]


def rms(values) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def angle_deg(a, b) -> float:
    return float(rotation_angle_deg(a.tip_sensor_quaternion(), b.tip_sensor_quaternion()))


@pytest.mark.parametrize("model", [CosseratModel(), PrbModel()], ids=["cosserat", "prb"])
def test_online_estimation_cuts_orientation_error_on_a_sweep(model):
    # The truth has physics the model lacks. Constant disturbance (zero here: no
    # calibration in this unit test) versus the online estimate after each step's two
    # updates. Position is judged in the calibrated paper reproduction, not here: a
    # moment alone cannot fix a stiffness distribution's position error.
    estimator = OnlineDisturbanceEstimator(model, PARAMS)
    constant, online = [], []
    for q, truth in zip(sweep(), truth_measurements()):
        constant.append(angle_deg(model.solve(q, PARAMS), truth))
        online.append(estimator.update(q, truth.tip_sensor_in_base_sensor()).error_after_deg)
    assert rms(constant) > 3.0  # the hidden stiffening matters
    assert rms(online) < 0.4 * rms(constant)


def test_the_estimate_carries_over_and_converges_on_a_constant_discrepancy():
    truth = CosseratModel(effects=("gravity", StiffTip())).solve([0.06, 0.0, 0.02], PARAMS)
    estimator = OnlineDisturbanceEstimator(CosseratModel(), PARAMS, OnlineSettings(iterations=1))
    errors = [estimator.update([0.06, 0.0, 0.02], truth.tip_sensor_in_base_sensor()).error_before_deg
              for _ in range(12)]
    # Gain 0.4 and one iteration per step: the error shrinks about 0.6x per step.
    assert errors[1] < 0.75 * errors[0]
    assert errors[-1] < 0.05 * errors[0]
    assert np.linalg.norm(estimator.disturbance_moment_nm) > 0.0


def test_quaternion_measurements_and_tolerance_stop():
    model = CosseratModel()
    exact = model.solve([0.05, 0.0, 0.0], PARAMS)
    estimator = OnlineDisturbanceEstimator(model, PARAMS)
    step = estimator.update([0.05, 0.0, 0.0], exact.tip_sensor_quaternion())
    assert step.iterations == 0 and step.error_before_deg < 1e-6
    np.testing.assert_allclose(estimator.disturbance_moment_nm, 0.0)


@pytest.mark.parametrize("field, value", [("gain", 0.0), ("gain", 1.5), ("damping", -1.0),
                                          ("iterations", 0), ("tolerance_deg", float("nan"))])
def test_settings_are_validated(field, value):
    with pytest.raises(ValueError, match=f"estimator.{field}"):
        OnlineSettings(**{field: value})


def _python_path_only(estimator, monkeypatch):
    """The estimator without its one-kernel update: every step through the model's solves."""
    monkeypatch.setattr(estimator, "_update_in_kernel", lambda *args: None)
    return estimator


ROD_WITH_EVERYTHING = (("gravity", "nonlinear_elasticity", "base_hysteresis", "sensor_mounting"),
                       {"nonlinear_elasticity.beta_m2": 2e-4, "base_hysteresis.compliance_rad_per_nm": 0.5,
                        "base_hysteresis.play_rad": 0.01, "sensor_mounting.rx_rad": 0.05,
                        "sensor_mounting.rz_rad": -0.1})


@pytest.mark.parametrize("model_class", [CosseratModel, PrbModel], ids=["cosserat", "prb"])
@pytest.mark.parametrize("rod", [(("gravity",), {}), ROD_WITH_EVERYTHING], ids=["plain", "everything"])
@pytest.mark.parametrize("settings", [OnlineSettings(), OnlineSettings(iterations=3, tolerance_deg=0.0)],
                         ids=["default", "three_iterations"])
def test_the_one_kernel_update_is_the_python_update_bit_for_bit(model_class, rod, settings, monkeypatch):
    # A random walk of jets with a noisy measurement each step, and a jump the warm solve
    # inside the kernel cannot finish in 8 iterations (the update then takes the model's
    # whole solve path): estimates, errors and shapes all equal, not close.
    from hydrojet_bench.estimation import online
    from hydrojet_bench.geometry import so3_exp
    from hydrojet_bench.params import with_parameters

    effects, values = rod
    params = with_parameters(PARAMS, values)
    model = model_class(effects=effects, max_iterations=8)
    outcomes = []
    kernel = online._update_kernel
    monkeypatch.setattr(online, "_update_kernel", lambda *args: outcomes.append(kernel(*args)) or outcomes[-1])
    fast = OnlineDisturbanceEstimator(model, params, settings)
    slow = _python_path_only(OnlineDisturbanceEstimator(model, params, settings), monkeypatch)
    rng = np.random.default_rng(7)
    jets = np.zeros(3)
    for step in range(14):
        jets = np.array([0.1, 0.0, 0.03]) if step == 4 else np.clip(jets + rng.normal(0.0, 0.006, 3), 0.0, 0.12)
        measured = (model_class().solve(jets, params).tip_sensor_in_base_sensor()
                    @ so3_exp(rng.normal(0.0, np.radians(1.0), 3)))
        a, b = fast.update(jets, measured), slow.update(jets, measured)
        assert (a.error_before_deg, a.error_after_deg, a.iterations) == (b.error_before_deg, b.error_after_deg,
                                                                         b.iterations)
        np.testing.assert_array_equal(a.disturbance_moment_nm, b.disturbance_moment_nm)
        for field in ("positions_in_base_m", "rotations_in_base", "base_wrench_in_base", "base_rotation_vector_rad",
                      "jacobian"):
            np.testing.assert_array_equal(getattr(a.solution, field), getattr(b.solution, field), err_msg=field)
        assert (a.solution.iterations, a.solution.residual) == (b.solution.iterations, b.solution.residual)
    assert -1 in outcomes and max(outcomes) >= 1  # both the fallback and the kernel ran


def test_a_measurement_of_the_wrong_shape_is_refused():
    estimator = OnlineDisturbanceEstimator(CosseratModel(), PARAMS)
    with pytest.raises(ValueError, match=r"3x3 rotation or a quaternion .* shape \(3,\)"):
        estimator.update([0.05, 0.0, 0.0], [1.0, 0.0, 0.0])


def _damped_least_squares_by_lapack(matrix, omega, damping, gain):
    gram = matrix @ matrix.T
    mu = damping * np.linalg.eigvalsh(gram)[-1]
    return gain * (matrix.T @ np.linalg.solve(gram + mu * np.eye(3), omega))


_SENSITIVITY_SHAPES = ("random", "rank_two", "rank_one", "equal_eigenvalues", "diagonal", "tiny", "minute",
                       "huge")


@pytest.mark.parametrize("case", _SENSITIVITY_SHAPES)
def test_the_closed_form_damped_least_squares_is_lapacks(case):
    # The update's eq. 4 solves its 3x3 system in closed form (the largest eigenvalue of
    # S S^T by the trigonometric formula): it must agree with LAPACK for any S the
    # sensitivity can give, including rank-deficient and degenerate ones.
    from hydrojet_bench.estimation.online import _damped_least_squares, _largest_eigenvalue_symmetric3

    rng = np.random.default_rng(_SENSITIVITY_SHAPES.index(case))
    for _ in range(200):
        matrix = rng.normal(size=(3, 3))
        if case == "rank_two":
            matrix[2] = rng.normal() * matrix[0] + rng.normal() * matrix[1]
        elif case == "rank_one":
            matrix = np.outer(rng.normal(size=3), rng.normal(size=3))
        elif case == "equal_eigenvalues":
            rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
            matrix = rng.uniform(0.1, 10.0) * rotation
        elif case == "diagonal":
            matrix = np.diag(rng.normal(size=3))
        elif case == "tiny":
            matrix *= 1e-9
        elif case == "minute":  # the cube of S S^T's spread would underflow
            matrix *= 1e-60
        elif case == "huge":
            matrix *= 1e6
        omega = rng.normal(size=3)
        gram = matrix @ matrix.T
        largest = np.linalg.eigvalsh(gram)[-1]
        assert _largest_eigenvalue_symmetric3(gram) == pytest.approx(largest, rel=1e-10)
        if case == "minute":
            continue  # Cramer's rule's singularity test underflows too; no rod is that stiff
        for damping in (1e-3, 0.3):
            change = np.empty(3)
            _damped_least_squares(matrix, omega, damping, 0.4, change)
            expected = _damped_least_squares_by_lapack(matrix, omega, damping, 0.4)
            np.testing.assert_allclose(change, expected, rtol=1e-7, atol=1e-9 * np.abs(expected).max())


def test_damped_least_squares_with_no_sensitivity_changes_nothing():
    from hydrojet_bench.estimation.online import _damped_least_squares

    change = np.full(3, np.nan)
    _damped_least_squares(np.zeros((3, 3)), np.array([0.01, -0.02, 0.0]), 1e-3, 0.4, change)
    np.testing.assert_array_equal(change, np.zeros(3))


def _failing_solves(model, monkeypatch, fails):
    """``model`` whose solves raise ConvergenceError where ``fails(prepared, turn)`` says."""
    from hydrojet_bench.errors import ConvergenceError

    solve = model.solve_prepared

    def solve_prepared(prepared, warm_start=None, predicted_tip_turn_rad=None):
        if fails(prepared, predicted_tip_turn_rad):
            raise ConvergenceError("cosserat model did not converge (as the test wants)")
        return solve(prepared, warm_start, predicted_tip_turn_rad=predicted_tip_turn_rad)

    monkeypatch.setattr(model, "solve_prepared", solve_prepared)


def test_an_estimate_the_model_cannot_carry_restarts_from_the_calibrated_one(monkeypatch):
    model = CosseratModel()
    jets = np.array([0.04, 0.0, 0.0])
    measured = model.solve(jets, PARAMS).tip_sensor_in_base_sensor()
    estimator = _python_path_only(OnlineDisturbanceEstimator(model, PARAMS), monkeypatch)
    estimator._moment = np.array([0.0, 0.0, 5e-3])  # carried from steps the model could follow
    calibrated = np.array(PARAMS.disturbance.moment_nm)
    _failing_solves(model, monkeypatch, lambda prepared, turn: turn is None and not np.array_equal(
        prepared.tip, model.prepare(jets, PARAMS).tip))
    step = estimator.update(jets, measured)
    assert step.fallback == "the carried estimate could not be solved: restarted from the calibrated w_d"
    assert step.error_before_deg < 1e-6  # the calibrated model is right here
    np.testing.assert_array_equal(step.disturbance_moment_nm, calibrated)


def test_a_correction_the_model_cannot_solve_is_not_made(monkeypatch):
    model = CosseratModel()
    jets = np.array([0.04, 0.0, 0.0])
    measured = model.solve(jets, PARAMS).tip_sensor_in_base_sensor() @ so3_exp(np.radians([0.5, 0.5, 0.0]))
    estimator = _python_path_only(OnlineDisturbanceEstimator(model, PARAMS), monkeypatch)
    _failing_solves(model, monkeypatch, lambda prepared, turn: turn is not None)
    step = estimator.update(jets, measured)
    assert step.fallback == "a correction could not be solved: not made"
    assert step.iterations == 0 and step.error_after_deg == step.error_before_deg > 0.5
    np.testing.assert_array_equal(step.disturbance_moment_nm, PARAMS.disturbance.moment_nm)
    # Without failures the same step corrects as usual and says nothing.
    monkeypatch.undo()
    usual = OnlineDisturbanceEstimator(model, PARAMS).update(jets, measured)
    assert usual.fallback == "" and usual.iterations >= 1 and usual.error_after_deg < step.error_after_deg


def test_a_comparison_says_on_which_steps_online_estimation_fell_back(monkeypatch):
    from hydrojet_bench.analysis.compare import compare_methods
    from hydrojet_bench.twin import DigitalTwin, TwinConfig
    from hydrojet_bench.plans import calibration_plan
    from hydrojet_bench.profile import load_profile

    profile = load_profile("sim")
    steps = DigitalTwin(TwinConfig.from_profile(profile, seed=2)).run_plan(
        calibration_plan(4, seed=2), record_window_s=0.5).to_dataset(profile, "four poses").quasistatic_steps()
    model = CosseratModel()
    monkeypatch.setattr(OnlineDisturbanceEstimator, "_update_in_kernel", lambda *args: None)
    _failing_solves(model, monkeypatch, lambda prepared, turn: turn is not None)
    results = compare_methods(model, profile.model_parameters(), steps, OnlineSettings(tolerance_deg=0.0))
    assert results["ref"].fallbacks == ()
    assert results["online"].fallbacks == tuple((index, "a correction could not be solved: not made")
                                                for index in range(4))
    assert results["online"].fallback_notice() == (
        "online estimation could not be solved as usual on 4 of 4 steps (0, 1, 2, 3; first: a correction could not "
        "be solved: not made); their Proposed predictions carry less or no correction")
