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
from ..errors import ConvergenceError
from ..geometry import matrix_from_quat
from ..models import kernels
from ..models.shooting import seeds_kernel
from ..params import DISTURBANCE_MOMENT_NAMES, PARAMETER_SCALES, ModelParameters, with_parameters
from ..sensitivity import DEFAULT_RELATIVE_STEP, disturbance_columns

if TYPE_CHECKING:
    from ..models.shooting import PreparedProblem, ShootingModel, Solution


@dataclass(frozen=True)
class EstimateStep:
    """One step of the estimator.

    error_before_deg / error_after_deg: angle between predicted and measured tip-relative-
    to-base orientation before the first and after the last update of this step.
    disturbance_moment_nm: the estimate after this step (tip frame, N m).
    solution: the model's shape with that estimate (the "Proposed" prediction).
    fallback: what the estimator did instead when the model could not be solved with the
    carried estimate or with a correction (`_update`; "" if nothing went wrong).
    """

    error_before_deg: float
    error_after_deg: float
    iterations: int
    disturbance_moment_nm: np.ndarray
    solution: Solution
    fallback: str = ""


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
        if measured.shape != (3, 3):
            raise ValueError(f"measured_tip_in_base_sensor must be a 3x3 rotation or a quaternion (w, x, y, z), "
                             f"got shape {measured.shape}")
        if gravity_in_base_m_s2 is not None and tuple(gravity_in_base_m_s2) != self.params.gravity_in_base_m_s2:
            self.params = replace(self.params, gravity_in_base_m_s2=tuple(gravity_in_base_m_s2))
        budget = self.settings.iterations if iterations is None else iterations
        packed = self.model.prepare(jet_forces_n, self.params, self._previous)
        step = self._update_in_kernel(packed, measured, budget)
        if step is None:
            step = self._update(packed, measured, budget)
        self._moment = step.disturbance_moment_nm.copy()
        self._previous = step.solution
        return step

    def _update_in_kernel(self, packed: PreparedProblem, measured: np.ndarray, budget: int) -> EstimateStep | None:
        """`_update` in one kernel call (`_update_kernel`), bit for bit: the Python around
        each solve and sensitivity costs more than they do. None when the last step left
        nothing to start from or a solve inside did not finish (`_update` then takes the
        model's whole solve path)."""
        previous = self._previous
        if not seeds_kernel(previous):
            return None
        model = self.model
        work = model.workspace(packed)
        moment = self._moment.copy()
        work.jacobian[:] = previous.jacobian
        errors_deg = np.empty(2)
        done = _update_kernel(model.kind, model.resolution, model.tolerance, model.max_iterations, packed.profile,
                              packed.tip, packed.base, packed.beta, packed.length_m, packed.wrench_scale,
                              packed.moment_scale_nm, np.array(self.params.disturbance.moment_nm), moment,
                              previous.rotations_in_base[-1].copy(), work.jacobian,
                              np.ascontiguousarray(measured), packed.problem.base_sensor_mounting,
                              packed.problem.tip_sensor_mounting, budget, self.settings.tolerance_deg,
                              self.settings.damping, self.settings.gain, work.nodes_p, work.nodes_r, work.base_wrench,
                              work.clamp_rotation, work.info, errors_deg)
        if done < 0:
            return None
        return EstimateStep(float(errors_deg[0]), float(errors_deg[1]), int(done), moment,
                            model.solution_from(packed, work))

    def _update(self, packed: PreparedProblem, measured: np.ndarray, budget: int) -> EstimateStep:
        """One update through the model's own solve path (cold start, ramping if need be).

        An estimate carried from the last step can load the rod beyond what the model
        solves under this step's jets (a heavy rod near a fold): the step then starts
        again from the calibrated w_d. A correction the model cannot solve is not made:
        the step keeps the estimate before it. Either is said in ``fallback``."""
        moment = self._moment
        fallback = ""
        try:
            prepared = packed.with_disturbance_moment(moment)
            solution = self.model.solve_prepared(prepared, self._previous)
        except ConvergenceError:
            calibrated = np.array(self.params.disturbance.moment_nm, dtype=float)
            if np.array_equal(moment, calibrated):
                raise  # the calibrated model itself fails here: the caller's to report
            moment, prepared = calibrated, packed
            solution = self.model.solve_prepared(prepared, self._previous)
            fallback = "the carried estimate could not be solved: restarted from the calibrated w_d"
        omega = np.empty(3)
        error_before = error = self._error_deg(solution, measured, omega)
        done = 0
        change = np.empty(3)
        turn = np.empty(3)
        while done < budget and error > self.settings.tolerance_deg:
            steps = DEFAULT_RELATIVE_STEP * np.maximum(np.abs(moment), _MOMENT_SCALES)
            try:
                columns, seed = disturbance_columns(self.model, prepared, solution, _MOMENT_COMPONENTS, steps)
                _moment_change(np.ascontiguousarray(columns[3:]), omega, solution.tip_sensor_mounting,
                               self.settings.damping, self.settings.gain, change, turn)
                moved = moment + change
                corrected = packed.with_disturbance_moment(moved)
                # The same columns predict where the tip turns: the solve starts there.
                solved = self.model.solve_prepared(corrected, seed, predicted_tip_turn_rad=turn)
            except ConvergenceError:
                fallback = "; ".join(filter(None, (fallback, "a correction could not be solved: not made")))
                break
            moment, prepared, solution = moved, corrected, solved
            error = self._error_deg(solution, measured, omega)
            done += 1
        return EstimateStep(error_before, error, done, moment, solution, fallback)

    @staticmethod
    def _error_deg(solution: Solution, measured: np.ndarray, omega: np.ndarray) -> float:
        """Angle (deg) from predicted to measured; writes the rotation vector (rad, tip
        sensor frame) into ``omega``."""
        return math.degrees(kernels.relative_rotation_vector(solution.tip_sensor_in_base_sensor(), measured, omega))


@njit(cache=True, nogil=True)
def _largest_eigenvalue_symmetric3(a):
    """The largest eigenvalue of a symmetric 3x3 matrix, in closed form (the trigonometric
    solution of its characteristic cubic): numba's LAPACK call took about 4 us of an
    online update's 45, this takes a tenth of a microsecond."""
    off = a[0, 1] * a[0, 1] + a[0, 2] * a[0, 2] + a[1, 2] * a[1, 2]
    if off == 0.0:
        return max(a[0, 0], a[1, 1], a[2, 2])
    mean = (a[0, 0] + a[1, 1] + a[2, 2]) / 3.0
    b00, b11, b22 = a[0, 0] - mean, a[1, 1] - mean, a[2, 2] - mean
    spread = math.sqrt((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * off) / 6.0)
    # B = (A - mean I) / spread has entries of order one; det(B) / 2 is the cosine of
    # three times the angle.
    b00, b11, b22 = b00 / spread, b11 / spread, b22 / spread
    b01, b02, b12 = a[0, 1] / spread, a[0, 2] / spread, a[1, 2] / spread
    half_det = 0.5 * (b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02))
    angle = math.acos(min(1.0, max(-1.0, half_det))) / 3.0
    return mean + 2.0 * spread * math.cos(angle)


@njit(cache=True, nogil=True)
def _damped_least_squares(matrix, omega, damping, gain, out):
    """gain S^T (S S^T + mu I)^-1 omega into ``out``, with mu = damping * the largest
    eigenvalue of S S^T (eq. 4 with the damping's sign corrected, see the module
    docstring), for the 3x3 S of the moment columns. A singular system (S zero, no
    damping) gives no change, the limit of the formula."""
    gram = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            gram[i, j] = matrix[i, 0] * matrix[j, 0] + matrix[i, 1] * matrix[j, 1] + matrix[i, 2] * matrix[j, 2]
    mu = damping * _largest_eigenvalue_symmetric3(gram)
    for i in range(3):
        gram[i, i] += mu
    weights = np.empty(3)
    if not kernels.solve3(gram, omega, weights):
        weights[:] = 0.0
    for i in range(3):
        out[i] = gain * (matrix[0, i] * weights[0] + matrix[1, i] * weights[1] + matrix[2, i] * weights[2])


@njit(cache=True, nogil=True)
def _moment_change(matrix, omega, tip_sensor_mounting, damping, gain, change, turn):
    """The moment correction (N m, tip frame) for the error ``omega`` (rad, tip sensor
    frame) through the rotation rows ``matrix`` (3x3, rad per N m, rod tip frame) into
    ``change``, and where it turns the tip (``matrix @ change``, rad) into ``turn``.
    omega_des is measured in the tip sensor's frame, the sensitivity in the rod tip's:
    the mounting takes one to the other. Shared by both update paths so they agree bit
    for bit."""
    error_in_tip = np.empty(3)
    for i in range(3):
        error_in_tip[i] = (tip_sensor_mounting[i, 0] * omega[0] + tip_sensor_mounting[i, 1] * omega[1]
                           + tip_sensor_mounting[i, 2] * omega[2])
    _damped_least_squares(matrix, error_in_tip, damping, gain, change)
    for i in range(3):
        turn[i] = matrix[i, 0] * change[0] + matrix[i, 1] * change[1] + matrix[i, 2] * change[2]


@njit(cache=True, nogil=True)
def _update_kernel(kind, resolution, tolerance, max_iterations, profile, packed_tip, base, beta, length, wrench_scale,
                   moment_scale, params_moment, moment, reference, jacobian, measured,
                   base_sensor_mounting, tip_sensor_mounting, budget, tolerance_deg, damping, gain,
                   nodes_p, nodes_r, base_wrench, clamp_rotation, info, errors_deg):
    """`OnlineDisturbanceEstimator._update` from a warm start (``reference``, ``jacobian``:
    the last shape's tip frame and solver matrix) in one call: solve, then up to
    ``budget`` times sensitivity, correction and solve again. ``moment`` (N m) is
    updated in place; the last solve's shape is left in the node arrays and its matrix
    in ``jacobian``; ``errors_deg`` gets the error before and after. Returns the number
    of corrections, or -1 when a solve or a sensitivity did not finish."""
    tip = packed_tip.copy()
    for i in range(3):
        tip[kernels.TIP_FOLLOWER_MOMENT + i] = (packed_tip[kernels.TIP_FOLLOWER_MOMENT + i]
                                                + (moment[i] - params_moment[i]) / moment_scale)
    kernels.solve(kind, resolution, reference, jacobian, np.bool_(True), profile, tip, base, beta, 1.0, tolerance,
                  max_iterations, length, wrench_scale, nodes_p, nodes_r, base_wrench, clamp_rotation, info)
    if info[0] != kernels.CONVERGED:
        return -1
    tip_frame = nodes_r[nodes_r.shape[0] - 1]
    omega = np.empty(3)
    error = math.degrees(kernels.relative_rotation_vector(
        kernels.sensor_rotation(base_sensor_mounting, tip_frame, tip_sensor_mounting), measured, omega))
    errors_deg[0] = error
    # A writable copy: numba types a global array as read-only, a type of its own, and
    # would compile `tip_wrench_sensitivity` once more for it.
    components = _MOMENT_COMPONENTS.copy()
    steps = np.empty(3)
    columns = np.empty((6, 3))
    matrix = np.empty((3, 3))
    change = np.empty(3)
    turn = np.empty(3)
    done = 0
    while done < budget and error > tolerance_deg:
        for i in range(3):
            steps[i] = DEFAULT_RELATIVE_STEP * max(abs(moment[i]), _MOMENT_SCALES[i]) / moment_scale
        if not kernels.tip_wrench_sensitivity(kind, resolution, tip_frame, profile, tip, base, beta,
                                              components, steps, length, jacobian, columns):
            return -1
        for i in range(3):
            for j in range(3):
                matrix[i, j] = columns[3 + i, j] / moment_scale
        _moment_change(matrix, omega, tip_sensor_mounting, damping, gain, change, turn)
        for i in range(3):
            moment[i] = moment[i] + change[i]
            tip[kernels.TIP_FOLLOWER_MOMENT + i] = (packed_tip[kernels.TIP_FOLLOWER_MOMENT + i]
                                                    + (moment[i] - params_moment[i]) / moment_scale)
        start = kernels.turned(tip_frame, turn)
        kernels.solve(kind, resolution, start, jacobian, np.bool_(True), profile, tip, base, beta, 1.0, tolerance,
                      max_iterations, length, wrench_scale, nodes_p, nodes_r, base_wrench, clamp_rotation, info)
        if info[0] != kernels.CONVERGED:
            return -1
        error = math.degrees(kernels.relative_rotation_vector(
            kernels.sensor_rotation(base_sensor_mounting, tip_frame, tip_sensor_mounting), measured, omega))
        done += 1
    errors_deg[1] = error
    return done


_MOMENT_COMPONENTS = np.array([3, 4, 5], dtype=np.int64)
_MOMENT_SCALES = np.array([PARAMETER_SCALES[name] for name in DISTURBANCE_MOMENT_NAMES])
