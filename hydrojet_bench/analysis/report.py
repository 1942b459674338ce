"""Report figures for `compare` (PNG, matplotlib Agg): the paper's Figs. 4-6, the
residual vectors and the online disturbance per sweep (where the model fails), and, given
a baseline, errors and disturbance before and after."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: the bench machines have no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..data.dataset import Dataset  # noqa: E402
from ..errors import UserError  # noqa: E402
from .breakdowns import MISSING_LABEL, orientation_residuals_deg  # noqa: E402
from .compare import Comparison, measured_bend_deg  # noqa: E402

LABELS = {"ref": "Ref. (constant disturbance)", "online": "Proposed (online estimation)"}
SHORT_LABELS = {"ref": "Ref.", "online": "Proposed"}


def write_report(folder: Path, results: dict[str, Comparison], steps: Dataset, model_name: str,
                 baseline: dict[str, Comparison] | None = None) -> list[Path]:
    """Write the figures into ``folder`` (created if needed); returns their paths.
    ``baseline``: the same methods with the parameters before a change (``results`` are
    after it)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise UserError(f"cannot create report folder {folder}: {error.strerror}") from None
    paths = [_tip_paths(folder, results, steps, model_name), _error_boxes(folder, results, model_name)]
    paths += [_residuals(folder, key, comparison, steps, model_name) for key, comparison in results.items()]
    if "online" in results:
        paths.append(_disturbance(folder, results["online"], steps, model_name))
    if baseline is not None:
        paths.append(_before_after_rmse(folder, baseline, results, model_name))
        if "online" in results and "online" in baseline:
            paths.append(_before_after_disturbance(folder, baseline["online"], results["online"], steps, model_name))
    return paths


def _tip_paths(folder: Path, results: dict[str, Comparison], steps: Dataset, model_name: str) -> Path:
    """Fig. 4: measured tip positions (dots) and predicted paths, projected on xy, xz, yz."""
    measured = steps.tip_position_in_base_m()
    figure, axes = plt.subplots(1, 3, figsize=(13, 4.2))
    for axis, (i, j, name) in zip(axes, ((0, 1, "xy"), (0, 2, "xz"), (1, 2, "yz"))):
        for sweep in np.unique(steps.sweep):
            rows = steps.sweep == sweep
            colour = f"C{int(sweep) % 10}"
            if measured is not None:
                axis.plot(measured[rows, i] * 1e3, measured[rows, j] * 1e3, ".", color=colour, markersize=4)
            for key, style in (("ref", "--"), ("online", "-")):
                if key in results:
                    predicted = results[key].predictions.tip_position_in_base_m
                    axis.plot(predicted[rows, i] * 1e3, predicted[rows, j] * 1e3, style, color=colour, linewidth=1)
        axis.set_xlabel(f"{name[0]} (mm)")
        axis.set_ylabel(f"{name[1]} (mm)")
        axis.set_aspect("equal", adjustable="datalim")
        axis.set_title(f"{name} plane")
    figure.suptitle(f"{model_name}: measured tip (dots), Ref. (dashed), Proposed (solid), one colour per sweep")
    figure.tight_layout()
    return _save(figure, folder / "tip_paths.png")


def _error_boxes(folder: Path, results: dict[str, Comparison], model_name: str) -> Path:
    """Figs. 5-6: distribution of orientation and position errors per method."""
    figure, axes = plt.subplots(1, 2, figsize=(10, 4))
    keys = list(results)
    axes[0].boxplot([results[k].orientation_error_deg for k in keys], tick_labels=[LABELS[k] for k in keys])
    axes[0].set_ylabel("orientation error (deg)")
    positions = [results[k].position_error_mm for k in keys]
    if all(p is not None for p in positions):
        axes[1].boxplot(positions, tick_labels=[LABELS[k] for k in keys])
    axes[1].set_ylabel("position error (mm)")
    figure.suptitle(f"{model_name}: error distribution over the sweeps")
    figure.tight_layout()
    return _save(figure, folder / "error_boxes.png")


def _residuals(folder: Path, key: str, comparison: Comparison, steps: Dataset, model_name: str) -> Path:
    """The orientation error vector (tip frame) against measured bend and against time,
    one colour per sweep: its direction and how it grows say which physics is missing."""
    residual = orientation_residuals_deg(comparison.predictions, steps)
    bend = measured_bend_deg(steps)
    minutes = (steps.time_s - steps.time_s[0]) / 60.0
    figure, axes = plt.subplots(2, 3, figsize=(13, 6.5), sharey=True)
    for sweep in np.unique(steps.sweep):
        rows = steps.sweep == sweep
        for component, name in enumerate("xyz"):
            style = {"color": f"C{int(sweep) % 10}", "marker": ".", "markersize": 4, "linewidth": 0.8}
            axes[0, component].plot(bend[rows], residual[rows, component], **style, label=f"sweep {sweep}")
            axes[1, component].plot(minutes[rows], residual[rows, component], **style)
            axes[0, component].set_title(f"{name} component")
    for component in range(3):
        axes[0, component].set_xlabel("measured bend (deg)")
        axes[1, component].set_xlabel("time (min)")
    for row in axes:
        row[0].set_ylabel("orientation error (deg)")
        for axis in row:
            axis.axhline(0.0, color="0.6", linewidth=0.6)
    axes[0, 2].legend(fontsize=7, ncol=2)
    figure.suptitle(f"{model_name}, {LABELS[key]}: rotation vector of R_pred^T R_meas (tip frame)")
    figure.tight_layout()
    return _save(figure, folder / f"residuals_{key}.png")


def _sweep_grid(count: int, figsize_per_panel: tuple[float, float] = (4.2, 2.8)):
    columns = min(3, count)
    rows = -(-count // columns)
    figure, axes = plt.subplots(rows, columns, squeeze=False, sharey=True,
                                figsize=(max(figsize_per_panel[0] * columns, 7.0), figsize_per_panel[1] * rows + 1.0))
    for axis in axes.flat[count:]:
        axis.set_visible(False)
    return figure, axes.flat


def _disturbance(folder: Path, online: Comparison, steps: Dataset, model_name: str) -> Path:
    """The online disturbance moment over each sweep, components and norm against step:
    what the model is missing."""
    moment = online.predictions.disturbance_moment_nm * 1e3
    sweeps = np.unique(steps.sweep)
    figure, axes = _sweep_grid(len(sweeps))
    for axis, sweep in zip(axes, sweeps):
        rows = steps.sweep == sweep
        step = steps.step[rows]
        for component, name in enumerate("xyz"):
            axis.plot(step, moment[rows, component], linewidth=1, label=f"m_{name}")
        axis.plot(step, np.linalg.norm(moment[rows], axis=1), "k-", linewidth=1.6, label="norm")
        axis.axhline(0.0, color="0.8", linewidth=0.6)
        axis.set_title(f"sweep {sweep}", fontsize=9)
        axis.set_xlabel("step")
        axis.set_ylabel("moment (mN m)")
    axes[0].legend(fontsize=7)
    figure.suptitle(f"{model_name}: {MISSING_LABEL}\nthe online disturbance moment (tip frame) over each sweep")
    figure.tight_layout()
    return _save(figure, folder / "disturbance.png")


def _before_after_rmse(folder: Path, before: dict[str, Comparison], after: dict[str, Comparison],
                       model_name: str) -> Path:
    """RMS errors per sweep and overall, before and after, as grouped bars."""
    sweeps = list(after["ref"].by_sweep)
    groups = ["all"] + [f"sweep {s}" for s in sweeps]
    bars = [(f"{SHORT_LABELS[key]} {when}", results[key]) for key in after
            for when, results in (("before", before), ("after", after)) if key in results]
    figure, axes = plt.subplots(1, 2, figsize=(13, 4.2))
    width = 0.8 / len(bars)
    x = np.arange(len(groups))
    for axis, name, unit in ((axes[0], "orientation_rmse_deg", "orientation RMSE (deg)"),
                             (axes[1], "position_rmse_mm", "position RMSE (mm)")):
        for index, (label, comparison) in enumerate(bars):
            summaries = [comparison.overall] + [comparison.by_sweep[s] for s in sweeps]
            values = [getattr(summary, name) for summary in summaries]
            if any(value is None for value in values):
                continue
            axis.bar(x + (index - (len(bars) - 1) / 2) * width, values, width, label=label,
                     color=f"C{index // 2}", alpha=0.45 if label.endswith("before") else 1.0)
        axis.set_xticks(x, groups, rotation=45, ha="right", fontsize=8)
        axis.set_ylabel(unit)
        axis.margins(y=0.3)  # headroom for the legend above the bars
    axes[0].legend(fontsize=8, ncol=len(bars), loc="upper center")
    figure.suptitle(f"{model_name}: RMS errors before (pale) and after (solid)")
    figure.tight_layout()
    return _save(figure, folder / "before_after_rmse.png")


def _before_after_disturbance(folder: Path, before: Comparison, after: Comparison, steps: Dataset,
                              model_name: str) -> Path:
    """Norm of the online disturbance moment at each step, before and after: it shrinks
    when the change explains the physics the disturbance was absorbing."""
    figure, axis = plt.subplots(figsize=(10, 4))
    index = np.arange(len(steps))
    for label, comparison, style in (("before", before, "--"), ("after", after, "-")):
        axis.plot(index, np.linalg.norm(comparison.predictions.disturbance_moment_nm, axis=1) * 1e3, style,
                  label=label)
    for boundary in np.flatnonzero(np.diff(steps.sweep)) + 0.5:
        axis.axvline(boundary, color="0.8", linewidth=0.8)
    axis.set_xlabel("step (sweeps separated by grey lines)")
    axis.set_ylabel("online disturbance moment norm (mN m)")
    axis.legend()
    axis.set_title(f"{model_name}: {MISSING_LABEL}, before and after")
    figure.tight_layout()
    return _save(figure, folder / "before_after_disturbance.png")


def _save(figure, path: Path) -> Path:
    try:
        figure.savefig(path, dpi=110)
    except OSError as error:
        raise UserError(f"cannot write {path}: {error.strerror}") from None
    finally:
        plt.close(figure)
    return path
