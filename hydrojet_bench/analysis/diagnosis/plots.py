"""Report figures for `diagnose` (PNG, matplotlib Agg, as `analysis.report`)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: the bench machines have no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ...errors import UserError  # noqa: E402
from ..report import _save  # noqa: E402
from .engine import NONE, Diagnosis  # noqa: E402


def write_diagnosis_report(folder: Path, diagnosis: Diagnosis) -> list[Path]:
    """Write the figures into ``folder`` (created if needed); returns their paths."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise UserError(f"cannot create report folder {folder}: {error.strerror}") from None
    return [_ranking(folder, diagnosis), _signature(folder, diagnosis)]


def _ranking(folder: Path, diagnosis: Diagnosis) -> Path:
    """Held-out RMSE per candidate against the baseline and the noise floor."""
    ranked = [c for c in diagnosis.ranking if c.error is None]
    figure, axis = plt.subplots(figsize=(9, 0.45 * len(ranked) + 1.8))
    names = [c.effect for c in ranked][::-1]
    values = [c.heldout_orientation_rmse_deg for c in ranked][::-1]
    colours = ["C2" if name == diagnosis.verdict else ("C0" if c.qualifies else "0.6")
               for name, c in zip(names, ranked[::-1])]
    axis.barh(names, values, color=colours)
    axis.axvline(diagnosis.baseline_heldout_rmse_deg, color="C3", linestyle="--",
                 label=f"baseline {diagnosis.baseline_heldout_rmse_deg:.3f} deg")
    axis.axvline(diagnosis.noise_floor_deg, color="k", linestyle=":",
                 label=f"noise floor {diagnosis.noise_floor_deg:.3f} deg")
    axis.axvline(diagnosis.at_floor_threshold_deg, color="0.4", linestyle=":", linewidth=0.8,
                 label=f"at the floor up to {diagnosis.at_floor_threshold_deg:.3f} deg")
    axis.set_xlabel("held-out orientation RMSE (deg)")
    axis.set_title(f"{diagnosis.model}: baseline + each candidate; verdict: {diagnosis.verdict}")
    axis.legend(loc="lower right", fontsize=8)
    figure.tight_layout()
    return _save(figure, folder / "diagnose_ranking.png")


def _signature(folder: Path, diagnosis: Diagnosis) -> Path:
    """The baseline's residual and the online disturbance estimate over the held-out
    steps, against the signature of the winner (or of the best-ranked candidate)."""
    name = diagnosis.verdict if diagnosis.winner is not None else next(
        (c.effect for c in diagnosis.ranking if c.effect in diagnosis.signatures_deg), None)
    figure, axes = plt.subplots(2, 1, figsize=(13, 7), sharex=True)
    index = np.arange(len(diagnosis.held_out_rows))
    residual = diagnosis.baseline_residual_deg
    missing = diagnosis.online.missing_moment_nm * 1e3
    signature = diagnosis.signatures_deg.get(name) if name else None
    for component, axis_name in enumerate("xyz"):
        colour = f"C{component}"
        axes[0].plot(index, residual[:, component], ".", color=colour, markersize=3,
                     label=f"baseline residual {axis_name}")
        axes[1].plot(index, missing[:, component], ".", color=colour, markersize=3,
                     label=f"online estimate {axis_name}")
        if signature is not None:
            axes[0].plot(index, signature[:, component], "-", color=colour, linewidth=1,
                         label=f"{name} signature {axis_name}")
            moment = diagnosis.online.equivalent_moment_nm(np.radians(signature)) * 1e3
            axes[1].plot(index, moment[:, component], "-", color=colour, linewidth=1,
                         label=f"{name} as a moment {axis_name}")
    for boundary in np.flatnonzero(np.diff(diagnosis.held_out_sweep)) + 0.5:
        for axis in axes:
            axis.axvline(boundary, color="0.85", linewidth=0.8)
    axes[0].set_ylabel("tip rotation (deg, tip sensor frame)")
    axes[1].set_ylabel("moment (mN m, tip frame)")
    axes[1].set_xlabel("held-out step (sweeps separated by grey lines)")
    verdict = ("verdict none: nothing missing" if diagnosis.verdict == NONE else
               f"winner {name}" if diagnosis.winner is not None else f"best candidate {name}, not significant")
    axes[0].set_title(f"{diagnosis.model}: baseline residual (dots) and what {name or '-'} changes (lines); {verdict}")
    axes[1].set_title("online disturbance estimate minus calibrated w_d (dots: what the model is missing) "
                      "and the signature as a moment (lines)")
    for axis in axes:
        axis.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    figure.tight_layout()
    return _save(figure, folder / "diagnose_signature.png")
