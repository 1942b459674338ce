"""Calibration of model parameters on static poses (paper sec. V-B, eq. 24).

Eq. 24 scores each pose by the scalar product of the predicted and measured tip-
relative-to-base quaternions. We minimise the same discrepancy as a vector: the
rotation vector of R_pred^T R_meas (rad, tip sensor frame), whose squared norm is the
squared relative angle theta^2 and, for small errors, 8 (1 - |<q_pred, q_meas>|), i.e.
eight times Huynh's Phi_4 that the paper cites. A vector residual gives the
least-squares solver a Jacobian straight from the sensitivity matrix: the rotation rows
of S, carried into the sensor frame by its mounting, with a minus sign.

Optional position term: when positions are measured, ``position_weight_rad_per_m``
turns each tip position error (base sensor frame, m) into residual radians: 1 rad per
mm (1000) makes a 1 mm miss count as much as a 57 degree one, far too much; the
default 10 rad/m makes 1 mm weigh like 0.57 degrees, close to the EM tracker's
0.48 mm / 0.70 deg accuracy ratio. The tip sensor is taken at the rod tip.

Standard errors come from J^T J at the optimum scaled by the residual variance; pairs of
parameters whose correlation exceeds 0.99 in magnitude are reported as unidentifiable.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares

from ..effects import EffectParameter
from ..errors import ConvergenceError
from ..geometry import body_rotation_error
from ..models.shooting import ShootingModel, Solution
from ..params import PARAMETER_NAMES, ModelParameters, get_parameter, with_parameters
from ..sensitivity import effect_parameter, parameter_scale, sensitivity

# Physical bounds of the core parameters; effect parameters carry their own.
CORE_BOUNDS: dict[str, tuple[float, float]] = {
    "E0": (1e3, 1e8), "EL": (1e3, 1e8), "L": (0.005, 1.0),
    "wd_fx": (-1.0, 1.0), "wd_fy": (-1.0, 1.0), "wd_fz": (-1.0, 1.0),
    "wd_mx": (-0.1, 0.1), "wd_my": (-0.1, 0.1), "wd_mz": (-0.1, 0.1),
}
CORRELATION_WARNING = 0.99
DEFAULT_POSITION_WEIGHT_RAD_PER_M = 10.0


@dataclass(frozen=True)
class CalibrationPose:
    """One static pose: jet forces (N), the measured tip sensor orientation in the base
    sensor's frame (3x3), gravity in the base frame then (m/s^2), and optionally the
    measured tip position in the base sensor frame (m)."""

    jet_forces_n: np.ndarray
    measured_tip_in_base_sensor: np.ndarray
    gravity_in_base_m_s2: tuple[float, float, float]
    tip_position_in_base_sensor_m: np.ndarray | None = None


@dataclass(frozen=True)
class CalibrationResult:
    """params: calibrated parameters. names/values/standard_errors: the fitted ones.
    correlation: their correlation matrix. unidentifiable: pairs with |corr| > 0.99.
    rms_orientation_deg: RMS relative angle over the poses before and after."""

    params: ModelParameters
    names: tuple[str, ...]
    values: np.ndarray
    standard_errors: np.ndarray
    correlation: np.ndarray
    unidentifiable: tuple[tuple[str, str, float], ...]
    rms_orientation_deg_before: float
    rms_orientation_deg_after: float
    evaluations: int


DEFAULT_NAMES = PARAMETER_NAMES  # E0, EL, L and the six components of w_d: nine parameters


def parameter_bounds(model: ShootingModel, name: str) -> tuple[float, float]:
    if name in CORE_BOUNDS:
        return CORE_BOUNDS[name]
    parameter: EffectParameter | None = effect_parameter(model, name)
    if parameter is None:
        raise KeyError(f"parameter {name!r} belongs to no enabled effect of {model!r}")
    return parameter.lower, parameter.upper


def calibrate(model: ShootingModel, poses: Sequence[CalibrationPose], initial: ModelParameters,
              names: Sequence[str] = DEFAULT_NAMES, *,
              position_weight_rad_per_m: float = DEFAULT_POSITION_WEIGHT_RAD_PER_M,
              max_evaluations: int = 100) -> CalibrationResult:
    """Fit ``names`` to the poses by bounded nonlinear least squares (trust region
    reflective), starting from ``initial``. Raises ValueError for too few poses."""
    names = tuple(names)
    use_positions = position_weight_rad_per_m > 0 and all(
        pose.tip_position_in_base_sensor_m is not None for pose in poses)
    rows_per_pose = 6 if use_positions else 3
    if len(poses) * rows_per_pose <= len(names):
        raise ValueError(f"{len(poses)} poses cannot determine {len(names)} parameters")
    bounds = np.array([parameter_bounds(model, name) for name in names]).T
    scales = np.array([parameter_scale(model, name) for name in names])
    start = np.array([get_parameter(initial, name, _default(model, name)) for name in names])
    start = np.clip(start, bounds[0], bounds[1])
    per_pose_params = [_with_gravity(initial, pose) for pose in poses]
    cache: dict[bytes, tuple[np.ndarray, list[Solution]]] = {}

    def params_for(x: np.ndarray, index: int) -> ModelParameters:
        return with_parameters(per_pose_params[index], dict(zip(names, x)))

    def evaluate(x: np.ndarray) -> tuple[np.ndarray, list[Solution]]:
        key = x.tobytes()
        if key not in cache:
            cache.clear()  # only the latest point is asked for again (by the Jacobian)
            residuals = np.empty(len(poses) * rows_per_pose)
            solutions: list[Solution] = []
            previous: Solution | None = None
            for index, pose in enumerate(poses):
                solution = model.solve(pose.jet_forces_n, params_for(x, index), warm_start=previous)
                solutions.append(solution)
                previous = solution
                rows = residuals[index * rows_per_pose:(index + 1) * rows_per_pose]
                rows[:3] = body_rotation_error(solution.tip_sensor_in_base_sensor(), pose.measured_tip_in_base_sensor)
                if use_positions:
                    predicted = solution.base_sensor_mounting.T @ solution.tip_position_in_base_m
                    rows[3:] = position_weight_rad_per_m * (predicted - pose.tip_position_in_base_sensor_m)
            cache[key] = (residuals, solutions)
        return cache[key]

    def residual(x: np.ndarray) -> np.ndarray:
        return evaluate(x)[0]

    def jacobian(x: np.ndarray) -> np.ndarray:
        _, solutions = evaluate(x)
        matrix = np.empty((len(poses) * rows_per_pose, len(names)))
        for index, (pose, solution) in enumerate(zip(poses, solutions)):
            columns = sensitivity(model, pose.jet_forces_n, params_for(x, index), names, nominal=solution).matrix
            rows = matrix[index * rows_per_pose:(index + 1) * rows_per_pose]
            # d(log(R_pred^T R_meas))/dzeta = -(tip sensor mounting)^T S_rot, to first order.
            rows[:3] = -solution.tip_sensor_mounting.T @ columns[3:]
            if use_positions:
                # The tip moves by R_tip v for a body twist (v, omega).
                rows[3:] = position_weight_rad_per_m * (
                    solution.base_sensor_mounting.T @ solution.tip_rotation_in_base @ columns[:3])
        return matrix

    try:
        before = residual(start)
        fit = least_squares(residual, start, jac=jacobian, bounds=bounds, x_scale=scales,
                            max_nfev=max_evaluations, xtol=1e-10, ftol=1e-10, gtol=1e-10)
    except ConvergenceError as error:
        raise ConvergenceError(f"calibration stopped: a model solve failed ({error})") from error
    values = fit.x
    final = residual(values)
    dof = max(final.size - len(names), 1)
    variance = float(final @ final) / dof
    # In scaled variables: the raw columns span ~15 decades (rad per Pa vs per N m), and
    # a pseudo-inverse of the raw J^T J would discard the small ones as rank-deficient.
    scaled = fit.jac * scales
    covariance = variance * np.linalg.pinv(scaled.T @ scaled) * np.outer(scales, scales)
    standard_errors = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        correlation = covariance / np.outer(standard_errors, standard_errors)
    correlation = np.nan_to_num(correlation)
    unidentifiable = tuple(
        (names[i], names[j], float(correlation[i, j]))
        for i in range(len(names)) for j in range(i + 1, len(names))
        if abs(correlation[i, j]) > CORRELATION_WARNING)
    return CalibrationResult(
        params=with_parameters(initial, dict(zip(names, values))),
        names=names, values=values, standard_errors=standard_errors, correlation=correlation,
        unidentifiable=unidentifiable,
        rms_orientation_deg_before=_rms_angle_deg(before, rows_per_pose),
        rms_orientation_deg_after=_rms_angle_deg(final, rows_per_pose),
        evaluations=int(fit.nfev),
    )


def _default(model: ShootingModel, name: str) -> float | None:
    parameter = effect_parameter(model, name)
    return parameter.default if parameter is not None else None


def _with_gravity(params: ModelParameters, pose: CalibrationPose) -> ModelParameters:
    return replace(params, gravity_in_base_m_s2=tuple(pose.gravity_in_base_m_s2))


def _rms_angle_deg(residuals: np.ndarray, rows_per_pose: int) -> float:
    rotation = residuals.reshape(-1, rows_per_pose)[:, :3]
    return float(np.degrees(np.sqrt(np.mean(np.sum(rotation**2, axis=1)))))
