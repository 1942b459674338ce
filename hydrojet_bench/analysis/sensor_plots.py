"""Report figures for `sensors` (styled and written by `analysis.figures`): the IMU
against the EM tracker over time, per axis, over the static holds, and as histograms."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .figures import create_folder, figure_legend, save, styled, subplots, zero_line
from .sensors import AXES, SensorAgreement, hold_label


def write_sensor_report(folder: Path, agreement: SensorAgreement, figure_format: str = "png") -> list[Path]:
    """Angle against time, per-axis components, static-hold bars and a histogram in
    ``folder`` (created if needed) as ``figure_format`` (png, svg, pdf); returns their
    paths."""
    create_folder(folder)
    return [save(draw(agreement), folder / f"{name}.{figure_format}") for name, draw in (
        ("angle_vs_time", angle_figure), ("per_axis", per_axis_figure), ("static_holds", static_holds_figure),
        ("histogram", histogram_figure))]


def _shade_holds(axis, agreement: SensorAgreement) -> None:
    """Each hold's settling (rod and fusion-filter transient, left out) pale, and its
    settled window, the one the static figures use, darker."""
    for index, hold in enumerate(agreement.holds):
        first = index == 0
        axis.axvspan((hold.start_s - agreement.settle_s) / 60.0, hold.start_s / 60.0, color="0.95", zorder=0,
                     label=f"hold settling ({agreement.settle_s:g} s, left out)" if first else None)
        axis.axvspan(hold.start_s / 60.0, hold.end_s / 60.0, color="0.84", zorder=0,
                     label="hold, settled window" if first else None)


@styled
def angle_figure(agreement: SensorAgreement):
    """The IMU-against-EM angle at every aligned sample over the session."""
    figure, axis = subplots(figsize=(11, 4))
    _shade_holds(axis, agreement)
    axis.plot(agreement.aligned.time_s / 60.0, agreement.difference.angle_deg, ".", markersize=1.5, color="C0",
              label="IMU against EM, each IMU sample")
    axis.set_xlabel("session time (min)")
    axis.set_ylabel("angle between IMU and EM (deg)")
    axis.set_ylim(bottom=0.0)
    axis.legend(loc="upper left", markerscale=6)
    axis.set_title(f"RMS {agreement.overall.rms_deg:.2f} deg, max {agreement.overall.max_deg:.2f} deg")
    figure.suptitle("Tip orientation relative to the base: IMUs against the EM tracker")
    return figure


@styled
def per_axis_figure(agreement: SensorAgreement):
    """The error rotation vector's base-frame components, then its heading and tilt."""
    difference, minutes = agreement.difference, agreement.aligned.time_s / 60.0
    figure, axes = subplots(2, 1, figsize=(11, 6), sharex=True)
    for i, axis_name in enumerate(AXES):
        axes[0].plot(minutes, difference.rotation_vector_deg[:, i], ".", markersize=1.5, color=f"C{i}",
                     label=f"about base {axis_name}")
    axes[0].set_ylabel("error component (deg)")
    axes[0].set_title("error rotation vector (IMU relative to EM), base (clamp) frame")
    axes[1].plot(minutes, difference.heading_deg, ".", markersize=1.5, color="C3",
                 label="heading: about up (signed)")
    axes[1].plot(minutes, difference.tilt_deg, ".", markersize=1.5, color="C4", label="tilt")
    axes[1].set_ylabel("error (deg)")
    axes[1].set_title("the same error split into heading (magnetometer, gyro drift) and tilt (gravity)")
    axes[1].set_xlabel("session time (min)")
    for axis in axes:
        _shade_holds(axis, agreement)
        zero_line(axis)
        axis.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), markerscale=6)
    figure.suptitle("Per-axis error of the IMU tip orientation against the EM tracker")
    return figure


@styled
def static_holds_figure(agreement: SensorAgreement):
    """Mean angle +- SD, bias and |mean heading| over each hold's settled window."""
    holds = agreement.holds
    figure, axis = subplots(figsize=(max(6.5, 0.7 * len(holds) + 3), 4.4))
    if holds:
        positions = np.arange(len(holds))
        axis.bar(positions, [h.angle.mean_deg for h in holds], yerr=[h.sd_deg for h in holds], color="C0",
                 capsize=3, label="mean angle +- SD (noise included)")
        axis.plot(positions, [h.bias_deg for h in holds], "x", color="k", markersize=6,
                  label="bias: angle between the mean orientations")
        axis.plot(positions, [abs(h.mean_heading_deg) for h in holds], "o", color="C3", fillstyle="none",
                  label="|mean heading error|")
        axis.set_xticks(positions, [hold_label(h) for h in holds], rotation=30 if len(holds) > 8 else 0,
                        ha="right" if len(holds) > 8 else "center")
        figure_legend(figure, axis.get_legend_handles_labels()[0], ncols=1)
    else:
        axis.text(0.5, 0.5, f"no hold of {agreement.min_hold_s:g} s or more", ha="center",
                  transform=axis.transAxes)
    axis.set_xlabel("static hold (calibration pose, or sweep and step)")
    axis.set_ylabel("angle between IMU and EM (deg)")
    axis.set_title(f"settled windows only: the first {agreement.settle_s:g} s of each hold\n"
                   "(rod and fusion-filter transient) left out")
    figure.suptitle("Static accuracy of the IMUs against the EM tracker")
    return figure


@styled
def histogram_figure(agreement: SensorAgreement):
    """Distribution of the angle, and of the signed heading and the tilt."""
    difference = agreement.difference
    figure, axes = subplots(1, 2, figsize=(11, 4))
    axes[0].hist(difference.angle_deg, bins=60, color="C0")
    axes[0].set_xlabel("angle between IMU and EM (deg)")
    axes[0].set_title("angle")
    axes[1].hist(difference.heading_deg, bins=60, alpha=0.6, color="C3", label="heading (signed)")
    axes[1].hist(difference.tilt_deg, bins=60, alpha=0.6, color="C4", label="tilt")
    axes[1].set_xlabel("error (deg)")
    axes[1].set_title("heading (about up) and tilt")
    axes[1].legend()
    for axis in axes:
        axis.set_ylabel("IMU samples")
    figure.suptitle(f"Distribution of the IMU error against the EM tracker ({len(difference.angle_deg)} samples)")
    return figure
