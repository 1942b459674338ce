"""Report figures for `compare`, `replay` and `run --report`: the paper's Figs. 4-6, the
residual vectors and the online disturbance per sweep (where the model fails), and, given
a baseline, errors and disturbance before and after. Styled and written by `figures`, in
the format ``figure_format`` names (png, svg, pdf)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.lines import Line2D

from ..data.dataset import Dataset
from .breakdowns import LOADING, MISSING_LABEL, UNLOADING, driving_jet_labels, load_phases, orientation_residuals_deg
from .compare import Comparison, measured_bend_deg
from .figures import (create_folder, figure_legend, save, styled, subplots, sweep_boundaries, sweep_colour,
                      sweep_marker, zero_line)

LABELS = {"ref": "Ref. (constant disturbance)", "online": "Proposed (online estimation)"}
SHORT_LABELS = {"ref": "Ref.", "online": "Proposed"}
# Ref. dashed under Proposed solid: two styles, never two colours (colour is the sweep's).
METHOD_STYLE = {"ref": {"linestyle": (0, (4, 2)), "linewidth": 1.3, "zorder": 3},
                "online": {"linestyle": "-", "linewidth": 1.0, "zorder": 4}}
# Loading and unloading passes: separate lines, filled against hollow markers.
PASS_STYLE = {LOADING: {"linestyle": "-", "fillstyle": "full"},
              UNLOADING: {"linestyle": (0, (3, 1.5)), "fillstyle": "none"}}
COMPONENTS = "xyz"
# Bars or boxes whose values span more than this ratio get a log axis.
LOG_RATIO = 10.0


def write_report(folder: Path, results: dict[str, Comparison], steps: Dataset, model_name: str,
                 baseline: dict[str, Comparison] | None = None, figure_format: str = "png") -> list[Path]:
    """Write the figures into ``folder`` (created if needed); returns their paths.
    ``baseline``: the same methods with the parameters before a change (``results`` are
    after it)."""
    create_folder(folder)

    def path(stem: str) -> Path:
        return folder / f"{stem}.{figure_format}"

    paths = [save(tip_paths_figure(results, steps, model_name), path("tip_paths")),
             save(error_boxes_figure(results, model_name), path("error_boxes"))]
    limits = shared_limits([orientation_residuals_deg(c.predictions, steps) for c in results.values()])
    paths += [save(residuals_figure(key, comparison, steps, model_name, limits), path(f"residuals_{key}"))
              for key, comparison in results.items()]
    if "online" in results:
        paths.append(save(disturbance_figure(results["online"], steps, model_name), path("disturbance")))
    if baseline is not None:
        paths.append(save(before_after_rmse_figure(baseline, results, model_name), path("before_after_rmse")))
        if "online" in results and "online" in baseline:
            paths.append(save(before_after_disturbance_figure(baseline["online"], results["online"], steps,
                                                              model_name), path("before_after_disturbance")))
    return paths


def sweep_names(steps: Dataset) -> dict[int, str]:
    """"sweep 0 (jet 1)" for each validation sweep, "calibration poses" for sweep -1."""
    jets = driving_jet_labels(steps)
    return {int(s): "calibration poses" if s < 0 else f"sweep {s} ({jets[steps.sweep == s][0]})"
            for s in np.unique(steps.sweep)}


def passes(rows: np.ndarray, phases: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """Split ``rows`` (one sweep, in time order) into runs of one load phase; each run
    after the first starts at the last step of the one before, so a pass spans its whole
    force range without being joined to the next."""
    change = np.flatnonzero(phases[rows][1:] != phases[rows][:-1]) + 1
    starts, stops = np.concatenate([[0], change]), np.concatenate([change, [len(rows)]])
    return [(str(phases[rows[a]]), rows[max(a - 1, 0):b]) for a, b in zip(starts, stops)]


def sweep_passes(steps: Dataset, sweep: int, phases: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """`passes` of a validation sweep; the calibration poses (sweep -1), in no order of
    force, as one set of points ("poses", drawn unjoined)."""
    rows = np.flatnonzero(steps.sweep == sweep)
    return passes(rows, phases) if sweep >= 0 else [("poses", rows)]


def shared_limits(series: list[np.ndarray]) -> tuple[float, float]:
    """One y range (low, high) holding every series, padded by 6 %."""
    low = min(float(np.nanmin(s)) for s in series)
    high = max(float(np.nanmax(s)) for s in series)
    pad = 0.06 * max(high - low, 1e-9)
    return low - pad, high + pad


def _sweep_handles(names: dict[int, str]) -> list[Line2D]:
    return [Line2D([], [], color=sweep_colour(s), marker=sweep_marker(s), linestyle="-", label=name)
            for s, name in names.items()]


def _pass_handles() -> list[Line2D]:
    return [Line2D([], [], color="0.3", marker="o", label=f"{phase} pass", **style)
            for phase, style in PASS_STYLE.items()]


@styled
def tip_paths_figure(results: dict[str, Comparison], steps: Dataset, model_name: str):
    """Fig. 4: measured tip positions (hollow markers) and predicted paths (lines above
    them) projected on xy, xz and yz, and below, each method's error at every step: Ref.
    and Proposed stay apart there even when both paths lie within a millimetre."""
    measured = steps.tip_position_in_base_m()
    names = sweep_names(steps)
    figure, axes = subplots(2, 3, figsize=(12.5, 7.2), height_ratios=(1.5, 1.0))
    errors = axes[1, 0].get_gridspec()
    for axis in axes[1]:
        axis.remove()
    error_axis = figure.add_subplot(errors[1, :])
    for axis, (i, j, plane) in zip(axes[0], ((0, 1, "xy"), (0, 2, "xz"), (1, 2, "yz"))):
        for sweep in names:
            rows = steps.sweep == sweep
            colour = sweep_colour(sweep)
            if measured is not None:
                axis.plot(measured[rows, i] * 1e3, measured[rows, j] * 1e3, linestyle="none",
                          marker=sweep_marker(sweep), color=colour, fillstyle="none", markersize=4.5,
                          markeredgewidth=0.7, alpha=0.8, zorder=2)
            for key, style in METHOD_STYLE.items():
                if key in results:
                    # Calibration poses follow no path: their predictions are points.
                    unjoined = {"linestyle": "none", "marker": "+" if key == "ref" else "x"} if sweep < 0 else {}
                    predicted = results[key].predictions.tip_position_in_base_m
                    axis.plot(predicted[rows, i] * 1e3, predicted[rows, j] * 1e3, color=colour,
                              **{**style, **unjoined})
        axis.set_xlabel(f"tip {plane[0]} in the base frame (mm)")
        axis.set_ylabel(f"tip {plane[1]} in the base frame (mm)")
        axis.set_aspect("equal", adjustable="datalim")
        axis.set_title(f"{plane} plane")
    position = all(c.position_error_mm is not None for c in results.values())
    index = np.arange(len(steps))
    for sweep in names:
        rows = np.flatnonzero(steps.sweep == sweep)
        for key, style in METHOD_STYLE.items():
            if key in results:
                error = results[key].position_error_mm if position else results[key].orientation_error_deg
                error_axis.plot(index[rows], error[rows], color=sweep_colour(sweep), marker=sweep_marker(sweep),
                                markersize=3, fillstyle="full" if key == "online" else "none", **style)
    sweep_boundaries(error_axis, steps.sweep)
    error_axis.set_xlabel("step, in session order (grey lines separate the sweeps)")
    error_axis.set_ylabel("tip position error (mm)" if position else "tip orientation error (deg)")
    error_axis.set_ylim(bottom=0.0)
    error_axis.set_title("error at each step: Ref. (dashed, hollow markers) and Proposed (solid, filled)")
    methods = [Line2D([], [], color="0.3", linestyle="none", marker="o", fillstyle="none", label="measured tip")]
    methods += [Line2D([], [], color="0.3", label=LABELS[key], **{k: v for k, v in style.items() if k != "zorder"})
                for key, style in METHOD_STYLE.items() if key in results]
    figure_legend(figure, methods + _sweep_handles(names))
    figure.suptitle(f"{model_name}: measured and predicted tip paths, one colour and marker per sweep")
    return figure


@styled
def error_boxes_figure(results: dict[str, Comparison], model_name: str):
    """Figs. 5-6: distribution of orientation and position errors per method (log axis
    when one method's errors are an order of magnitude below the other's)."""
    figure, axes = subplots(1, 2, figsize=(10, 4.2))
    keys = list(results)
    labels = [LABELS[k].replace(" (", "\n(") for k in keys]
    columns = (("orientation error (deg)", "tip orientation", [results[k].orientation_error_deg for k in keys]),
               ("position error (mm)", "tip position", [results[k].position_error_mm for k in keys]))
    for axis, (unit, title, values) in zip(axes, columns):
        axis.set_xlabel("method")
        axis.set_ylabel(unit)
        axis.set_title(title)
        if any(v is None for v in values):
            axis.text(0.5, 0.5, "no measured tip position", ha="center", transform=axis.transAxes)
            axis.set_xticks([])
            continue
        axis.boxplot(values, tick_labels=labels, showmeans=True, medianprops={"color": "k"},
                     meanprops={"marker": "D", "markerfacecolor": "white", "markeredgecolor": "k"})
        _log_if_wide(axis, [float(np.median(v)) for v in values])
    figure_legend(figure, [Line2D([], [], color="k", label="median"),
                           Line2D([], [], linestyle="none", marker="D", markerfacecolor="white",
                                  markeredgecolor="k", label="mean")])
    figure.suptitle(f"{model_name}: error distribution over the sweeps (box: quartiles, whiskers: 1.5 IQR)")
    return figure


def _log_if_wide(axis, values: list[float]) -> None:
    positive = [v for v in values if v > 0.0]
    if len(positive) == len(values) and max(positive) > LOG_RATIO * min(positive):
        axis.set_yscale("log")
        axis.set_ylabel(axis.get_ylabel() + ", log scale")


@styled
def residuals_figure(key: str, comparison: Comparison, steps: Dataset, model_name: str,
                     limits: tuple[float, float] | None = None):
    """The orientation error vector (tip frame) against measured bend and against time,
    one colour per sweep, loading and unloading passes drawn apart: its direction and how
    it grows say which physics is missing. ``limits``: the y range (deg), shared by the
    methods' figures so they compare at a glance."""
    residual = orientation_residuals_deg(comparison.predictions, steps)
    bend = measured_bend_deg(steps)
    minutes = (steps.time_s - steps.time_s[0]) / 60.0
    phases = load_phases(steps)
    names = sweep_names(steps)
    figure, axes = subplots(2, 3, figsize=(13, 6.8), sharey=True)
    for sweep in names:
        for phase, rows in sweep_passes(steps, sweep, phases):
            style = {"color": sweep_colour(sweep), "marker": sweep_marker(sweep), "markersize": 3.5,
                     "linewidth": 0.9, **PASS_STYLE.get(phase, {"linestyle": "none"})}
            for component in range(3):
                axes[0, component].plot(bend[rows], residual[rows, component], **style)
                axes[1, component].plot(minutes[rows], residual[rows, component], **style)
    for component, name in enumerate(COMPONENTS):
        axes[0, component].set_title(f"{name} component against bend")
        axes[1, component].set_title(f"{name} component against time")
        axes[0, component].set_xlabel("measured bend (deg)")
        axes[1, component].set_xlabel("session time (min)")
    for row in axes:
        row[0].set_ylabel("orientation error (deg, tip frame)")
        for axis in row:
            zero_line(axis)
    if limits is not None:
        axes[0, 0].set_ylim(*limits)
    figure_legend(figure, _sweep_handles(names) + _pass_handles())
    figure.suptitle(f"{model_name}, {LABELS[key]}: orientation error as a rotation vector "
                    "(R_pred^T R_meas, tip frame); same y scale for every method")
    return figure


@styled
def disturbance_figure(online: Comparison, steps: Dataset, model_name: str):
    """The online disturbance moment (tip frame) against the force of the jet each sweep
    drives (calibration poses: against the total force), one panel per sweep: what the
    model is missing, and whether it grows with the jet."""
    moment = online.predictions.disturbance_moment_nm * 1e3
    names = sweep_names(steps)
    jets = driving_jet_labels(steps)
    phases = load_phases(steps)
    columns = min(3, len(names))
    rows_count = -(-len(names) // columns)
    figure, axes = subplots(rows_count, columns, squeeze=False, sharey=True,
                            figsize=(max(4.3 * columns, 7.0), 3.1 * rows_count + 0.9))
    for axis in axes.flat[len(names):]:
        axis.set_visible(False)
    colours = {"x": "C0", "y": "C1", "z": "C2"}
    for axis, (sweep, name) in zip(axes.flat, names.items()):
        in_sweep = np.flatnonzero(steps.sweep == sweep)
        if sweep >= 0 and jets[in_sweep[0]] != "none":
            jet = int(jets[in_sweep[0]].split()[1])
            force, xlabel = steps.jet_forces_n[:, jet - 1], f"jet {jet} force q{jet} (N)"
            title = f"sweep {sweep}: jet {jet} swept"
        else:
            force, xlabel = steps.jet_forces_n.sum(axis=1), "total jet force q1+q2+q3 (N)"
            title = name
        for phase, rows in sweep_passes(steps, sweep, phases):
            style = PASS_STYLE.get(phase, {"linestyle": "none"})
            for component, label in enumerate(COMPONENTS):
                axis.plot(force[rows], moment[rows, component], color=colours[label], marker=".", linewidth=1,
                          **style)
            axis.plot(force[rows], np.linalg.norm(moment[rows], axis=1), color="k", marker="o", markersize=3,
                      linewidth=1.5, **style)
        zero_line(axis)
        axis.set_title(title)
        axis.set_xlabel(xlabel)
        axis.set_ylabel("disturbance moment (mN m)")
    handles = [Line2D([], [], color=colours[c], marker=".", label=f"m_{c} (tip frame)") for c in COMPONENTS]
    handles.append(Line2D([], [], color="k", marker="o", markersize=3, linewidth=1.5, label="norm |m|"))
    figure_legend(figure, handles + _pass_handles())
    figure.suptitle(f"{model_name}: {MISSING_LABEL}: the online disturbance moment against jet force, per sweep")
    return figure


@styled
def before_after_rmse_figure(before: dict[str, Comparison], after: dict[str, Comparison], model_name: str):
    """RMS errors per sweep and overall, before and after, as grouped bars with their
    values written on them, on a log axis when the bars span an order of magnitude."""
    sweeps = list(after["ref"].by_sweep)
    groups = ["all sweeps"] + [f"sweep {s}" for s in sweeps]
    bars = [(key, when, results[key]) for key in after
            for when, results in (("before", before), ("after", after)) if key in results]
    figure, axes = subplots(1, 2, figsize=(13, 4.6))
    width = 0.8 / len(bars)
    x = np.arange(len(groups))
    for axis, name, unit, title in ((axes[0], "orientation_rmse_deg", "orientation RMSE (deg)", "tip orientation"),
                                    (axes[1], "position_rmse_mm", "position RMSE (mm)", "tip position")):
        heights = []
        for index, (key, when, comparison) in enumerate(bars):
            summaries = [comparison.overall] + [comparison.by_sweep[s] for s in sweeps]
            values = [getattr(summary, name) for summary in summaries]
            if any(value is None for value in values):
                continue
            heights += values
            container = axis.bar(x + (index - (len(bars) - 1) / 2) * width, values, width,
                                 label=f"{SHORT_LABELS[key]} {when}", color=f"C{index // 2}",
                                 alpha=0.4 if when == "before" else 1.0, hatch="//" if when == "before" else None,
                                 edgecolor=f"C{index // 2}", linewidth=0.6)
            axis.bar_label(container, fmt="%.2g", fontsize=6.5, padding=1.5, rotation=90)
        axis.set_xticks(x, groups)
        axis.set_xlabel("sweeps (RMS over each sweep's steps)")
        axis.set_ylabel(unit)
        axis.set_title(title)
        if not heights:
            axis.text(0.5, 0.5, "no measured tip position", ha="center", transform=axis.transAxes)
            continue
        _log_if_wide(axis, heights)
        if axis.get_yscale() == "log":
            axis.set_ylim(min(heights) / 2.0, max(heights) * 6.0)  # room for the rotated labels
        else:
            axis.set_ylim(0.0, max(heights) * 1.3)
    figure_legend(figure, axes[0].get_legend_handles_labels()[0])
    figure.suptitle(f"{model_name}: RMS errors before (pale, hatched) and after (solid) the change")
    return figure


@styled
def before_after_disturbance_figure(before: Comparison, after: Comparison, steps: Dataset, model_name: str):
    """Norm of the online disturbance moment at each step, before and after: it shrinks
    when the change explains the physics the disturbance was absorbing."""
    figure, axis = subplots(figsize=(11, 4.2))
    index = np.arange(len(steps))
    norms = {}
    for when, comparison, style in (("before", before, {"linestyle": (0, (4, 2)), "color": "C3"}),
                                    ("after", after, {"linestyle": "-", "color": "C0"})):
        norms[when] = np.linalg.norm(comparison.predictions.disturbance_moment_nm, axis=1) * 1e3
        for number, sweep in enumerate(np.unique(steps.sweep)):
            rows = np.flatnonzero(steps.sweep == sweep)
            axis.plot(index[rows], norms[when][rows], marker=".", markersize=3, linewidth=1.1,
                      label=None if number else f"{when} the change", **style)
    sweep_boundaries(axis, steps.sweep)
    for sweep, name in sweep_names(steps).items():
        middle = float(np.mean(np.flatnonzero(steps.sweep == sweep)))
        axis.annotate(name, (middle, 1.0), xycoords=("data", "axes fraction"), ha="center", va="bottom",
                      fontsize=7.5, color="0.3")
    all_norms = np.concatenate(list(norms.values()))
    if all_norms.min() > 0.0 and all_norms.max() > LOG_RATIO * all_norms.min():
        axis.set_yscale("log")
    axis.set_xlabel("step, in session order (grey lines separate the sweeps)")
    axis.set_ylabel("disturbance moment norm (mN m)" + (", log scale" if axis.get_yscale() == "log" else ""))
    figure_legend(figure, axis.get_legend_handles_labels()[0], title="parameters")
    figure.suptitle(f"{model_name}: {MISSING_LABEL}: the online disturbance moment before and after the change")
    return figure
