"""Evidence beside the ranking: what each candidate changes, and whether that is what
the baseline misses.

Signature of a candidate: the rotation that adding it (and recalibrating) makes to the
predicted tip orientation on each held-out step, ``log(R_base^T R_cand)`` (tip sensor
frame). Two things it is compared with, by the cosine of the stacked 3-vectors over the
held-out steps (1: same shape and direction, 0: unrelated):

* the baseline's residual, ``log(R_base^T R_meas)``: does the candidate move the
  prediction where the measurements are?
* the ONLINE disturbance estimate (paper eq. 4, run along the session on the baseline):
  the moment it had to add to the calibrated w_d at each step is what the baseline is
  missing, found without any candidate. The candidate's signature is carried into the
  same space through the baseline's moment sensitivity S_m at each step (the moment
  that would turn the tip by the signature, S_m^-1 omega). This is independent of the
  fit: a candidate that only fits noise or trades off against w_d does not follow it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...data.dataset import Dataset
from ...estimation.online import OnlineSettings
from ...estimation.path import ONLINE, PathPredictor, Predictions
from ...geometry import body_rotation_error, matrix_from_quat, rotation_angle_deg
from ...models.shooting import ShootingModel
from ...params import DISTURBANCE_MOMENT_NAMES, ModelParameters
from ...sensitivity import sensitivity
from ..breakdowns import NOISE_GAP_PER_FLOOR, driving_jet_labels, hysteresis_gaps


def rotation_between(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """(n, 3) rotation vectors (rad) of R_first^T R_second for quaternion arrays (n, 4)."""
    return body_rotation_error(matrix_from_quat(first), matrix_from_quat(second))


def cosine(a: np.ndarray, b: np.ndarray) -> float:
    """Cosine between two stacked vector fields; 0 when either is zero."""
    norm = float(np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.sum(a * b) / norm) if norm > 0.0 else 0.0


def rmse_by_jet(predictions: Predictions, steps: Dataset) -> dict[str, float]:
    """Held-out orientation RMSE (deg) per driving jet."""
    errors = rotation_angle_deg(predictions.tip_orientation_in_base, steps.tip_orientation_in_base())
    labels = driving_jet_labels(steps)
    return {str(label): float(np.sqrt(np.mean(errors[labels == label] ** 2))) for label in np.unique(labels)}


def hysteresis_gap_deg(predictions: Predictions, steps: Dataset) -> float | None:
    """Mean norm of (unloading - loading) residual at matched forces (deg), see
    `breakdowns.loading_split`."""
    return hysteresis_gaps(predictions, steps)[0]


@dataclass(frozen=True)
class OnlineEvidence:
    """The online estimator run along the session on the calibrated baseline.

    missing_moment_nm: (n, 3) estimated moment minus the calibrated w_d moment on the
    held-out steps (tip frame, N m). moment_sensitivity: (n, 3, 3) rotation of the tip
    sensor (rad, its frame) per N m of w_d moment at the baseline's held-out predictions.
    online_rmse_deg: held-out orientation RMSE with online estimation."""

    missing_moment_nm: np.ndarray
    moment_sensitivity: np.ndarray
    online_rmse_deg: float

    def equivalent_moment_nm(self, rotation_rad: np.ndarray) -> np.ndarray:
        """(n, 3) moments that turn the tip sensor by ``rotation_rad`` (n, 3) per step."""
        # Least squares, minimum norm where a matrix is singular, for the whole stack at
        # once: `lstsq`'s cut-off (eps x size), as one pseudo-inverse instead of a call a step.
        inverse = np.linalg.pinv(self.moment_sensitivity, rtol=3 * np.finfo(float).eps)
        return (inverse @ np.asarray(rotation_rad, dtype=float)[:, :, np.newaxis])[:, :, 0]


def online_evidence(model: ShootingModel, params: ModelParameters, steps: Dataset, held_out: np.ndarray,
                    gravity_in_base_m_s2: np.ndarray, settings: OnlineSettings) -> OnlineEvidence:
    """Run online estimation over the session (`PathPredictor`, in recorded order with
    each step's own gravity, as the bench runs it) and the baseline's moment sensitivity
    at each held-out step (predicted along the path with the gravity the fits used)."""
    online = Predictions.along(PathPredictor(model, params, settings).predict(steps), ONLINE)
    missing = online.disturbance_moment_nm[held_out] - np.asarray(params.disturbance.moment_nm)
    rows = np.flatnonzero(held_out)
    path = np.arange(rows[-1] + 1)
    baseline = PathPredictor(model, params).predict(steps.select(path), gravity_in_base_m_s2[path])
    matrices = []
    for row in rows:
        solution = baseline[row].ref.solution
        row_params = replace(params, gravity_in_base_m_s2=tuple(gravity_in_base_m_s2[row]))
        columns = sensitivity(model, steps.jet_forces_n[row], row_params, DISTURBANCE_MOMENT_NAMES, nominal=solution,
                              previous=baseline[row - 1].ref.solution if row > 0 else None).rotation_rows
        # The sensitivity is in the rod tip's frame; signatures are in the tip sensor's.
        matrices.append(solution.tip_sensor_mounting.T @ columns)
    errors = rotation_angle_deg(online.tip_orientation_in_base[held_out], steps.tip_orientation_in_base()[held_out])
    return OnlineEvidence(missing, np.array(matrices), float(np.sqrt(np.mean(errors**2))))
