"""Online disturbance estimation (paper sec. II-A, eq. 4).

At each quasistatic step the model predicts the tip sensor's orientation relative to the
base sensor; the measured one differs by a body-frame rotation omega_des. The disturbance
moment w_d|m is corrected by damped least squares on the rotation rows of the
sensitivity matrix,

    delta w_m = lambda * S^T (S S^T + mu I)^-1 * omega_des,

and the model is solved again, up to ``iterations`` times per step or until the error
is below ``tolerance_deg``. The estimate carries over to the next step.

The paper prints ``(S S^T - mu I)^-1``. With a minus sign the "damping" would make the
matrix singular whenever mu reaches an eigenvalue of S S^T and reverse the update
beyond it; damped least squares (Levenberg, Nakamura) adds mu, so we do.

mu has units of S S^T, (rad per N m)^2, which depend on the rod; it is set relative to
the largest eigenvalue of S S^T (``damping``), so one default works for any rod.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from ..config.schema import OnlineSettings
from ..geometry import matrix_from_quat
from ..models import kernels
from ..params import DISTURBANCE_MOMENT_NAMES, PARAMETER_SCALES, ModelParameters, with_parameters
from ..sensitivity import DEFAULT_RELATIVE_STEP, disturbance_columns

if TYPE_CHECKING:
    from ..models.shooting import ShootingModel, Solution


@dataclass(frozen=True)
class EstimateStep:
    """One step of the estimator.

    error_before_deg / error_after_deg: angle between predicted and measured tip-relative-
    to-base orientation before the first and after the last update of this step.
    disturbance_moment_nm: the estimate after this step (tip frame, N m).
    solution: the model's shape with that estimate (the "Proposed" prediction).
    """

    error_before_deg: float
    error_after_deg: float
    iterations: int
    disturbance_moment_nm: np.ndarray
    solution: Solution


class OnlineDisturbanceEstimator:
    """Tracks w_d|m from a stream of (jet forces, measured orientation) pairs.

    params: the calibrated parameters; their w_d is the starting estimate. Only the
    moment is updated, as in the paper; the calibrated force stays. The estimate is
    applied to the packed problem rather than to ``params``, so the model keeps reusing
    its packing between updates (rebuilding it would cost more than the update).
    """

    def __init__(self, model: ShootingModel, params: ModelParameters,
                 settings: OnlineSettings = OnlineSettings()) -> None:
        self.model = model
        self.settings = settings
        self.params = params
        self._moment = np.array(params.disturbance.moment_nm, dtype=float)
        self._previous: Solution | None = None

    @property
    def disturbance_moment_nm(self) -> np.ndarray:
        """The current estimate of w_d|m, tip frame, N m."""
        return self._moment.copy()

    def current_params(self) -> ModelParameters:
        """The calibrated parameters with the current moment estimate."""
        return with_parameters(self.params, dict(zip(DISTURBANCE_MOMENT_NAMES, self._moment)))

    def reset(self, params: ModelParameters | None = None, previous: Solution | None = None) -> None:
        """Restart: from ``params``' disturbance if given, and from the path state of
        ``previous`` (the last shape of a session being resumed) or from none."""
        if params is not None:
            self.params = params
            self._moment = np.array(params.disturbance.moment_nm, dtype=float)
        self._previous = previous

    def update(self, jet_forces_n, measured_tip_in_base_sensor: np.ndarray, *,
               gravity_in_base_m_s2=None, iterations: int | None = None) -> EstimateStep:
        """Correct the estimate with one measurement.

        measured_tip_in_base_sensor: 3x3 rotation of the tip sensor in the base sensor's
            frame, or a quaternion (w, x, y, z).
        gravity_in_base_m_s2: gravity in the base frame now, when the base moves.
        iterations: override ``settings.iterations`` (per-sample mode passes 1).
        """
        measured = np.asarray(measured_tip_in_base_sensor, dtype=float)
        if measured.shape == (4,):
            measured = matrix_from_quat(measured)
        if gravity_in_base_m_s2 is not None and tuple(gravity_in_base_m_s2) != self.params.gravity_in_base_m_s2:
            self.params = replace(self.params, gravity_in_base_m_s2=tuple(gravity_in_base_m_s2))
        budget = self.settings.iterations if iterations is None else iterations
        packed = self.model.prepare(jet_forces_n, self.params, self._previous)
        prepared = packed.with_disturbance_moment(self._moment)
        solution = self.model.solve_prepared(prepared, self._previous)
        omega = np.empty(3)
        error_before = error = self._error_deg(solution, measured, omega)
        done = 0
        while done < budget and error > self.settings.tolerance_deg:
            steps = DEFAULT_RELATIVE_STEP * np.maximum(np.abs(self._moment), _MOMENT_SCALES)
            columns, seed = disturbance_columns(self.model, prepared, solution, _MOMENT_COMPONENTS, steps)
            matrix = np.ascontiguousarray(columns[3:])
            # omega_des is in the tip sensor's frame; the sensitivity in the rod tip's.
            change = _damped_least_squares(matrix, solution.tip_sensor_mounting @ omega, self.settings.damping,
                                           self.settings.gain)
            self._moment = self._moment + change
            prepared = packed.with_disturbance_moment(self._moment)
            # The same columns predict where the tip turns: the solve starts there.
            solution = self.model.solve_prepared(prepared, seed, predicted_tip_turn_rad=matrix @ change)
            error = self._error_deg(solution, measured, omega)
            done += 1
        self._previous = solution
        return EstimateStep(error_before, error, done, self._moment.copy(), solution)

    @staticmethod
    def _error_deg(solution: Solution, measured: np.ndarray, omega: np.ndarray) -> float:
        """Angle (deg) from predicted to measured; writes the rotation vector (rad, tip
        sensor frame) into ``omega``."""
        return math.degrees(kernels.relative_rotation_vector(solution.tip_sensor_in_base_sensor(), measured, omega))


@njit(cache=True, nogil=True)
def _damped_least_squares(matrix, omega, damping, gain):
    """gain S^T (S S^T + mu I)^-1 omega with mu = damping * the largest eigenvalue of S S^T
    (eq. 4 with the damping's sign corrected, see the module docstring); one kernel
    call, as numpy's small-matrix calls cost more than the solve."""
    gram = matrix @ matrix.T
    mu = damping * np.linalg.eigvalsh(gram)[-1]
    return gain * (matrix.T @ np.linalg.solve(gram + mu * np.eye(gram.shape[0]), omega))


_MOMENT_COMPONENTS = np.array([3, 4, 5], dtype=np.int64)
_MOMENT_SCALES = np.array([PARAMETER_SCALES[name] for name in DISTURBANCE_MOMENT_NAMES])
