"""Per-step tables for notebooks: one pandas row per step (and per method), the columns
named with their units.

Frames: orientations are the tip's in the rod's base (clamp) frame as quaternions,
scalar first (``*_qw .. *_qz``); positions are the tip's in the base frame, mm; the
disturbance moment is in the tip frame, N m. Methods are keyed as in the JSON of
`compare`: ``"ref"`` (calibrated, constant disturbance; "Ref." in the paper) and
``"online"`` (online disturbance estimation; "Proposed").
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

from ..analysis.compare import Comparison, measured_bend_deg
from ..data.dataset import Dataset

QUATERNION = ("qw", "qx", "qy", "qz")
POSITION_MM = ("x_mm", "y_mm", "z_mm")
JETS_N = ("q1_n", "q2_n", "q3_n")


def measured_steps_table(steps: Dataset) -> pd.DataFrame:
    """The steps as measured: time (s), sweep (-1: calibration pose), step, commanded jet
    forces q1..q3 (N), the measured tip pose and bend (deg)."""
    columns: dict[str, np.ndarray] = {"time_s": steps.time_s, "sweep": steps.sweep, "step": steps.step}
    columns.update(zip(JETS_N, steps.jet_forces_n.T))
    columns.update(_pose("measured", steps.tip_orientation_in_base(), steps.tip_position_in_base_m()))
    columns["measured_bend_deg"] = measured_bend_deg(steps)
    return pd.DataFrame(columns)


def predicted_steps_table(results: Mapping[str, Comparison], steps: Dataset) -> pd.DataFrame:
    """`measured_steps_table` once per method (a ``method`` column first) with the
    predicted tip pose and bend, the orientation (deg) and position (mm; NaN unmeasured)
    errors, and the disturbance moment the prediction used (N m, tip frame)."""
    measured = measured_steps_table(steps)
    parts = []
    for method, comparison in results.items():
        predicted = comparison.predictions
        part = measured.copy()
        part.insert(0, "method", method)
        for name, values in _pose("predicted", predicted.tip_orientation_in_base,
                                  predicted.tip_position_in_base_m).items():
            part[name] = values
        part["predicted_bend_deg"] = predicted.bend_deg
        part["orientation_error_deg"] = comparison.orientation_error_deg
        part["position_error_mm"] = (np.full(len(steps), np.nan) if comparison.position_error_mm is None
                                     else comparison.position_error_mm)
        for axis, values in zip("xyz", predicted.disturbance_moment_nm.T):
            part[f"disturbance_m{axis}_nm"] = values
        parts.append(part)
    return pd.concat(parts, ignore_index=True)


def _pose(prefix: str, orientation: np.ndarray, position_m: np.ndarray | None) -> dict[str, np.ndarray]:
    columns = {f"{prefix}_{name}": values for name, values in zip(QUATERNION, np.asarray(orientation).T)}
    position_mm = (np.full((len(orientation), 3), np.nan) if position_m is None
                   else np.asarray(position_m) * 1e3)
    columns.update({f"{prefix}_{name}": values for name, values in zip(POSITION_MM, position_mm.T)})
    return columns
