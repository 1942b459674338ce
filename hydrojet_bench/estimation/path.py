"""One path predictor: the steps of a recorded path predicted in order, as the bench
predicts them live.

Each step gets the paper's two predictions (Table II):

* "ref" (Ref.): the calibrated model with the calibrated, constant disturbance wrench
  w_d (force and moment, as fitted by eq. 24) at every step;
* "online" (Proposed), with online estimation on: w_d|m starts from the calibrated one
  and is corrected at each step from that step's measured orientation (eq. 4), the
  estimate carried along the path.

Each of the two carries its own path state from step to step (``previous=``, which a
clamp with play turns into hysteresis), so Ref. is the same whether online estimation
runs or not. Gravity in the base frame is given per step: from the measured base
orientation (`Dataset.gravity_in_base_m_s2`) unless the caller has a better one.

The live session, `replay`, `compare`, `sensors` and `diagnose` all predict through
`PathPredictor`: fed the same steps with the same parameters, they agree bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from itertools import groupby

import numpy as np

from ..data.dataset import Dataset
from ..errors import ConvergenceError
from ..geometry import matrix_from_quat, position_error_mm, quat_from_matrix, rotation_angle_deg
from ..models.shooting import ShootingModel, Solution, tip_sensors_in_base_sensor
from ..params import ModelParameters
from .online import EstimateStep, OnlineDisturbanceEstimator, OnlineSettings

REF = "ref"
ONLINE = "online"


@dataclass(frozen=True)
class Prediction:
    """One method's prediction of one step, compared with that step's measurement.

    method: "ref" or "online".
    tip_orientation_in_base: predicted tip sensor orientation in the base sensor frame
        (w, x, y, z); without mounting effects the rod tip in the base frame, as
        `Dataset.tip_orientation_in_base`.
    tip_position_in_base_m: predicted rod tip position, base frame, m.
    bend_deg: predicted bending angle, deg.
    disturbance_moment_nm: the w_d|m this prediction used, tip frame, N m: the calibrated
        one for Ref., the estimate after this step's correction for online.
    orientation_error_deg, position_error_mm: against the measurement (position None
        when none was measured).
    """

    method: str
    tip_orientation_in_base: np.ndarray
    tip_position_in_base_m: np.ndarray
    bend_deg: float
    disturbance_moment_nm: np.ndarray
    orientation_error_deg: float
    position_error_mm: float | None
    solution: Solution


@dataclass(frozen=True)
class StepPrediction:
    """Both predictions of one step. index: the step's place along the path (0-based);
    online: None when online estimation is off. disturbance_force_n: w_d|f, the
    calibrated constant (tip frame, N). error_before_deg: the online prediction's error
    before this step's correction (deg); iterations: corrections made (both None when
    online estimation is off). online_fallback: what the estimator did instead on this
    step when the model could not be solved (`EstimateStep.fallback`)."""

    index: int
    ref: Prediction
    online: Prediction | None
    disturbance_force_n: np.ndarray
    error_before_deg: float | None
    iterations: int | None
    online_fallback: str = ""

    @property
    def best(self) -> Prediction:
        return self.online if self.online is not None else self.ref


@dataclass(frozen=True)
class Predictions:
    """One method's predictions along a path of N steps, the fields of `Prediction` as
    arrays: tip_orientation_in_base (N, 4), tip_position_in_base_m (N, 3) m, bend_deg
    (N,), disturbance_moment_nm (N, 3) N m, tip frame."""

    tip_orientation_in_base: np.ndarray
    tip_position_in_base_m: np.ndarray
    bend_deg: np.ndarray
    disturbance_moment_nm: np.ndarray

    @classmethod
    def along(cls, steps: Sequence[StepPrediction], method: str) -> Predictions | None:
        """The ``method`` ("ref" or "online") predictions of ``steps`` (None if some
        step lacks that method)."""
        picked = [getattr(step, method) for step in steps]
        if not picked or any(prediction is None for prediction in picked):
            return None
        return cls(np.array([p.tip_orientation_in_base for p in picked]),
                   np.array([p.tip_position_in_base_m for p in picked]),
                   np.array([p.bend_deg for p in picked]),
                   np.array([p.disturbance_moment_nm for p in picked]))

    def select(self, rows: np.ndarray) -> Predictions:
        """The steps picked by a boolean mask or integer indices."""
        return Predictions(self.tip_orientation_in_base[rows], self.tip_position_in_base_m[rows],
                           self.bend_deg[rows], self.disturbance_moment_nm[rows])


def orientation_error_deg(predicted: np.ndarray, measured: np.ndarray) -> float:
    """Angle (deg) between one predicted and one measured orientation (w, x, y, z): the
    error of one step, computed the same way live and offline."""
    return float(rotation_angle_deg(predicted, measured))


def step_position_error_mm(predicted_m: np.ndarray, measured_m: np.ndarray | None) -> float | None:
    """Distance (mm) between one predicted and one measured position (m); None when
    nothing was measured."""
    return None if measured_m is None else float(position_error_mm(predicted_m, measured_m))


class PathPredictor:
    """Predicts the steps of one path in order with ``params`` (the calibrated ones: their
    w_d is Ref.'s constant and the online estimate's start), with online estimation when
    ``online`` settings are given."""

    def __init__(self, model: ShootingModel, params: ModelParameters, online: OnlineSettings | None = None) -> None:
        self.model = model
        self.params = params
        self._estimator = OnlineDisturbanceEstimator(model, params, online) if online is not None else None
        self._ref_params = params
        self._previous_ref: Solution | None = None
        self._count = 0

    def step(self, jet_forces_n: np.ndarray, measured_tip_in_base: np.ndarray, gravity_in_base_m_s2: np.ndarray,
             measured_tip_position_in_base_m: np.ndarray | None = None) -> StepPrediction:
        """Predict the next step: jet forces (N), the measured tip orientation in the base
        frame (w, x, y, z), gravity in the base frame then (m/s^2) and, when measured, the
        tip position in the base frame (m). Raises `ConvergenceError` when the model does
        not converge on it."""
        solution, estimate = self._solve(jet_forces_n, measured_tip_in_base, gravity_in_base_m_s2)
        positions = (None if measured_tip_position_in_base_m is None
                     else np.asarray(measured_tip_position_in_base_m, dtype=float)[np.newaxis])
        measured = np.asarray(measured_tip_in_base)[np.newaxis]
        ref, = _predictions(REF, [solution], np.array([self.params.disturbance.moment_nm]), measured, positions)
        if estimate is None:
            return self._next_record(ref)
        online, = _predictions(ONLINE, [estimate.solution], estimate.disturbance_moment_nm[np.newaxis], measured,
                               positions)
        return self._next_record(ref, online, estimate.error_before_deg, estimate.iterations, estimate.fallback)

    def _solve(self, jet_forces_n: np.ndarray, measured_tip_in_base: np.ndarray,
               gravity_in_base_m_s2: np.ndarray) -> tuple[Solution, EstimateStep | None]:
        """Ref.'s solution of the next step and, with online estimation, the estimator's
        update on it (``measured_tip_in_base``: a quaternion (w, x, y, z) or a 3x3 rotation)."""
        solution = self.model.solve(jet_forces_n, self._params_under(gravity_in_base_m_s2),
                                    previous=self._previous_ref)
        self._previous_ref = solution
        if self._estimator is None:
            return solution, None
        return solution, self._estimator.update(jet_forces_n, measured_tip_in_base,
                                                gravity_in_base_m_s2=gravity_in_base_m_s2)

    def _params_under(self, gravity_in_base_m_s2: np.ndarray) -> ModelParameters:
        gravity = tuple(gravity_in_base_m_s2)
        if gravity != self._ref_params.gravity_in_base_m_s2:
            # Kept while gravity stays the same, so the model can reuse its packed problem.
            self._ref_params = replace(self.params, gravity_in_base_m_s2=gravity)
        return self._ref_params

    def _next_record(self, ref: Prediction, online: Prediction | None = None, error_before_deg: float | None = None,
                     iterations: int | None = None, fallback: str = "") -> StepPrediction:
        record = StepPrediction(self._count, ref, online, np.array(self.params.disturbance.force_n), error_before_deg,
                                iterations, fallback)
        self._count += 1
        return record

    def predict(self, steps: Dataset, gravity_in_base_m_s2: np.ndarray | None = None) -> list[StepPrediction]:
        """Every row of ``steps`` in order (see `step`). gravity_in_base_m_s2: (N, 3) per
        row, m/s^2; None takes each row's from its measured base orientation."""
        gravity = steps.gravity_in_base_m_s2() if gravity_in_base_m_s2 is None else np.asarray(gravity_in_base_m_s2)
        measured = steps.tip_orientation_in_base()
        positions = steps.tip_position_in_base_m()
        if self._estimator is not None:
            # The estimate carries from step to step, so the steps are solved in turn; the
            # predictions are then made from all their solutions at once.
            rotations = matrix_from_quat(measured)
            solved = [self._solve(steps.jet_forces_n[row], rotations[row], gravity[row]) for row in range(len(steps))]
            refs = _predictions(REF, [solution for solution, _ in solved],
                                np.tile(self.params.disturbance.moment_nm, (len(steps), 1)), measured, positions)
            estimates = [estimate for _, estimate in solved]
            onlines = _predictions(ONLINE, [estimate.solution for estimate in estimates],
                                   np.array([estimate.disturbance_moment_nm for estimate in estimates]), measured,
                                   positions)
            return [self._next_record(ref, online, estimate.error_before_deg, estimate.iterations, estimate.fallback)
                    for ref, online, estimate in zip(refs, onlines, estimates)]
        solutions = self._solve_ref_along(steps.jet_forces_n, gravity)
        moments = np.tile(self.params.disturbance.moment_nm, (len(steps), 1))
        return list(map(self._next_record, _predictions(REF, solutions, moments, measured, positions)))

    def carry(self, steps: Dataset) -> None:
        """Follow the path through ``steps`` (the rows recorded before the ones to predict,
        in order), predicting none of them: the next step starts from the shape they end
        in, Ref. and online estimation alike (the estimate itself is not changed; a path
        the model cannot follow leaves none). A rod with several equilibria under one load
        (a heavy tip on a soft horizontal rod) sits on the one its history led it to; a
        path predicted from a fresh solve at its first step can start on another and stay
        there."""
        if not len(steps):
            return
        try:
            solutions = self._solve_ref_along(steps.jet_forces_n, steps.gravity_in_base_m_s2())
        except ConvergenceError:
            self._previous_ref = None  # a path the model cannot follow: start afresh, as without one
            return
        if self._estimator is not None:
            self._estimator.reset(previous=solutions[-1])

    def _solve_ref_along(self, jet_forces_n: np.ndarray, gravity_in_base_m_s2: np.ndarray) -> list[Solution]:
        """Ref.'s solutions of the rows in order, each from the last one's shape: each run of
        rows under one gravity is one batch of solves."""
        solutions: list[Solution] = []
        for _, run in groupby(range(len(jet_forces_n)), key=lambda row: tuple(gravity_in_base_m_s2[row])):
            run = list(run)
            solutions.extend(self.model.solve_batch(jet_forces_n[run], self._params_under(gravity_in_base_m_s2[run[0]]),
                                                    [None] * len(run), self._previous_ref, along_path=True))
            self._previous_ref = solutions[-1]
        return solutions


def _predictions(method: str, solutions: Sequence[Solution], moments_nm: np.ndarray, measured: np.ndarray,
                 measured_positions_m: np.ndarray | None) -> list[Prediction]:
    """One prediction per solution against its row of ``measured`` (k, 4) and, when given,
    ``measured_positions_m`` (k, 3, m); ``moments_nm`` (k, 3): the w_d|m each used."""
    predicted = quat_from_matrix(tip_sensors_in_base_sensor(solutions))
    positions = np.array([solution.positions_in_base_m[-1] for solution in solutions])
    tip_cosines = np.array([solution.rotations_in_base[-1, 2, 2] for solution in solutions])
    bends = np.degrees(np.arccos(np.clip(tip_cosines, -1.0, 1.0))).tolist()
    errors = rotation_angle_deg(predicted, measured).tolist()
    position_errors = ([None] * len(solutions) if measured_positions_m is None
                       else position_error_mm(positions, measured_positions_m).tolist())
    return [Prediction(method, predicted[k], positions[k], bends[k], moments_nm[k], errors[k], position_errors[k],
                       solution) for k, solution in enumerate(solutions)]
