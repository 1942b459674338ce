"""Calibration of model parameters on static poses (paper sec. V-B, eq. 24).

Eq. 24 scores each pose by the scalar product of the predicted and measured tip-
relative-to-base quaternions. We minimise the same discrepancy as a vector: the
rotation vector of R_pred^T R_meas (rad, tip sensor frame), whose squared norm is the
squared relative angle theta^2 and, for small errors, 8 (1 - |<q_pred, q_meas>|), i.e.
eight times Huynh's Phi_4 that the paper cites. A vector residual gives the
least-squares solver a Jacobian straight from the sensitivity matrix: for w_d, the
rotation rows of S, carried into the sensor frame by its mounting, with a minus sign.
Every other parameter may also change what the sensors read (a sensor-mounting effect
moves no part of the rod, so its tip twist is zero), so its column is the forward
difference of the residual itself, with the steps `sensitivity` uses; one parameter at
a time over all poses, which then share the model's packed problem.

Optional position term: when positions are measured, ``position_weight_rad_per_m``
turns each tip position error (base sensor frame, m) into residual radians: 1 rad per
mm (1000) makes a 1 mm miss count as much as a 57 degree one, far too much; the
default 10 rad/m makes 1 mm weigh like 0.57 degrees, close to the EM tracker's
0.48 mm / 0.70 deg accuracy ratio. The tip sensor is taken at the rod tip unless a pose
gives the point it was measured at (`CalibrationPose.position_offset_in_tip_m`).

Standard errors come from J^T J at the optimum scaled by the residual variance; pairs of
parameters whose correlation exceeds 0.99 in magnitude are reported as unidentifiable.

Path dependence: a clamp with play (`RodProblem.depends_on_previous_state`) makes each
pose depend on the ones before it. By default poses are independent and each solve is
only warm-started from the last; with ``follow_path=True`` the poses are taken as one
recorded path in time order and each solve carries the previous pose's state
(``previous=``), as the rig did. Poses outside ``fitted`` are then solved to carry that
state across, without entering the fit. Without path state both give the same numbers.
With it, every Jacobian column is a forward difference along the whole perturbed path:
a parameter also acts on later poses through the clamp state it leaves behind, which a
per-pose sensitivity misses (and a fit guided by it stalls far from the optimum).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares

from ..data.dataset import Dataset
from ..effects import CALIBRATION_POSES, SWEEPS, Effect, EffectParameter, identifying_rows
from ..effects.base import at_physical_limits
from ..errors import ConvergenceError
from ..geometry import body_rotation_error, matrix_from_quat
from ..models import make_model
from ..models.shooting import (ShootingModel, Solution, tip_sensor_positions_in_base_sensor_m,
                               tip_sensors_in_base_sensor)
from ..params import DISTURBANCE_NAMES, PARAMETER_NAMES, ModelParameters, get_parameter, with_parameters
from ..sensitivity import (DEFAULT_RELATIVE_STEP, disturbance_columns_batch, effect_parameter, parameter_scale,
                           parameter_steps)

# Physical bounds of the core parameters; effect parameters carry their own.
CORE_BOUNDS: dict[str, tuple[float, float]] = {
    "E0": (1e3, 1e8), "EL": (1e3, 1e8), "L": (0.005, 1.0),
    "wd_fx": (-1.0, 1.0), "wd_fy": (-1.0, 1.0), "wd_fz": (-1.0, 1.0),
    "wd_mx": (-0.1, 0.1), "wd_my": (-0.1, 0.1), "wd_mz": (-0.1, 0.1),
}
CORRELATION_WARNING = 0.99
# Converged: the projected gradient of chi^2 per parameter scale is at most this, chi^2
# taking the residual variance (or the noise variance, when known and larger) as the
# noise: a Newton step would then gain less than 0.25 in chi^2.
GRADIENT_TOLERANCE = 1.0
# The least noise that judgement assumes: data a model fits to within a hundredth of a
# degree (no sensor here resolves that) leave no noise to measure the gradient against.
NEGLIGIBLE_RESIDUAL_RAD = np.radians(1e-2)
# A fitted value within this share of its bounds' span (of their logarithms, for bounds
# three or more decades apart) from a bound sits on it.
BOUND_SHARE = 1e-3
# `CalibrationResult.off_branch`: the poses solved afresh at the result cost more than this
# times what the fit reached (one equilibrium found twice costs the same to 1e-10).
OFF_BRANCH_COST_RATIO = 1.5
DEFAULT_POSITION_WEIGHT_RAD_PER_M = 10.0


@dataclass(frozen=True)
class CalibrationPose:
    """One static pose: jet forces (N), the measured tip sensor orientation in the base
    sensor's frame (3x3), gravity in the base frame then (m/s^2), and optionally the
    measured tip position in the base sensor frame (m), taken at the point
    ``position_offset_in_tip_m`` of the tip frame (m; None: the rod tip itself). Giving
    the tip sensor's own origin and offset compares what the tracker measured directly,
    rather than a rod tip reconstructed with the measured orientation (which an unknown
    sensor mounting rotation would move)."""

    jet_forces_n: np.ndarray
    measured_tip_in_base_sensor: np.ndarray
    gravity_in_base_m_s2: tuple[float, float, float]
    tip_position_in_base_sensor_m: np.ndarray | None = None
    position_offset_in_tip_m: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class CalibrationResult:
    """params: calibrated parameters. names/values/standard_errors: the fitted ones.
    correlation: their correlation matrix. unidentifiable: pairs with |corr| > 0.99.
    rms_orientation_deg: RMS relative angle over the poses before and after.
    scaled_gradient_norm: largest component of the projected gradient of the cost
    (half the sum of squared residuals) per parameter scale (`parameter_scale`) at the
    result: zero at an optimum, bounds respected. stop_reason: why the fit stopped.
    relative_gradient: the same gradient of chi^2 (the residual variance, or
    ``variance_floor`` if larger, as the noise); converged: it is at most
    `GRADIENT_TOLERANCE` and the fit is not `off_branch`. at_bound: fitted parameters that
    sit on a bound other than their no-effect default (`BOUND_SHARE`): the data push them
    past the range they may take. The errors after are those of the poses solved afresh
    at the result (from the straight rod, in the poses' order), as every prediction
    solves them. off_branch: there they settle on other equilibria than the fit followed
    from evaluation to evaluation, and fit the data far worse than the fit saw
    (`rms_orientation_deg_followed`), or cannot be solved: the optimum is one the rod
    does not reach. poses: how many poses were fitted."""

    params: ModelParameters
    names: tuple[str, ...]
    values: np.ndarray
    standard_errors: np.ndarray
    correlation: np.ndarray
    unidentifiable: tuple[tuple[str, str, float], ...]
    rms_orientation_deg_before: float
    rms_orientation_deg_after: float
    evaluations: int
    scaled_gradient_norm: float = float("nan")
    stop_reason: str = ""
    relative_gradient: float = float("nan")
    converged: bool = False
    at_bound: tuple[str, ...] = ()
    off_branch: bool = False
    rms_orientation_deg_followed: float | None = None
    poses: int = 0

    @property
    def branch_note(self) -> str:
        """For an `off_branch` fit, what a fresh solve found, in words ("; ..."); else ""."""
        if not self.off_branch:
            return ""
        fresh = ("a fresh solve fails" if self.rms_orientation_deg_followed is None else
                 f"solved afresh, the poses settle on other equilibria than the fit followed (RMS "
                 f"{self.rms_orientation_deg_after:.2f} deg where the fit saw {self.rms_orientation_deg_followed:.2f})")
        return f"; {fresh}: the rod does not reach this optimum"

    @property
    def convergence(self) -> str:
        """Whether the fit converged and why, in words."""
        verdict = "converged" if self.converged else "NOT converged"
        return (f"{verdict}: {self.stop_reason} after {self.evaluations} evaluations, scaled gradient "
                f"{self.relative_gradient:.2g} (tolerance {GRADIENT_TOLERANCE:g}){self.branch_note}")


DEFAULT_NAMES = PARAMETER_NAMES  # E0, EL, L and the six components of w_d: nine parameters


def parameter_bounds(model: ShootingModel, name: str) -> tuple[float, float]:
    if name in CORE_BOUNDS:
        return CORE_BOUNDS[name]
    parameter: EffectParameter | None = effect_parameter(model, name)
    if parameter is None:
        raise KeyError(f"parameter {name!r} belongs to no enabled effect of {model!r}")
    return parameter.lower, parameter.upper


class TooFewPoses(ValueError):
    """Fewer residuals than parameters: the fit is not even attempted."""


def determinable(poses: int, parameters: int, with_positions: bool) -> bool:
    """Whether ``poses`` give more residuals (3 orientation rows each, 3 more with tip
    positions) than ``parameters``: the least a fit must have to be attempted."""
    return poses * (6 if with_positions else 3) > parameters


def calibrate(model: ShootingModel, poses: Sequence[CalibrationPose], initial: ModelParameters,
              names: Sequence[str] = DEFAULT_NAMES, *,
              position_weight_rad_per_m: float = DEFAULT_POSITION_WEIGHT_RAD_PER_M,
              max_evaluations: int = 100, follow_path: bool = False,
              fitted: Sequence[bool] | None = None, cost_tolerance: float = 1e-10,
              gradient_tolerance: float | None = None, variance_floor: float = 0.0) -> CalibrationResult:
    """Fit ``names`` to the poses by bounded nonlinear least squares, starting from
    ``initial``: scipy's dogbox (a dogleg step in a box-shaped trust region) for
    independent poses, its trust region reflective method along a path. Raises
    ValueError for too few poses.

    follow_path: the poses are one recorded path, in time order: every solve gets the
        pose before it as ``previous=`` (path state), not only as a warm start.
    fitted: which poses enter the fit (default all); the others are only solved to carry
        the path state, so they need ``follow_path``.
    cost_tolerance: the fit stops once a step lowers the cost by less than this fraction
        (least_squares' ftol; its xtol and gtol stay at 1e-10).
    gradient_tolerance: also stop once the scaled projected gradient (see
        `CalibrationResult.scaled_gradient_norm`) is at most this times the residual
        variance (the mean squared residual, or ``variance_floor`` if larger: the noise
        variance where it is known), i.e. in the units of chi^2 / 2.

    The solver works in scaled variables x / `parameter_scale`, so its step and
    gradient tests weigh every parameter alike (in raw units E0 ~ 3e5 Pa would
    dominate every norm).
    """
    names = tuple(names)
    fit_mask = np.ones(len(poses), dtype=bool) if fitted is None else np.asarray(fitted, dtype=bool)
    if fit_mask.shape != (len(poses),):
        raise ValueError(f"fitted has {fit_mask.size} entries for {len(poses)} poses")
    if not follow_path and not fit_mask.all():
        raise ValueError("poses left out of the fit only carry path state: pass follow_path=True")
    fitted_indices = np.flatnonzero(fit_mask)
    use_positions = position_weight_rad_per_m > 0 and all(
        poses[index].tip_position_in_base_sensor_m is not None for index in fitted_indices)
    rows_per_pose = 6 if use_positions else 3
    if not determinable(len(fitted_indices), len(names), use_positions):
        raise TooFewPoses(f"{len(fitted_indices)} pose{'' if len(fitted_indices) == 1 else 's'} cannot determine "
                          f"{len(names)} parameters")
    bounds = np.array([parameter_bounds(model, name) for name in names]).T
    scales = np.array([parameter_scale(model, name) for name in names])
    start = np.array([get_parameter(initial, name, _default(model, name)) for name in names])
    start = np.clip(start, bounds[0], bounds[1])
    # Poses recorded under the same gravity share one parameter object per evaluation, so
    # the model reuses its packed problem between them instead of rebuilding it.
    gravities = [tuple(pose.gravity_in_base_m_s2) for pose in poses]
    distinct = list(dict.fromkeys(gravities))
    gravity_group = [distinct.index(gravity) for gravity in gravities] if len(distinct) > 1 else [0] * len(poses)
    measured = np.array([poses[index].measured_tip_in_base_sensor for index in fitted_indices])
    measured_positions = (np.array([poses[index].tip_position_in_base_sensor_m for index in fitted_indices])
                          if use_positions else None)
    offsets = np.array([poses[index].position_offset_in_tip_m or (0.0, 0.0, 0.0) for index in fitted_indices])
    disturbance_indices = [column for column, name in enumerate(names) if name in DISTURBANCE_NAMES]
    jet_forces = np.array([pose.jet_forces_n for pose in poses], dtype=float).reshape(len(poses), 3)
    cache: dict[bytes, tuple[np.ndarray, list[Solution], list[ModelParameters]]] = {}
    # Each pose's solution at the last evaluated parameters: the optimiser moves them a
    # little per evaluation, so they seed the next solves far better than the previous
    # pose (other jet forces) does. On a rod with several equilibria they may carry the
    # poses onto a branch no fresh solve reaches: the fit's end checks that.
    last: list[Solution | None] = [None] * len(poses)
    # Set after a fit that ended off its branch (`CalibrationResult.off_branch`): then
    # every evaluation solves afresh, as predictions do, at the cost of slower solves.
    fresh_only = [False]
    unsolved_steps = [0]
    restarted = [False]

    def parameters_at(x: np.ndarray) -> list[ModelParameters]:
        fitted_params = with_parameters(initial, dict(zip(names, x)))
        by_gravity = [replace(fitted_params, gravity_in_base_m_s2=gravity) for gravity in distinct]
        return [by_gravity[group] for group in gravity_group]

    def residual_rows(solutions: Sequence[Solution]) -> np.ndarray:
        """(fitted poses, rows_per_pose) residuals of solutions at the fitted poses."""
        rows = np.empty((len(solutions), rows_per_pose))
        rows[:, :3] = body_rotation_error(tip_sensors_in_base_sensor(solutions), measured)
        if measured_positions is not None:
            positions = tip_sensor_positions_in_base_sensor_m(solutions, offsets)
            rows[:, 3:] = position_weight_rad_per_m * (positions - measured_positions)
        return rows

    def solve_poses(rows: Sequence[int], params: list[ModelParameters], warm_starts: Sequence[Solution | None],
                    along_path: bool) -> list[Solution]:
        """Solve poses ``rows`` in order, each under its own parameters (its gravity) from
        its warm start or else the pose solved before it, in one `solve_batch`."""
        rows = list(rows)
        return model.solve_batch(jet_forces[rows], [params[row] for row in rows], warm_starts, None,
                                 along_path=along_path)

    def evaluate(x: np.ndarray) -> tuple[np.ndarray, list[Solution], list[ModelParameters]]:
        key = x.tobytes()
        if key not in cache:
            params = parameters_at(x)
            solutions = solve_poses(range(len(poses)), params, [None] * len(poses) if fresh_only[0] else last,
                                    follow_path)
            last[:] = solutions
            residuals = residual_rows([solutions[index] for index in fitted_indices]).ravel()
            cache.clear()  # only the latest point is asked for again (by the Jacobian)
            cache[key] = (residuals, solutions, params)
        return cache[key]

    def residual(x: np.ndarray) -> np.ndarray:
        try:
            return evaluate(x)[0]
        except ConvergenceError:
            if last[0] is None:  # the start itself: there is no solved point to fall back on
                raise
            # A trial step the model cannot solve (a soft rod folding under a heavy load,
            # say): non-finite residuals make the trust-region solver shorten the step.
            unsolved_steps[0] += 1
            return np.full(len(fitted_indices) * rows_per_pose, np.nan)

    def jacobian(x: np.ndarray) -> np.ndarray:
        residuals, solutions, params = evaluate(x)
        matrix = np.empty((len(fitted_indices) * rows_per_pose, len(names)))
        # On a path with state (a clamp with play) a parameter changes every later pose
        # through the state it leaves behind: differentiate along the whole perturbed path.
        along_path = follow_path and model.build_problem(poses[0].jet_forces_n, params[0]).depends_on_previous_state
        batched = [] if along_path else disturbance_indices
        # Seeds for the perturbed solves below: the nominal solutions with the accurate
        # Jacobian the w_d columns leave behind converge in 2 iterations instead of 4-5.
        seeds = list(solutions)
        if batched:
            wanted = [names[column] for column in batched]
            components = np.array([DISTURBANCE_NAMES.index(name) for name in wanted], dtype=np.int64)
            # w_d is fitted, so every pose has the same value and the same steps.
            steps = parameter_steps(model, params[0], wanted)
            # No pose here takes its history: along a path with state ``batched`` is empty.
            by_pose, fitted_seeds = disturbance_columns_batch(
                model, jet_forces[fitted_indices], [params[index] for index in fitted_indices],
                [solutions[index] for index in fitted_indices], components, steps)
            for index, seed in zip(fitted_indices, fitted_seeds):
                seeds[index] = seed
            fitted_solutions = [solutions[index] for index in fitted_indices]
            block = np.empty((len(fitted_indices), rows_per_pose, len(batched)))
            # d(log(R_pred^T R_meas))/dzeta = -(tip sensor mounting)^T S_rot, to first order.
            tip_mounting = np.array([solution.tip_sensor_mounting for solution in fitted_solutions])
            block[:, :3] = -np.swapaxes(tip_mounting, 1, 2) @ by_pose[:, 3:]
            if use_positions:
                # A point o of the tip frame moves by R_tip (v + omega x o) for a body twist (v, omega).
                moved = by_pose[:, :3] + np.cross(by_pose[:, 3:], offsets[:, :, np.newaxis], axis=1)
                base_mounting = np.array([solution.base_sensor_mounting for solution in fitted_solutions])
                tip_rotation = np.array([solution.rotations_in_base[-1] for solution in fitted_solutions])
                block[:, 3:] = position_weight_rad_per_m * (np.swapaxes(base_mounting, 1, 2) @ tip_rotation @ moved)
            matrix[:, batched] = block.reshape(len(fitted_indices) * rows_per_pose, len(batched))
        # Other parameters may change the shape, the sensor mountings or both: forward
        # differences of the residual itself, one parameter at a time over all poses (which
        # then share one packed problem), with the steps `sensitivity` uses.
        for column in (column for column in range(len(names)) if column not in batched):
            step = DEFAULT_RELATIVE_STEP * max(abs(x[column]), scales[column])
            if x[column] + step > bounds[1][column]:
                step = -step
            shifted = x.copy()
            shifted[column] += step
            perturbed_params = parameters_at(shifted)
            if along_path:
                perturbed = solve_poses(range(len(poses)), perturbed_params, solutions, True)
                perturbed = [perturbed[index] for index in fitted_indices]
            else:
                # Path state is followed only along_path: no pose here depends on the one before it.
                perturbed = solve_poses(fitted_indices, perturbed_params, [seeds[index] for index in fitted_indices],
                                        False)
            matrix[:, column] = (residual_rows(perturbed).ravel() - residuals) / step
        return matrix

    # z = (x - start) / scale + 1: one unit per parameter scale, and the start at 1 (not
    # 0) so that the solver's first trust region (|z0|) spans one scale per parameter.
    offset = start / scales - 1.0
    scaled_bounds = (bounds[0] / scales - offset, bounds[1] / scales - offset)
    latest_jacobian: dict[bytes, np.ndarray] = {}

    def scaled_jacobian(z: np.ndarray) -> np.ndarray:
        latest_jacobian.clear()
        latest_jacobian[z.tobytes()] = jacobian((z + offset) * scales) * scales
        return latest_jacobian[z.tobytes()]

    def projected_gradient(z: np.ndarray, rows: np.ndarray, matrix: np.ndarray) -> float:
        # |z - clip(z - g)|: the gradient, less any part pushing out through a bound.
        gradient = matrix.T @ rows
        return float(np.max(np.abs(z - np.clip(z - gradient, *scaled_bounds)), initial=0.0))

    def relative_gradient_of(z: np.ndarray, rows: np.ndarray, matrix: np.ndarray) -> float:
        """The convergence test's figure (`CalibrationResult.relative_gradient`) at ``z``."""
        return 2.0 * projected_gradient(z, rows, matrix) / max(variance_floor, float(rows @ rows) / rows.size,
                                                                NEGLIGIBLE_RESIDUAL_RAD**2)

    def stop_at_gradient(intermediate_result) -> None:  # scipy picks the signature by this name
        z = intermediate_result.x
        matrix = latest_jacobian.get(z.tobytes())
        rows = intermediate_result.fun
        variance = max(variance_floor, float(rows @ rows) / rows.size)
        if matrix is not None and projected_gradient(z, rows, matrix) <= gradient_tolerance * variance:
            raise StopIteration

    # Independent poses: dogbox. The fit has a narrow valley (E0, L and a force of w_d
    # correlate to 0.99); trust region reflective crawled along it, its trust region
    # holding each step to a fraction of a Gauss-Newton step that predicted the remaining
    # gain well, and dogbox got through in fewer evaluations (README, Speed). Along a
    # path (diagnosis fits, sweeps) trust region reflective stays: there a clamp's play
    # makes the cost piecewise smooth, and dogbox left such a fit unconverged after 115
    # evaluations where trust region reflective converged.
    def least_squares_run(z_start: np.ndarray, evaluations: int):
        return least_squares(lambda z: residual((z + offset) * scales), z_start,
                             jac=scaled_jacobian, method="trf" if follow_path else "dogbox",
                             bounds=scaled_bounds, max_nfev=evaluations, xtol=1e-10, ftol=cost_tolerance,
                             gtol=1e-10, callback=None if gradient_tolerance is None else stop_at_gradient)

    def least_squares_fit():
        fit = least_squares_run(np.ones(len(names)), max_evaluations)
        restarted[0] = False
        if (fit.status in _STALLED and fit.nfev < max_evaluations
                and relative_gradient_of(fit.x, fit.fun, fit.jac) > GRADIENT_TOLERANCE):
            # Steps shrunk below xtol (or a stalled cost) with the gradient test unmet: the
            # trust region was lost on the way along the narrow valley (E0, L, w_d's force),
            # not the optimum. A jet ring turned 0.3 rad stopped so with a scaled gradient of
            # 1.9 in L, one Gauss-Newton step short; a restart from there, with a fresh trust
            # region, took it (the gradient fell to 0, the cost changed by 1e-10 of itself).
            # It is kept unless it costs more than rounding: solves converged to 1e-10 leave
            # the cost uncertain in about its tenth digit (the restart above: +1e-10 of it).
            again = least_squares_run(fit.x, max_evaluations - fit.nfev)
            again.nfev += fit.nfev
            if again.cost <= fit.cost * (1.0 + SAME_COST):
                fit = again
                restarted[0] = True
            else:
                fit.nfev = again.nfev
        return fit

    def fresh_residuals(values: np.ndarray) -> np.ndarray | None:
        """The residuals at ``values`` solved afresh (None when a solve fails)."""
        try:
            solutions = solve_poses(range(len(poses)), parameters_at(values), [None] * len(poses), follow_path)
        except ConvergenceError:
            return None
        return residual_rows([solutions[index] for index in fitted_indices]).ravel()

    def off_its_branch(fitted: np.ndarray, fresh: np.ndarray | None) -> bool:
        # A margin of the noise variance per residual keeps noise-level differences
        # (another solver path to one equilibrium) from counting.
        return fresh is None or float(fresh @ fresh) > (OFF_BRANCH_COST_RATIO * float(fitted @ fitted) + fresh.size
                                                        * max(variance_floor, NEGLIGIBLE_RESIDUAL_RAD**2))

    def checked_fit():
        """The fit, its values, and the residuals there solved afresh, as every prediction
        will solve them (the result's errors), with whether they leave the fit's branch."""
        fit = least_squares_fit()
        values = (fit.x + offset) * scales
        fresh = fresh_residuals(values)
        return fit, values, fresh, off_its_branch(fit.fun, fresh)

    try:
        before = residual(start)
        fit, values, fresh, off_branch = checked_fit()
    except ConvergenceError as error:
        raise ConvergenceError(f"calibration stopped: a model solve failed ({error})") from error
    evaluations = int(fit.nfev)
    refitted = ""
    if off_branch:
        # Again from the start, every evaluation solved afresh: the optimum predictions reach.
        fresh_only[0] = True
        cache.clear()
        fit, values, fresh, off_branch = checked_fit()
        evaluations += int(fit.nfev)
        refitted = "; refitted solving every pose afresh (the first fit followed equilibria the rod does not reach)"
    final = fit.fun if fresh is None else fresh
    dof = max(final.size - len(names), 1)
    variance = float(final @ final) / dof
    # In scaled variables: the raw columns span ~15 decades (rad per Pa vs per N m), and
    # a pseudo-inverse of the raw J^T J would discard the small ones as rank-deficient.
    scaled = fit.jac
    covariance = variance * np.linalg.pinv(scaled.T @ scaled) * np.outer(scales, scales)
    standard_errors = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        correlation = covariance / np.outer(standard_errors, standard_errors)
    correlation = np.nan_to_num(correlation)
    unidentifiable = tuple(
        (names[i], names[j], float(correlation[i, j]))
        for i in range(len(names)) for j in range(i + 1, len(names))
        if abs(correlation[i, j]) > CORRELATION_WARNING)
    gradient = projected_gradient(fit.x, final, fit.jac)
    relative_gradient = relative_gradient_of(fit.x, final, fit.jac)
    return CalibrationResult(
        params=with_parameters(initial, dict(zip(names, values))),
        names=names, values=values, standard_errors=standard_errors, correlation=correlation,
        unidentifiable=unidentifiable,
        rms_orientation_deg_before=_rms_angle_deg(before, rows_per_pose),
        rms_orientation_deg_after=_rms_angle_deg(final, rows_per_pose),
        evaluations=evaluations,
        scaled_gradient_norm=gradient,
        stop_reason=_STOP_REASONS.get(fit.status, fit.message) + (
            f"; {unsolved_steps[0]} trial step(s) the model could not solve were shortened"
            if unsolved_steps[0] else "") + ("; restarted once where its steps had stalled" if restarted[0] else "")
        + refitted,
        relative_gradient=relative_gradient,
        converged=bool(relative_gradient <= GRADIENT_TOLERANCE) and not off_branch,
        off_branch=off_branch,
        rms_orientation_deg_followed=_rms_angle_deg(fit.fun, rows_per_pose) if off_branch and fresh is not None
        else None,
        at_bound=tuple(name for name, value, lower, upper in zip(names, values, *bounds)
                       if on_bound(value, lower, upper, _default(model, name))),
        poses=len(fitted_indices),
    )


def on_bound(value: float, lower: float, upper: float, default: float | None = None) -> bool:
    """Whether ``value`` sits on ``lower`` or ``upper`` (`BOUND_SHARE`), a bound equal to
    the parameter's no-effect ``default`` not counting (an effect fitted away)."""
    if lower > 0.0 and upper >= 1e3 * lower:
        value, lower, upper, default = (np.log(max(value, lower)), np.log(lower), np.log(upper),
                                        None if default is None or default <= 0.0 else np.log(default))
    margin = BOUND_SHARE * (upper - lower)
    return any(abs(value - bound) <= margin and bound != default for bound in (lower, upper))


# Two costs closer than this share are the same to the solver's rounding (shapes to 1e-10).
SAME_COST = 1e-8
# least_squares' statuses of a stall: the cost (ftol), the step (xtol) or both.
_STALLED = (2, 3, 4)
_STOP_REASONS = {
    -2: "scaled projected gradient within tolerance", 0: "evaluation limit reached",
    1: "gradient below 1e-10", 2: "cost change below tolerance", 3: "step below 1e-10", 4: "cost and step stalled",
}


def calibration_poses(steps: Dataset) -> list[CalibrationPose]:
    """The dataset's rows as calibration poses (measured tip in base frame, gravity per row,
    positions when present)."""
    rotations = matrix_from_quat(steps.tip_orientation_in_base())
    positions = steps.tip_position_in_base_m()
    gravity = steps.gravity_in_base_m_s2()
    return [CalibrationPose(steps.jet_forces_n[i], rotations[i], tuple(gravity[i]),
                            None if positions is None else positions[i]) for i in range(len(steps))]


ALL_ROWS = "all"
# `calibrate --fit-on`: the calibration poses (sweep -1), the sweeps, or both.
FIT_ON = (CALIBRATION_POSES, SWEEPS, ALL_ROWS)


def rows_that_identify(effects: Sequence[Effect]) -> str:
    """The rows a calibration of ``effects`` fits by default: the calibration poses,
    unless one of them is identified only by sweeps (`Effect.identified_by`), then all."""
    return ALL_ROWS if any(identifying_rows(effect) == SWEEPS for effect in effects) else CALIBRATION_POSES


def fit_mask(steps: Dataset, fit_on: str) -> np.ndarray:
    """Which rows of ``steps`` a calibration on ``fit_on`` (one of `FIT_ON`) fits."""
    if fit_on == CALIBRATION_POSES:
        return steps.sweep == -1
    if fit_on == SWEEPS:
        return (steps.sweep >= 0) & steps.valid_mask()
    if fit_on == ALL_ROWS:
        return (steps.sweep == -1) | ((steps.sweep >= 0) & steps.valid_mask())
    raise ValueError(f"fit_on must be one of {', '.join(FIT_ON)}, got {fit_on!r}")


def calibrate_dataset(model: ShootingModel, steps: Dataset, initial: ModelParameters,
                      names: Sequence[str] = DEFAULT_NAMES, *, fit_on: str = CALIBRATION_POSES,
                      **options) -> CalibrationResult:
    """Calibrate on the dataset's rows that ``fit_on`` picks (`fit_mask`); ``options`` as
    `calibrate`. On the calibration poses alone they are independent poses, as the paper
    fits them; with sweeps the steps are one path in recorded order (``follow_path``), so
    a clamp with play sees loading and unloading as the rig did, and the rows not fitted
    before the last fitted one are solved to carry that path."""
    mask = fit_mask(steps, fit_on)
    if not mask.any():
        what = "calibration rows (sweep -1)" if fit_on == CALIBRATION_POSES else "sweep rows (sweep >= 0)"
        raise ValueError(f"{steps.source or 'dataset'} has no {what} to fit on")
    if fit_on == CALIBRATION_POSES:
        return calibrate(model, calibration_poses(steps.select(mask)), initial, names, **options)
    solved = slice(0, int(np.flatnonzero(mask)[-1]) + 1)
    return calibrate(model, calibration_poses(steps.select(np.arange(len(steps))[solved])), initial, names,
                     follow_path=True, fitted=mask[solved], **options)


@dataclass(frozen=True)
class WidenedCalibration:
    """`calibrate_widening`'s answer: the result kept, the model it was fitted with (the
    result's bounds are that model's), and the parameters whose search was widened."""

    result: CalibrationResult
    model: ShootingModel
    widened: tuple[str, ...] = ()


def calibrate_widening(model: ShootingModel, requested: Sequence[Effect], steps: Dataset,
                       initial: ModelParameters, names: Sequence[str], **options) -> WidenedCalibration:
    """`calibrate_dataset`; a fit whose ``requested`` effects' parameters end on a search
    bound is refitted from there with those effects searched up to their physical limits
    (`at_physical_limits`), as diagnose fits its candidates, so that a calibration
    delivers what diagnose found. The wider fit is kept when it converged or fits no
    worse."""
    result = calibrate_dataset(model, steps, initial, names, **options)
    wide = {effect.name: at_physical_limits(effect) for effect in requested
            if any(f"{effect.name}.{p.name}" in result.at_bound and p.limits != (p.lower, p.upper)
                   for p in effect.parameters)}
    if not wide:
        return WidenedCalibration(result, model)
    wider_model = make_model(model.name, tuple(wide.get(effect.name, effect) for effect in model.effects))
    wider = calibrate_dataset(wider_model, steps, result.params, names, **options)
    if wider.converged or wider.rms_orientation_deg_after <= result.rms_orientation_deg_after:
        return WidenedCalibration(wider, wider_model,
                                  tuple(name for name in result.at_bound if name.partition(".")[0] in wide))
    return WidenedCalibration(result, model)


def _default(model: ShootingModel, name: str) -> float | None:
    parameter = effect_parameter(model, name)
    return parameter.default if parameter is not None else None


def _rms_angle_deg(residuals: np.ndarray, rows_per_pose: int) -> float:
    rotation = residuals.reshape(-1, rows_per_pose)[:, :3]
    return float(np.degrees(np.sqrt(np.mean(np.sum(rotation**2, axis=1)))))
