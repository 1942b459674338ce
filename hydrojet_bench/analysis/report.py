"""Report figures for `compare`, after the paper's Figs. 4-6 (PNG, matplotlib Agg)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: the bench machines have no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..data.dataset import Dataset  # noqa: E402
from ..errors import UserError  # noqa: E402
from .compare import Comparison  # noqa: E402

LABELS = {"ref": "Ref. (constant disturbance)", "online": "Proposed (online estimation)"}


def write_report(folder: Path, results: dict[str, Comparison], steps: Dataset, model_name: str) -> list[Path]:
    """Write the figures into ``folder`` (created if needed); returns their paths."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise UserError(f"cannot create report folder {folder}: {error.strerror}") from None
    paths = [_tip_paths(folder, results, steps, model_name), _error_boxes(folder, results, model_name)]
    if "online" in results:
        paths.append(_disturbance(folder, results["online"], steps, model_name))
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


def _disturbance(folder: Path, online: Comparison, steps: Dataset, model_name: str) -> Path:
    """The online disturbance moment over each sweep: what the model is missing."""
    moment = online.predictions.disturbance_moment_nm * 1e3
    figure, axis = plt.subplots(figsize=(10, 4))
    index = np.arange(len(steps))
    for component, name in enumerate("xyz"):
        axis.plot(index, moment[:, component], label=f"w_d moment {name}")
    for boundary in np.flatnonzero(np.diff(steps.sweep)) + 0.5:
        axis.axvline(boundary, color="0.8", linewidth=0.8)
    axis.set_xlabel("step (sweeps separated by grey lines)")
    axis.set_ylabel("estimated disturbance moment (mN m)")
    axis.legend()
    axis.set_title(f"{model_name}: online disturbance estimate")
    figure.tight_layout()
    return _save(figure, folder / "disturbance.png")


def _save(figure, path: Path) -> Path:
    try:
        figure.savefig(path, dpi=110)
    except OSError as error:
        raise UserError(f"cannot write {path}: {error.strerror}") from None
    finally:
        plt.close(figure)
    return path
