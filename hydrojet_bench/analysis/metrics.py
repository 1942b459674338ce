"""RMS summaries of the errors between predicted and measured tip poses, and their
breakdowns.

Orientation error: the angle (deg) of the rotation between the predicted and the measured
tip-relative-to-base orientation (`geometry.rotation_angle_deg`). Position error: the
Euclidean distance (mm) between predicted and measured tip positions in the base frame
(`geometry.position_error_mm`, the paper's ||epsilon||_2). Breakdowns group samples by
sweep and by bending angle, the latter in the bins of the paper's Table II, labelled by
their upper edges 10, 25, 50 and 75 degrees (bends beyond 75 degrees form a last bin).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

BEND_BIN_EDGES_DEG: tuple[float, ...] = (10.0, 25.0, 50.0, 75.0)


@dataclass(frozen=True)
class ErrorSummary:
    """RMS and standard deviation of the errors of one group of samples."""

    count: int
    orientation_rmse_deg: float
    orientation_sd_deg: float
    position_rmse_mm: float | None
    position_sd_mm: float | None

    def as_dict(self) -> dict:
        return {key: getattr(self, key) for key in self.__dataclass_fields__}


def summarise(orientation_deg: np.ndarray, position_mm: np.ndarray | None = None) -> ErrorSummary:
    orientation = np.asarray(orientation_deg, dtype=float)
    if orientation.size == 0:
        raise ValueError("no samples to summarise")
    position = None if position_mm is None else np.asarray(position_mm, dtype=float)
    return ErrorSummary(
        count=int(orientation.size),
        orientation_rmse_deg=float(np.sqrt(np.mean(orientation**2))),
        orientation_sd_deg=float(np.std(orientation)),
        position_rmse_mm=None if position is None else float(np.sqrt(np.mean(position**2))),
        position_sd_mm=None if position is None else float(np.std(position)),
    )


def bend_bin_names(edges: Sequence[float] = BEND_BIN_EDGES_DEG) -> list[str]:
    """The bending-angle bins' labels, smallest first: "10", "25", "50", "75", ">75"."""
    return [f"{edge:g}" for edge in edges] + [f">{edges[-1]:g}"]


def bend_bin_labels(bend_deg: np.ndarray, edges: Sequence[float] = BEND_BIN_EDGES_DEG) -> np.ndarray:
    """Label of each sample's bending-angle bin: "10", "25", "50", "75" (upper edges,
    inclusive) or ">75"."""
    bend = np.asarray(bend_deg, dtype=float)
    return np.array(bend_bin_names(edges))[np.searchsorted(np.asarray(edges), bend, side="left")]


def breakdown(orientation_deg: np.ndarray, position_mm: np.ndarray | None, groups: np.ndarray) -> dict:
    """``{group: ErrorSummary}`` for every group label present, in sorted order."""
    groups = np.asarray(groups)
    result = {}
    for group in sorted(set(groups.tolist()), key=lambda g: (isinstance(g, str), g)):
        mask = groups == group
        result[group] = summarise(orientation_deg[mask], None if position_mm is None else position_mm[mask])
    return result
