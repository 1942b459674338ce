"""Model against measurements: every validation step predicted along its path
(`estimation.path.PathPredictor`) with the calibrated, constant disturbance ("Ref." in
the paper's Table II) and with the online estimate ("Proposed"), and the errors.

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
from ..estimation.online import OnlineSettings
from ..estimation.path import (ONLINE, REF, PathPredictor, Predictions, StepPrediction, orientation_error_deg,
                               step_position_error_mm)
from ..geometry import matrix_from_quat
from ..models.shooting import ShootingModel
from ..params import ModelParameters
from .metrics import ErrorSummary, bend_bin_labels, breakdown, summarise


@dataclass(frozen=True)
class Comparison:
    """Errors of one prediction method on one dataset, with their breakdowns."""

    orientation_error_deg: np.ndarray
    position_error_mm: np.ndarray | None
    overall: ErrorSummary
    by_sweep: dict
    by_bend: dict
    predictions: Predictions
    # Steps where online estimation could not be solved as usual, and what it did there
    # (`StepPrediction.online_fallback`): (step index, what) pairs.
    fallbacks: tuple[tuple[int, str], ...] = ()

    def fallback_notice(self) -> str:
        """One line on `fallbacks` ("" when there are none)."""
        if not self.fallbacks:
            return ""
        shown = ", ".join(str(index) for index, _ in self.fallbacks[:5]) + (", ..." if len(self.fallbacks) > 5 else "")
        return (f"online estimation could not be solved as usual on {len(self.fallbacks)} of "
                f"{len(self.orientation_error_deg)} steps ({shown}; first: {self.fallbacks[0][1]}); their Proposed "
                "predictions carry less or no correction")

    def as_dict(self) -> dict:
        return {
            "orientation_rmse_deg": self.overall.orientation_rmse_deg,
            "position_rmse_mm": self.overall.position_rmse_mm,
            "by_sweep": {str(k): v.as_dict() for k, v in self.by_sweep.items()},
            "by_bend": {str(k): v.as_dict() for k, v in self.by_bend.items()},
        }


def compare(predictions: Predictions, steps: Dataset) -> Comparison:
    """Errors of ``predictions`` against the dataset's measurements, overall, per sweep
    and per measured bending-angle bin."""
    # Step by step, with the measures each live step uses: the live figures, bit for bit.
    measured = steps.tip_orientation_in_base()
    orientation = np.array([orientation_error_deg(predicted, row) for predicted, row
                            in zip(predictions.tip_orientation_in_base, measured)])
    measured_positions = steps.tip_position_in_base_m()
    position = None if measured_positions is None else np.array(
        [step_position_error_mm(predicted, row) for predicted, row
         in zip(predictions.tip_position_in_base_m, measured_positions)])
    measured_bend = measured_bend_deg(steps)
    return Comparison(orientation, position, summarise(orientation, position),
                      breakdown(orientation, position, steps.sweep),
                      breakdown(orientation, position, bend_bin_labels(measured_bend)), predictions)


def compare_steps(predicted: Sequence[StepPrediction], steps: Dataset) -> dict[str, Comparison]:
    """Ref. ("ref") and, when every step has it, Proposed ("online") of ``predicted`` (one
    record per row of ``steps``), each compared on ``steps``."""
    results = {}
    for method in (REF, ONLINE):
        predictions = Predictions.along(predicted, method)
        if predictions is not None:
            results[method] = compare(predictions, steps)
    if ONLINE in results:
        fallbacks = tuple((index, step.online_fallback) for index, step in enumerate(predicted) if step.online_fallback)
        results[ONLINE] = replace(results[ONLINE], fallbacks=fallbacks)
    return results


def compare_methods(model: ShootingModel, params: ModelParameters, steps: Dataset,
                    online: OnlineSettings | None = None, lead_in: Dataset | None = None) -> dict[str, Comparison]:
    """Ref. and, given ``online`` settings, Proposed, predicted along ``steps`` in order
    (`PathPredictor`) and compared on them; the path first goes through ``lead_in``, the
    rows recorded before them (`PathPredictor.carry`)."""
    predictor = PathPredictor(model, params, online)
    if lead_in is not None:
        predictor.carry(lead_in)
    return compare_steps(predictor.predict(steps), steps)


def validation_rows(steps: Dataset) -> np.ndarray:
    """The rows predictions are compared on (boolean mask): the sweeps (sweep >= 0), or
    every row of a table without sweeps."""
    sweeps = steps.sweep >= 0
    return sweeps if sweeps.any() else np.ones(len(steps), dtype=bool)


def lead_in(steps: Dataset) -> Dataset:
    """The rows recorded before the first validation row (none without sweeps): the path a
    prediction of the sweeps goes through first, as the rod did (`PathPredictor.carry`)."""
    return steps.select(np.arange(int(np.argmax(validation_rows(steps))) if len(steps) else 0))


def measured_bend_deg(steps: Dataset) -> np.ndarray:
    """Bending angle of each row from the measured tip orientation: the angle between the
    clamp axis and the tip tangent (z axes), degrees."""
    rotation = matrix_from_quat(steps.tip_orientation_in_base())
    return np.degrees(np.arccos(np.clip(rotation[:, 2, 2], -1.0, 1.0)))
