"""Every report figure, rendered from a small session and read back as matplotlib
objects (not pixels): a title, axis labels with units, a legend, and what each figure
promises a reader (sweeps told apart, passes not joined, shared scales, named jets,
readable bars); then each format of `--format` written."""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.lines import Line2D
from test_analysis_sensors import held_plan_samples

from hydrojet_bench.analysis import report
from hydrojet_bench.analysis.breakdowns import LOADING, UNLOADING, load_phases, orientation_residuals_deg
from hydrojet_bench.analysis.compare import compare_methods
from hydrojet_bench.analysis.diagnosis import diagnose
from hydrojet_bench.analysis.figures import save
from hydrojet_bench.analysis.diagnosis.plots import ranking_figure, signature_figure, write_diagnosis_report
from hydrojet_bench.analysis.sensor_plots import angle_figure, histogram_figure, per_axis_figure, static_holds_figure
from hydrojet_bench.analysis.sensors import sensor_agreement
from hydrojet_bench.commands.figure_options import FIGURE_FORMATS
from hydrojet_bench.effects import load_effect
from hydrojet_bench.estimation import OnlineSettings
from hydrojet_bench.model_choice import build_model
from hydrojet_bench.plans import calibration_plan, validation_sweeps
from hydrojet_bench.profile import load_profile
from hydrojet_bench.twin import DigitalTwin, TwinConfig

CLOGGED_JET = f"{Path(__file__).resolve().parents[2] / 'docs/examples/clogged_jet.py'}:CloggedJet"
# A quantity's unit in parentheses, or a label that counts or names things.
UNIT = re.compile(r"\((deg|mm|min|N|mN m)[,)]")
CATEGORICAL = ("IMU samples", "candidate effect", "static hold", "step, in session order", "held-out step", "sweeps",
               "method")


@pytest.fixture(autouse=True)
def close_figures():
    yield
    plt.close("all")


@pytest.fixture(scope="module")
def session():
    """A twin whose jet 2 is clogged, one sweep per jet up and down in 3 steps; the
    nominal parameters without the effect (before) and with it (after: the twin's truth,
    errors at its noise floor, ~50x below before)."""
    profile = load_profile("sim")
    twin = DigitalTwin(TwinConfig.from_profile(profile, hidden_effects=(load_effect(CLOGGED_JET),), seed=4))
    plan = calibration_plan(6, seed=4) + validation_sweeps(steps_up=3, repetitions=1)
    recorded = twin.run_plan(plan, record_window_s=1.0).to_dataset(profile, "short twin").quasistatic_steps()
    steps = recorded.select(recorded.sweep >= 0)
    params = profile.model_parameters()
    before = compare_methods(build_model("cosserat", [])[0], params, steps, OnlineSettings())
    after = compare_methods(build_model("cosserat", [CLOGGED_JET])[0], params, steps, OnlineSettings())
    return steps, before, after, recorded


def labelled(figure) -> None:
    """A title, both axis labels (units for quantities) on every panel, and a legend."""
    axes = [axis for axis in figure.axes if axis.get_visible()]
    assert figure.get_suptitle() or (len(axes) == 1 and axes[0].get_title())
    for axis in axes:
        for label, shared, name in ((axis.get_xlabel(), axis.get_shared_x_axes(), "xaxis"),
                                    (axis.get_ylabel(), axis.get_shared_y_axes(), "yaxis")):
            if not label:  # a shared axis: labelled on a sibling panel, with the same scale
                label = next(l for s in shared.get_siblings(axis) if (l := getattr(s, name).get_label_text()))
            assert UNIT.search(label) or label.startswith(CATEGORICAL), f"{label!r} names no unit"
    legends = list(figure.legends) + [axis.get_legend() for axis in axes if axis.get_legend() is not None]
    assert legends and all(text.get_text() for legend in legends for text in legend.get_texts())


def legend_labels(figure) -> list[str]:
    return [text.get_text() for legend in figure.legends for text in legend.get_texts()]


def data_lines(axis) -> list[Line2D]:
    """The plotted series, without reference lines (axhline/axvline span [0, 1])."""
    return [line for line in axis.get_lines() if list(line.get_xdata()) != [0, 1]]


def test_tip_paths_tell_sweeps_and_methods_apart_with_lines_above_markers(session):
    steps, _, after, _ = session
    figure = report.tip_paths_figure(after, steps, "cosserat")
    labelled(figure)
    labels = legend_labels(figure)
    for name in ("sweep 0 (jet 1)", "sweep 1 (jet 2)", "sweep 2 (jet 3)", "Ref. (constant disturbance)",
                 "Proposed (online estimation)", "measured tip"):
        assert name in labels
    projection, error = figure.axes[0], figure.axes[-1]
    markers = [line for line in projection.get_lines() if line.get_linestyle() == "None"]
    paths = [line for line in projection.get_lines() if line.get_linestyle() != "None"]
    assert markers and paths and min(p.get_zorder() for p in paths) > max(m.get_zorder() for m in markers)
    # The per-step errors: Ref. and Proposed apart even below a millimetre.
    assert error.get_ylabel() == "tip position error (mm)"
    assert after["online"].position_error_mm.max() < 1.0
    styles = {line.get_linestyle() for line in data_lines(error)}
    assert len(styles) == 2


def test_residual_passes_are_not_joined_and_methods_share_one_scale(session, tmp_path):
    steps, before, _, _ = session
    phases = load_phases(steps)
    limits = report.shared_limits([orientation_residuals_deg(c.predictions, steps)
                                    for c in before.values()])
    figures = {key: report.residuals_figure(key, comparison, steps, "cosserat", limits)
               for key, comparison in before.items()}
    for figure in figures.values():
        labelled(figure)
        assert {"loading pass", "unloading pass"} <= set(legend_labels(figure))
    assert figures["ref"].axes[0].get_ylim() == figures["online"].axes[0].get_ylim()
    against_bend = data_lines(figures["ref"].axes[0])
    # One line per pass of each sweep: up then down is two lines, never one zigzag.
    assert len(against_bend) == 2 * len(steps.sweep_ids())
    for sweep in steps.sweep_ids():
        rows = np.flatnonzero(steps.sweep == sweep)
        (up, up_rows), (down, down_rows) = report.passes(rows, phases)
        assert (up, down) == (LOADING, UNLOADING)
        assert down_rows[0] == up_rows[-1]  # the unloading pass starts at the turning point


def test_calibration_poses_are_points_not_a_path(session):
    """`replay` and `run` pass the calibration poses too: random poses, never joined."""
    _, _, _, recorded = session
    results = compare_methods(build_model("cosserat", [CLOGGED_JET])[0], load_profile("sim").model_parameters(),
                              recorded, OnlineSettings())
    poses = recorded.sweep < 0
    figures = [report.tip_paths_figure(results, recorded, "cosserat"),
               report.residuals_figure("online", results["online"], recorded, "cosserat"),
               report.disturbance_figure(results["online"], recorded, "cosserat")]
    for figure in figures:
        labelled(figure)
        assert "calibration poses" in legend_labels(figure) + [axis.get_title() for axis in figure.axes]
    unjoined = [line for figure in figures[:2] for line in data_lines(figure.axes[0])
                if len(line.get_xdata()) == poses.sum()]
    assert unjoined and all(line.get_linestyle() == "None" for line in unjoined)


def test_disturbance_is_against_each_panels_jet_force(session):
    steps, _, after, _ = session
    figure = report.disturbance_figure(after["online"], steps, "cosserat")
    labelled(figure)
    panels = [axis for axis in figure.axes if axis.get_visible()]
    for jet, axis in enumerate(panels, start=1):
        assert f"jet {jet}" in axis.get_title()
        assert axis.get_xlabel() == f"jet {jet} force q{jet} (N)"


def test_before_after_bars_are_readable_fifty_times_smaller(session):
    steps, before, after, _ = session
    assert after["ref"].overall.orientation_rmse_deg < before["ref"].overall.orientation_rmse_deg / 20
    figure = report.before_after_rmse_figure(before, after, "cosserat")
    labelled(figure)
    for axis in figure.axes:
        assert axis.get_yscale() == "log"
        bars = len(axis.patches)
        assert bars and len([t for t in axis.texts if t.get_text()]) == bars  # each bar shows its value
    figure = report.before_after_disturbance_figure(before["online"], after["online"], steps, "cosserat")
    labelled(figure)
    assert figure.axes[0].get_yscale() == "log"
    labelled(report.error_boxes_figure(after, "cosserat"))


def test_imu_holds_are_named_and_their_settled_windows_skip_the_transient():
    em, imu = held_plan_samples(rate_deg_per_min=0.6)
    agreement = sensor_agreement(imu, em, min_hold_s=10.0, settle_s=2.5)
    for draw in (angle_figure, per_axis_figure, histogram_figure):
        labelled(draw(agreement))
    figure = static_holds_figure(agreement)
    labelled(figure)
    axis = figure.axes[0]
    assert [tick.get_text() for tick in axis.get_xticklabels()] == ["pose 0", "pose 1"]
    assert "first 2.5 s of each hold" in axis.get_title()
    shaded = angle_figure(agreement).axes[0].patches
    settling, settled = shaded[0].get_x(), shaded[1].get_x()
    assert (settling, settled) == pytest.approx((0.0, 2.5 / 60.0))


def test_diagnosis_figures_are_labelled(tmp_path):
    profile = load_profile("sim")
    twin = DigitalTwin(TwinConfig.from_profile(profile, hidden_effects=("jet_gain",),
                                               hidden_effect_values=(("jet_gain.gain_3", 0.85),), seed=3))
    plan = calibration_plan(12) + validation_sweeps(0.1, steps_up=3, repetitions=2)
    steps = twin.run_plan(plan).to_dataset(profile, "short twin").quasistatic_steps()
    diagnosis = diagnose(steps, candidates=(load_effect("jet_gain"),))
    labelled(ranking_figure(diagnosis))
    figure = signature_figure(diagnosis)
    labelled(figure)
    assert diagnosis.verdict in figure.axes[0].get_title()
    for fmt in FIGURE_FORMATS:
        paths = write_diagnosis_report(tmp_path / fmt, diagnosis, fmt)
        assert [p.name for p in paths] == [f"diagnose_ranking.{fmt}", f"diagnose_signature.{fmt}"]


@pytest.mark.parametrize("fmt", FIGURE_FORMATS)
def test_every_format_is_written_and_vector_files_carry_no_date(session, tmp_path, fmt):
    _, before, after, _ = session
    first, second = (save(report.error_boxes_figure(after, "cosserat"), tmp_path / f"{name}.{fmt}")
                     for name in ("first", "second"))
    assert first.read_bytes().startswith({"png": b"\x89PNG", "svg": b"<?xml", "pdf": b"%PDF"}[fmt])
    assert first.read_bytes() == second.read_bytes()  # reruns leave identical files
