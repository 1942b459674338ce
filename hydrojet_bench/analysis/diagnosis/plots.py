"""Report figures for `diagnose` (styled and written by `analysis.figures`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from ..figures import create_folder, figure_legend, save, styled, subplots, sweep_boundaries, zero_line
from .engine import NONE, Diagnosis

VERDICT_COLOUR, QUALIFIES_COLOUR, OTHER_COLOUR = "C2", "C0", "0.65"


def write_diagnosis_report(folder: Path, diagnosis: Diagnosis, figure_format: str = "png") -> list[Path]:
    """Write the figures into ``folder`` (created if needed) as ``figure_format`` (png,
    svg, pdf); returns their paths."""
    create_folder(folder)
    return [save(ranking_figure(diagnosis), folder / f"diagnose_ranking.{figure_format}"),
            save(signature_figure(diagnosis), folder / f"diagnose_signature.{figure_format}")]


@styled
def ranking_figure(diagnosis: Diagnosis):
    """Held-out RMSE per candidate against the baseline and the noise floor, each bar
    labelled with its value."""
    ranked = [c for c in diagnosis.ranking if c.error is None][::-1]
    figure, axis = subplots(figsize=(9, 0.45 * len(ranked) + 2.2))
    colours = [VERDICT_COLOUR if c.effect == diagnosis.verdict else (QUALIFIES_COLOUR if c.qualifies else OTHER_COLOUR)
               for c in ranked]
    bars = axis.barh([c.effect for c in ranked], [c.heldout_orientation_rmse_deg for c in ranked], color=colours)
    axis.bar_label(bars, fmt="%.3f", fontsize=7.5, padding=2)
    lines = [(diagnosis.baseline_heldout_rmse_deg, {"color": "C3", "linestyle": "--"}, "baseline (no candidate)"),
             (diagnosis.noise_floor_deg, {"color": "k", "linestyle": ":"}, "noise floor"),
             (diagnosis.at_floor_threshold_deg, {"color": "0.4", "linestyle": ":", "linewidth": 0.8},
              "at the floor up to")]
    handles = []
    for value, style, label in lines:
        axis.axvline(value, **style)
        handles.append(Line2D([], [], **style, label=f"{label} {value:.3f} deg"))
    handles += [Patch(color=VERDICT_COLOUR, label="verdict"), Patch(color=QUALIFIES_COLOUR, label="qualifies"),
                Patch(color=OTHER_COLOUR, label="does not qualify")]
    axis.set_xlabel("held-out orientation RMSE (deg)")
    axis.set_ylabel("candidate effect (added to the baseline)")
    axis.set_xlim(0.0, max([diagnosis.baseline_heldout_rmse_deg] + [c.heldout_orientation_rmse_deg for c in ranked])
                  * 1.15)
    axis.grid(axis="y", visible=False)
    figure_legend(figure, handles)
    axis.set_title(f"{diagnosis.model}: held-out error of the baseline plus each candidate; "
                   f"verdict: {diagnosis.verdict}")
    return figure


@styled
def signature_figure(diagnosis: Diagnosis):
    """The baseline's residual and the online disturbance estimate over the held-out
    steps, against the signature of the winner (or of the best-ranked candidate)."""
    name = diagnosis.verdict if diagnosis.winner is not None else next(
        (c.effect for c in diagnosis.ranking if c.effect in diagnosis.signatures_deg), None)
    figure, axes = subplots(2, 1, figsize=(13, 7), sharex=True)
    index = np.arange(len(diagnosis.held_out_rows))
    residual = diagnosis.baseline_residual_deg
    missing = diagnosis.online.missing_moment_nm * 1e3
    signature = diagnosis.signatures_deg.get(name) if name else None
    for component, axis_name in enumerate("xyz"):
        colour = f"C{component}"
        axes[0].plot(index, residual[:, component], ".", color=colour, markersize=3.5, zorder=2,
                     label=f"baseline residual {axis_name}")
        axes[1].plot(index, missing[:, component], ".", color=colour, markersize=3.5, zorder=2,
                     label=f"online estimate {axis_name}")
        if signature is not None:
            axes[0].plot(index, signature[:, component], "-", color=colour, linewidth=1, zorder=3,
                         label=f"{name} signature {axis_name}")
            moment = diagnosis.online.equivalent_moment_nm(np.radians(signature)) * 1e3
            axes[1].plot(index, moment[:, component], "-", color=colour, linewidth=1, zorder=3,
                         label=f"{name} as a moment {axis_name}")
    for axis in axes:
        sweep_boundaries(axis, diagnosis.held_out_sweep)
        zero_line(axis)
        axis.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    axes[0].set_ylabel("tip rotation (deg, tip sensor frame)")
    axes[1].set_ylabel("moment (mN m, tip frame)")
    axes[1].set_xlabel("held-out step (sweeps separated by grey lines)")
    verdict = ("verdict none: nothing missing" if diagnosis.verdict == NONE else
               f"winner {name}" if diagnosis.winner is not None else f"best candidate {name}, not significant")
    axes[0].set_title(f"baseline residual (dots) and what {name or '-'} changes (lines); {verdict}")
    axes[1].set_title("online disturbance estimate minus calibrated w_d (dots: what the model is missing) "
                      "and the signature as a moment (lines)")
    figure.suptitle(f"{diagnosis.model}: the residual the diagnosis explains, on the held-out sweeps")
    return figure
