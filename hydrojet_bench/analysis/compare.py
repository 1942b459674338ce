"""Model against measurements: calibrate on the calibration rows, then predict every
validation step with the calibrated, constant disturbance ("Ref." in the paper's Table
II) and with the online estimate ("Proposed").

Measurements are compared in the rod's own frames: the dataset removes the rig
profile's known sensor mountings (`Dataset.tip_orientation_in_base`,
`Dataset.tip_position_in_base_m`), and the model applies only the mountings its effects
add (an unknown extra mounting is something to diagnose). Gravity in the base frame is
taken per step from the measured base orientation.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..data.dataset import Dataset
from ..estimation.calibration import DEFAULT_NAMES, CalibrationPose, CalibrationResult, calibrate
from ..estimation.online import OnlineDisturbanceEstimator, OnlineSettings
from ..geometry import matrix_from_quat, quat_from_matrix
from ..models.shooting import ShootingModel
from ..params import ModelParameters
from .metrics import ErrorSummary, bend_bin_labels, breakdown, orientation_errors_deg, position_errors_mm, summarise


@dataclass(frozen=True)
class Predictions:
    """Per-step predictions over a dataset of quasistatic steps.

    tip_orientation_in_base: (N, 4) predicted tip sensor orientation relative to the base.
    tip_position_in_base_m: (N, 3) predicted tip position, base frame, m.
    bend_deg: (N,) predicted bending angle. disturbance_moment_nm: (N, 3) the w_d|m used.
    """

    tip_orientation_in_base: np.ndarray
    tip_position_in_base_m: np.ndarray
    bend_deg: np.ndarray
    disturbance_moment_nm: np.ndarray


@dataclass(frozen=True)
class Comparison:
    """Errors of one prediction method on one dataset, with their breakdowns."""

    orientation_error_deg: np.ndarray
    position_error_mm: np.ndarray | None
    overall: ErrorSummary
    by_sweep: dict
    by_bend: dict
    predictions: Predictions

    def as_dict(self) -> dict:
        return {
            "orientation_rmse_deg": self.overall.orientation_rmse_deg,
            "position_rmse_mm": self.overall.position_rmse_mm,
            "by_sweep": {str(k): v.as_dict() for k, v in self.by_sweep.items()},
            "by_bend": {str(k): v.as_dict() for k, v in self.by_bend.items()},
        }


def calibration_poses(steps: Dataset) -> list[CalibrationPose]:
    """The dataset's rows as calibration poses (measured tip in base frame, gravity per row,
    positions when present)."""
    orientations = steps.tip_orientation_in_base()
    positions = steps.tip_position_in_base_m()
    gravity = steps.gravity_in_base_m_s2()
    return [CalibrationPose(steps.jet_forces_n[i], matrix_from_quat(orientations[i]), tuple(gravity[i]),
                            None if positions is None else positions[i]) for i in range(len(steps))]


def calibrate_dataset(model: ShootingModel, steps: Dataset, initial: ModelParameters,
                      names: Sequence[str] = DEFAULT_NAMES, **options) -> CalibrationResult:
    """Calibrate on the dataset's calibration rows (sweep -1)."""
    rows = steps.calibration_rows()
    if len(rows) == 0:
        raise ValueError(f"{steps.source or 'dataset'} has no calibration rows (sweep -1)")
    return calibrate(model, calibration_poses(rows), initial, names, **options)


def predict(model: ShootingModel, params: ModelParameters, steps: Dataset,
            online: OnlineSettings | None = None) -> Predictions:
    """Predict each row in order, warm-starting along the path; with ``online``, the
    disturbance moment is corrected at each row from that row's measurement first."""
    gravity = steps.gravity_in_base_m_s2()
    measured = steps.tip_orientation_in_base()
    orientations = np.empty((len(steps), 4))
    positions = np.empty((len(steps), 3))
    bends = np.empty(len(steps))
    moments = np.empty((len(steps), 3))
    estimator = OnlineDisturbanceEstimator(model, params, online) if online is not None else None
    previous = None
    for row in range(len(steps)):
        jets = steps.jet_forces_n[row]
        if estimator is not None:
            step = estimator.update(jets, measured[row], gravity_in_base_m_s2=gravity[row])
            solution, moment = step.solution, step.disturbance_moment_nm
        else:
            row_params = replace(params, gravity_in_base_m_s2=tuple(gravity[row]))
            solution = model.solve(jets, row_params, previous=previous)
            moment = np.array(params.disturbance.moment_nm)
        previous = solution
        orientations[row] = quat_from_matrix(solution.tip_sensor_in_base_sensor())
        positions[row] = solution.tip_position_in_base_m
        bends[row] = solution.bend_angle_deg
        moments[row] = moment
    return Predictions(orientations, positions, bends, moments)


def compare(predictions: Predictions, steps: Dataset) -> Comparison:
    """Errors of ``predictions`` against the dataset's measurements, overall, per sweep
    and per measured bending-angle bin."""
    orientation = orientation_errors_deg(predictions.tip_orientation_in_base, steps.tip_orientation_in_base())
    measured_positions = steps.tip_position_in_base_m()
    position = None if measured_positions is None else position_errors_mm(
        predictions.tip_position_in_base_m, measured_positions)
    measured_bend = measured_bend_deg(steps)
    return Comparison(orientation, position, summarise(orientation, position),
                      breakdown(orientation, position, steps.sweep),
                      breakdown(orientation, position, bend_bin_labels(measured_bend)), predictions)


def compare_methods(model: ShootingModel, params: ModelParameters, steps: Dataset,
                    online: OnlineSettings | None = None) -> dict[str, Comparison]:
    """Ref. ("ref": the calibrated, constant disturbance) and, given ``online`` settings,
    Proposed ("online": online disturbance estimation), each compared on ``steps``."""
    results = {"ref": compare(predict(model, params, steps), steps)}
    if online is not None:
        results["online"] = compare(predict(model, params, steps, online), steps)
    return results


def measured_bend_deg(steps: Dataset) -> np.ndarray:
    """Bending angle of each row from the measured tip orientation: the angle between the
    clamp axis and the tip tangent (z axes), degrees."""
    rotation = matrix_from_quat(steps.tip_orientation_in_base())
    return np.degrees(np.arccos(np.clip(rotation[:, 2, 2], -1.0, 1.0)))
