"""Quick-look figures for the notebook results: each function returns a matplotlib
`Figure` (no pyplot state, so nothing is shown or kept open behind the caller's back; a
notebook displays a returned figure). The paper's figures are in `analysis.report`."""

from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

METHOD_LABELS = {"ref": "Ref.", "online": "Proposed"}


def step_errors_figure(table: pd.DataFrame, title: str) -> Figure:
    """Orientation (deg) and position (mm) error of every step per method, against the
    step's row; dotted lines where a sweep starts."""
    figure = Figure(figsize=(9.0, 5.0), layout="constrained")
    top, bottom = figure.subplots(2, 1, sharex=True)
    for method, rows in table.groupby("method", sort=False):
        label = METHOD_LABELS.get(str(method), str(method))
        index = np.arange(len(rows))
        top.plot(index, rows["orientation_error_deg"], marker=".", markersize=3, linewidth=0.8, label=label)
        bottom.plot(index, rows["position_error_mm"], marker=".", markersize=3, linewidth=0.8, label=label)
        sweeps = rows["sweep"].to_numpy()
    for axes in (top, bottom):
        for start in np.flatnonzero(np.diff(sweeps) != 0) + 1:
            axes.axvline(start - 0.5, color="0.7", linestyle=":", linewidth=0.8)
        axes.grid(alpha=0.3)
    top.set_ylabel("orientation error (deg)")
    bottom.set_ylabel("position error (mm)")
    bottom.set_xlabel("step (dotted: a new sweep)")
    top.legend()
    figure.suptitle(title)
    return figure


def measured_bend_figure(table: pd.DataFrame, title: str) -> Figure:
    """Measured bend (deg) of every step against time (s), one colour per sweep
    (calibration poses: sweep -1)."""
    figure = Figure(figsize=(9.0, 3.5), layout="constrained")
    axes = figure.subplots()
    for sweep, rows in table.groupby("sweep"):
        label = "calibration poses" if sweep == -1 else f"sweep {sweep}"
        axes.plot(rows["time_s"], rows["measured_bend_deg"], marker=".", linewidth=0.8, label=label)
    axes.set_xlabel("time (s)")
    axes.set_ylabel("measured bend (deg)")
    axes.grid(alpha=0.3)
    axes.legend(fontsize="small", ncols=2)
    axes.set_title(title)
    return figure


def ranking_figure(ranking: pd.DataFrame, baseline_deg: float, floor_deg: float, title: str) -> Figure:
    """Held-out orientation RMSE (deg) of each candidate against the baseline's and the
    noise floor."""
    figure = Figure(figsize=(8.0, 0.4 * len(ranking) + 1.6), layout="constrained")
    axes = figure.subplots()
    positions = np.arange(len(ranking))[::-1]
    axes.barh(positions, ranking["heldout_orientation_rmse_deg"].fillna(0.0), color="tab:blue")
    axes.set_yticks(positions, ranking["effect"])
    axes.axvline(baseline_deg, color="tab:red", label=f"baseline {baseline_deg:.3f} deg")
    axes.axvline(floor_deg, color="0.3", linestyle="--", label=f"noise floor {floor_deg:.3f} deg")
    axes.set_xlabel("held-out orientation RMSE (deg)")
    axes.legend(loc="lower right")
    axes.set_title(title)
    return figure


def confusion_figure(confusion: pd.DataFrame, title: str) -> Figure:
    """Cell counts by hidden truth (rows) and verdict (columns)."""
    figure = Figure(figsize=(1.0 + 0.9 * confusion.shape[1], 1.2 + 0.5 * confusion.shape[0]), layout="constrained")
    axes = figure.subplots()
    axes.imshow(confusion.to_numpy(), cmap="Blues")
    axes.set_xticks(range(confusion.shape[1]), confusion.columns, rotation=45, ha="right")
    axes.set_yticks(range(confusion.shape[0]), confusion.index)
    for (row, column), count in np.ndenumerate(confusion.to_numpy()):
        axes.text(column, row, str(count), ha="center", va="center")
    axes.set_xlabel("verdict")
    axes.set_ylabel("hidden truth")
    axes.set_title(title)
    return figure
