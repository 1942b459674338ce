"""Model predictions and the online disturbance estimate, one settled step at a time.

The live session and `hydrojet-bench replay` both feed settled steps through
`StepEstimation`, in the recorded order: fed the same steps with the same parameters and
settings, replay reproduces the live estimates exactly.

Each step gets two predictions, as in the paper's Table II: "ref" with the calibrated,
constant disturbance wrench, and, with online estimation on, "online" after correcting
w_d|m from that step's measurement (eq. 4).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..analysis.compare import Predictions
from ..analysis.metrics import orientation_errors_deg, position_errors_mm
from ..data.dataset import Dataset
from ..estimation.online import OnlineDisturbanceEstimator, OnlineSettings
from ..geometry import quat_from_matrix
from ..models.shooting import ShootingModel, Solution
from ..params import ModelParameters


@dataclass(frozen=True)
class Prediction:
    """One model prediction of one step, compared with its measurement.

    tip_in_base: predicted tip sensor orientation in the base sensor frame (w, x, y, z).
    tip_position_in_base_m: predicted rod tip position, base frame, m.
    """

    method: str
    tip_in_base: np.ndarray
    tip_position_in_base_m: np.ndarray
    bend_deg: float
    orientation_error_deg: float
    position_error_mm: float | None
    solution: Solution


@dataclass(frozen=True)
class StepEstimate:
    """Predictions of one settled step; ``online`` and the disturbance fields are None
    when online estimation is off. disturbance_moment_nm: w_d|m after this step, tip
    frame, N m; disturbance_force_n: the calibrated (constant) w_d|f, N."""

    index: int
    ref: Prediction
    online: Prediction | None
    disturbance_force_n: np.ndarray
    disturbance_moment_nm: np.ndarray | None
    error_before_deg: float | None
    iterations: int | None

    @property
    def best(self) -> Prediction:
        return self.online if self.online is not None else self.ref


class StepEstimation:
    """Predicts settled steps in order with ``params`` (calibrated), optionally with the
    online estimator (``online`` settings, None for off)."""

    def __init__(self, model: ShootingModel, params: ModelParameters, online: OnlineSettings | None) -> None:
        self.model = model
        self.params = params
        self.online_settings = online
        self._estimator = OnlineDisturbanceEstimator(model, params, online) if online is not None else None
        self._previous_ref: Solution | None = None
        self.count = 0

    def update(self, step: Dataset) -> StepEstimate:
        """Predict one settled step (a one-row `Dataset` from `quasistatic_steps`)."""
        if len(step) != 1:
            raise ValueError(f"StepEstimation.update takes one settled step, got {len(step)} rows")
        jets = step.jet_forces_n[0]
        gravity = step.gravity_in_base_m_s2()[0]
        measured = step.tip_orientation_in_base()[0]
        positions = step.tip_position_in_base_m()
        measured_position = None if positions is None else positions[0]
        row_params = replace(self.params, gravity_in_base_m_s2=tuple(gravity))
        ref_solution = self.model.solve(jets, row_params, previous=self._previous_ref)
        self._previous_ref = ref_solution
        ref = _prediction("ref", ref_solution, measured, measured_position)
        online = moment = before = iterations = None
        if self._estimator is not None:
            result = self._estimator.update(jets, measured, gravity_in_base_m_s2=gravity)
            online = _prediction("online", result.solution, measured, measured_position)
            moment, before, iterations = result.disturbance_moment_nm, result.error_before_deg, result.iterations
        estimate = StepEstimate(self.count, ref, online, np.array(self.params.disturbance.force_n), moment,
                                before, iterations)
        self.count += 1
        return estimate


def _prediction(method: str, solution: Solution, measured: np.ndarray, measured_position: np.ndarray | None) -> Prediction:
    predicted = quat_from_matrix(solution.tip_sensor_in_base_sensor())
    position = solution.tip_position_in_base_m
    return Prediction(
        method, predicted, position, solution.bend_angle_deg,
        float(orientation_errors_deg(predicted[None], measured[None])[0]),
        None if measured_position is None else float(position_errors_mm(position[None], measured_position[None])[0]),
        solution,
    )


def predictions_from_estimates(estimates: list[StepEstimate], method: str) -> Predictions | None:
    """The ``method`` ("ref" or "online") predictions of ``estimates`` as the analysis
    module's `Predictions` (None if some step lacks that method)."""
    picked = [getattr(estimate, method) for estimate in estimates]
    if not picked or any(prediction is None for prediction in picked):
        return None
    moments = [estimate.disturbance_moment_nm if estimate.disturbance_moment_nm is not None
               else np.zeros(3) for estimate in estimates]
    return Predictions(np.array([p.tip_in_base for p in picked]),
                       np.array([p.tip_position_in_base_m for p in picked]),
                       np.array([p.bend_deg for p in picked]), np.array(moments))
