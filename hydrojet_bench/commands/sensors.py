"""`hydrojet-bench sensors INPUT [--report DIR] [--json PATH]`: the IMUs against the EM tracker.

Compares the tip orientation relative to the base measured by the two ICM-20948s (fused
by the profile's `[imu] fusion` filter) with the EM tracker's over a session log: RMS and
largest angle, accuracy and drift in static holds, per-axis and heading/tilt errors
(`hydrojet_bench.analysis.sensors`). Then it answers "are the IMUs good enough for the
online correction?": calibrated once on the EM calibration poses (or given --params),
the online disturbance estimator runs over the settled steps fed by EM and fed by IMU
orientations, each scored against the EM measurement beside Ref.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.console import Console

from ..analysis.sensors import (AXES, DEFAULT_MIN_HOLD_S, DEFAULT_SETTLE_S, FRAME_RULE, METHODS,
                                AlignedOrientations, AngleSummary, EstimatorComparison, SensorAgreement,
                                compare_estimators, hold_label, imu_profile, sensor_agreement)
from ..data.dataset import Dataset
from ..errors import ConvergenceError, UserError
from ..estimation.calibration import CalibrationResult, TooFewPoses, calibrate_dataset
from ..estimation.setup_warnings import calibration_warnings
from ..logs import read_log
from ..logs.dataset import SAMPLE_TOPIC, dataset_from_log, em_frame_numbers, empty_note, logged_model
from ..logs.topics import EmFrame, Sample
from ..model_choice import ModelChoice, ModelDefaults, model_choice
from ..params import ModelParameters
from ..profile import RigProfile
from . import render
from .calibrate import UNTRUSTED, calibration_exit_code
from .figure_options import add_format_argument
from .common import SESSION_LOG, add_input_arguments, add_model_arguments
from .log_notice import (warn, warn_if_fitted_on, warn_if_incomplete, warn_if_recorded_elsewhere,
                         warn_if_scored_on_own_fit, warn_if_streams_fell_short, warn_if_uncalibrated)

# The longest EM gap --max-gap may bridge, s. A slerp across a gap assumes the tip turned
# steadily in between; a minute already spans twelve of the paper's 5 s steps and three
# of imu-vs-em's 20 s holds, so a longer gap would score the IMUs against orientations
# the tip never had (and 1e308 s printed as "gaps up to inf ms").
MAX_GAP_LIMIT_S = 60.0

SHORT_LABELS = {"ref": "Ref.", "online_em": "Proposed, fed by EM", "online_imu": "Proposed, fed by IMU"}


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("sensors", help="IMU against EM tracker over a session log, and whether the "
                                   "IMUs are good enough for online estimation")
    add_input_arguments(parser, SESSION_LOG + " with IMUs and EM tracker")
    add_model_arguments(parser, default="the live one",
                        params="the parameters for the estimation (default: calibrate on the log's EM "
                               "calibration poses)")
    parser.add_argument("--min-hold", type=float, default=DEFAULT_MIN_HOLD_S, metavar="S",
                        help=f"a command held at least this long is a static pose (default {DEFAULT_MIN_HOLD_S:g} s)")
    parser.add_argument("--settle", type=float, default=DEFAULT_SETTLE_S, metavar="S",
                        help=f"ignore the first S seconds of each hold (default {DEFAULT_SETTLE_S:g} s)")
    parser.add_argument("--max-gap", type=float, metavar="S",
                        help="largest interval between EM samples to interpolate across, at most "
                             f"{MAX_GAP_LIMIT_S:g} s (default: any without a tracker frame lost, from the frame "
                             "numbers the log records; 1.5 EM periods in a log without them)")
    render.add_json_argument(parser)
    parser.add_argument("--report", type=Path, metavar="DIR", help="write figures to this folder")
    add_format_argument(parser)
    render.add_exit_codes(parser, {UNTRUSTED: "its own calibration (no --params) did not converge or left a value "
                                              "on a bound: the estimation figures are of untrusted parameters"})
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    check_options(args)
    # Every input and output is checked before the analysis, whose tables would
    # otherwise be printed in full above the one line that refuses them.
    render.check_json_output(args.json)
    sources = load_sources(args.input, args.profile)
    em, imu = sources.em, sources.imu
    choice, params = choose_parameters(args, em, sources.metadata)
    log_damage = warn_if_incomplete(args.input)
    # A --profile of another rig models that rig's mountings and gravity, as calibrate does.
    profile_mismatch = warn_if_recorded_elsewhere(args.input, args.profile, em.profile)
    streams_short = warn_if_streams_fell_short(args.input)
    console = render.console_for(args)
    try:
        agreement = sensor_agreement(imu, em, args.max_gap, args.min_hold, args.settle, sources.em_frames)
    except ValueError as error:
        raise UserError(f"{args.input}: cannot align the IMU and EM samples: {error}") from None
    heading = heading_unobservable(em.profile, agreement)
    print_agreement(console, agreement, args.input)
    if sources.em_frames is None and args.max_gap is None:
        warn(f"{args.input}: the log does not give every EM sample's tracker frame number (/em/frame records "
             "missing or damaged), so EM gaps are judged on the host's stamps, whose jitter may drop IMU samples "
             "next to frames that were not lost (see 'dropped')")
    if heading is not None:
        warn(heading)
    skipped = None
    try:
        estimation = estimate(args, choice, params, em, imu)
    except EstimationSkipped as reason:
        estimation, skipped = None, str(reason)
        console.print(f"[yellow]{render.plain(skipped)}: online estimation skipped[/]")
    if estimation is not None:
        print_estimation(console, estimation)
    if args.json:
        render.write_json(args.json, {
            "log": str(args.input), **agreement.as_dict(),
            "online_estimation": None if estimation is None else estimation.as_dict(),
            "online_estimation_skipped": skipped,
            "log_damage": log_damage, "profile_mismatch": profile_mismatch, "streams_below_rate": streams_short,
            "heading_unobservable": heading})
    if args.report:
        from ..analysis.sensor_plots import write_sensor_report

        for path in write_sensor_report(args.report, agreement, args.figure_format):
            console.print(f"wrote {render.plain(path)}")
    # As calibrate and replay: figures of parameters whose fit is not to be trusted.
    return calibration_exit_code(None if estimation is None else estimation.calibration)


def heading_unobservable(profile: RigProfile, agreement: SensorAgreement) -> str | None:
    """Why the heading figures mean nothing when the IMUs were fused without their
    magnetometers (None when they were not): gravity pins each filter's tilt only, so
    the two filters start their headings each from its own convention and the tip's
    heading relative to the base is that start plus the gyros' drift."""
    if profile.config.imu.use_magnetometer:
        return None
    return (f"the IMUs were fused without magnetometers (imu.use_magnetometer = false in {profile.source}): nothing "
            "fixes the tip's heading relative to the base's, which is where the two filters started it plus the "
            f"gyros' drift, so the heading error ({agreement.axes.heading_mean_deg:+.2f} deg mean) and every angle "
            "that includes it (all, held, moving, bias, the IMU-fed estimation) measure that, not accuracy; the tilt "
            f"({agreement.axes.tilt_rms_deg:.2f} deg RMS) is the comparable figure")


def check_options(args: argparse.Namespace) -> None:
    """--min-hold, --settle and --max-gap are seconds >= 0; --max-gap at most a minute."""
    for option in ("min_hold", "settle", "max_gap"):
        value = getattr(args, option)
        if value is not None and not (np.isfinite(value) and value >= 0):
            raise UserError(f"--{option.replace('_', '-')} must be a number of seconds >= 0, got {value}")
    if args.max_gap is not None and args.max_gap > MAX_GAP_LIMIT_S:
        raise UserError(f"--max-gap must be at most {MAX_GAP_LIMIT_S:g} s (a longer EM gap spans several plan "
                        f"steps), got {args.max_gap}")


@dataclass(frozen=True)
class Sources:
    """A session log's EM samples, its IMU samples (with the IMU earth frame's gravity,
    `imu_profile`), the tracker frame number of each EM sample (None if the log does
    not say) and the log's metadata."""

    em: Dataset
    imu: Dataset
    em_frames: np.ndarray | None
    metadata: dict


def load_sources(log: Path, profile: str | None) -> Sources:
    """The log's samples (`Sources`). A log without samples of both sources is a
    `UserError` that says what it lacks."""
    contents = read_log(log, topics=[SAMPLE_TOPIC, EmFrame.topic])
    sources = {sample.source for sample in contents.on(Sample)}
    for source, what in (("imu", "IMU"), ("em", "EM tracker")):
        if source not in sources:
            raise UserError(missing_source(log, what, source, sources, contents.truncated))
    em = dataset_from_log(log, profile, source="em")
    return Sources(em, dataset_from_log(log, imu_profile(em.profile), source="imu"),
                   em_frame_numbers(contents, em.time_s), contents.metadata)


def missing_source(log: Path, what: str, source: str, sources: set[str], truncated: bool) -> str:
    """Why ``log``, whose samples come from ``sources``, has none from ``source``
    (``what``, in words), in one line: an empty file, a log cut before its first sample,
    or a session recorded without that device."""
    if empty_note(log):
        return (f"{log}: the file is empty (0 bytes): no session log (its session stopped before writing anything, "
                "or it was never written)")
    cut = " (the session was stopped, or the file was cut)"
    if not sources:
        if truncated:
            return f"{log}: no {SAMPLE_TOPIC} samples at all: the log is truncated before its first one{cut}"
        return (f"{log}: no {SAMPLE_TOPIC} samples at all; `sensors` needs a session recorded with both the IMUs "
                "and the EM tracker")
    lacking = f"{log}: no {what} samples ({SAMPLE_TOPIC} with source {source!r}), only {', '.join(sorted(sources))}"
    if truncated:
        return f"{lacking}: the log is truncated{cut}, and `sensors` needs both the IMUs and the EM tracker"
    return f"{lacking}; `sensors` needs a session recorded with both the IMUs and the EM tracker"


def choose_parameters(args: argparse.Namespace, em: Dataset,
                      metadata: dict[str, dict[str, str]]) -> tuple[ModelChoice, ModelParameters | None]:
    """The model (the live one unless --model, --effect or --params say otherwise) and the
    --params values on the log's profile (None without --params: calibrated later)."""
    model_name, effects = logged_model(args.input, metadata)
    live = ModelDefaults(model_name, effects, origin=f"{args.input}, metadata bench.model/effects")
    choice = model_choice(args, live)
    if args.params is None:
        return choice, None
    return choice, choice.parameters(em.profile.model_parameters())


@dataclass(frozen=True)
class Estimation:
    """The online estimator fed by each source (``comparison``), the line naming the
    model and its parameters (``model_line``), the own calibration on the EM
    calibration poses (None with --params) and the notice when the steps scored are
    the ones the parameters were fitted on (``training``: training errors)."""

    comparison: EstimatorComparison
    model_line: str
    calibration: CalibrationResult | None
    training: str | None

    def as_dict(self) -> dict:
        return {"model": self.model_line, "calibration": calibration_figures(self.calibration),
                "held_out": self.training is None, "training_notice": self.training, **self.comparison.as_dict()}


def calibration_figures(result: CalibrationResult | None) -> dict | None:
    """The own calibration for the JSON document, with the keys replay writes: whether
    it converged (and why, in words) and the values on a bound; None with --params."""
    if result is None:
        return None
    return {"poses": result.poses, "rms_orientation_deg_before": result.rms_orientation_deg_before,
            "rms_orientation_deg_after": result.rms_orientation_deg_after,
            "parameters": dict(zip(result.names, map(float, result.values))), "converged": result.converged,
            "convergence": result.convergence, "at_bound": list(result.at_bound)}


class EstimationSkipped(Exception):
    """Why there is no online estimation to show (the agreement tables still stand)."""


def estimate(args: argparse.Namespace, choice: ModelChoice, params: ModelParameters | None, em: Dataset,
             imu: Dataset) -> Estimation:
    """The online estimator fed by each source; `EstimationSkipped` when there is nothing
    to calibrate on. ``params``: those of --params, else None to calibrate on the EM
    calibration poses."""
    em_steps, imu_steps = em.quasistatic_steps(), imu.quasistatic_steps()
    model = choice.model
    calibration = None
    if params is not None:
        origin = f"parameters from {args.params}"
        warn_if_uncalibrated(choice, em.profile)
    else:
        poses = em_steps.calibration_rows().valid_rows()
        if len(poses) == 0:
            raise EstimationSkipped("no EM calibration poses (sweep -1) in the log and no --params")
        try:
            calibration = calibrate_dataset(model, poses, em.profile.model_parameters(), choice.calibration_names)
        except TooFewPoses as error:
            raise EstimationSkipped(f"no calibration to estimate with: {error} (give --params, or record more "
                                    "calibration poses)") from None
        except (ValueError, ConvergenceError) as error:
            raise UserError(f"{args.input}: cannot calibrate {model.name} on the EM calibration poses: "
                            f"{error}") from None
        params = calibration.params
        origin = (f"calibrated on {len(poses)} EM poses, RMS {calibration.rms_orientation_deg_before:.2f} -> "
                  f"{calibration.rms_orientation_deg_after:.2f} deg")
        for warning in calibration_warnings(model, calibration):
            render.progress_console().print(f"[yellow]warning:[/] {render.plain(warning)}")
    try:
        comparison = compare_estimators(model, params, em_steps, imu_steps, em.profile.online_settings())
    except ValueError as error:
        raise UserError(f"{args.input}: {error}") from None
    except ConvergenceError as error:
        raise UserError(f"{args.input}: {model.name} did not converge on a logged step: {error}") from None
    # Without sweeps the steps scored are the calibration poses: those fitted, by this
    # calibration or by the --params file's own on this log.
    training = (warn_if_scored_on_own_fit(args.input, comparison.steps) if calibration is not None
                else warn_if_fitted_on(choice, args.input, comparison.steps))
    effects = ", ".join(effect.name for effect in model.effects)
    return Estimation(comparison, f"{model.name} ({effects}); {origin}", calibration, training)


# --- console -------------------------------------------------------------------------


def _deg(value: float | None, signed: bool = False) -> str:
    return "-" if value is None else f"{value:+.2f}" if signed else f"{value:.2f}"


def _hz(rate: float | None) -> str:
    return "-" if rate is None else f"{rate:.1f} Hz"


def _bridging(aligned: AlignedOrientations) -> str:
    """How the EM samples were slerped to the IMU stamps, and what made a gap."""
    if aligned.gap_rule == FRAME_RULE:
        return (f"slerped to the IMU stamps between EM samples of consecutive tracker frames (intervals up to "
                f"{aligned.max_gap_s * 1e3:.0f} ms; a gap: a tracker frame lost)")
    return f"slerped to the IMU stamps across intervals up to {aligned.max_gap_s * 1e3:.0f} ms"


def print_agreement(console: Console, agreement: SensorAgreement, log: Path) -> None:
    aligned, axes = agreement.aligned, agreement.axes
    table = render.table(
        f"IMU against EM: tip orientation in the base frame, {log}", labels=("samples",),
        numbers=("n", "RMS (deg)", "mean (deg)", "max (deg)"),
        caption=f"{len(aligned)} of {aligned.imu_samples} IMU samples ({_hz(aligned.imu_rate_hz)}) aligned "
                f"with {aligned.em_samples} EM samples ({_hz(aligned.em_rate_hz)}), {_bridging(aligned)}; "
                f"dropped: {aligned.dropped.describe()}; held: settled part of holds "
                f"of >= {agreement.min_hold_s:g} s after {agreement.settle_s:g} s")

    def row(label: str, summary: AngleSummary | None) -> None:
        if summary is None:
            table.add_row(label, "0", "-", "-", "-")
        else:
            table.add_row(label, str(summary.count), _deg(summary.rms_deg), _deg(summary.mean_deg),
                          _deg(summary.max_deg))

    row("all", agreement.overall)
    row("held", agreement.held)
    row("moving", agreement.moving)
    console.print(table)

    table = render.table("Per-axis error (IMU relative to EM, rotation vector in the base frame)",
                         labels=("component",), numbers=("RMS (deg)", "mean (deg)", "drift (deg/min)"),
                         caption="heading: about up (against gravity), where the magnetometers and gyros rule; "
                                 "tilt: the rest, pinned by gravity")
    for i, axis in enumerate(AXES):
        table.add_row(f"base {axis}", _deg(axes.rms_deg[i]), _deg(axes.mean_deg[i], signed=True), "")
    table.add_row("heading", _deg(axes.heading_rms_deg), _deg(axes.heading_mean_deg, signed=True),
                  _deg(agreement.heading_trend_deg_per_min, signed=True))
    table.add_row("tilt", _deg(axes.tilt_rms_deg), _deg(axes.tilt_mean_deg), "")
    table.add_row("angle", _deg(agreement.overall.rms_deg), _deg(agreement.overall.mean_deg),
                  _deg(agreement.trend_deg_per_min, signed=True))
    console.print(table)

    if not agreement.holds:
        console.print(f"no static hold (a command held >= {agreement.min_hold_s:g} s, with samples after its first "
                      f"{agreement.settle_s:g} s); see --min-hold and --settle", highlight=False)
        return
    table = render.table("Static accuracy: settled part of each hold", labels=("hold", "q (mN)"),
                         numbers=("n", "mean", "SD", "bias", "heading", "tilt", "trend"),
                         caption="angles in deg; bias: between the mean orientations; heading signed; trend in "
                                 "deg/min; across holds "
                                 f"{_deg(agreement.across_holds_deg_per_min, signed=True)}, within holds (mean) "
                                 f"{_deg(agreement.within_holds_deg_per_min, signed=True)}")
    for hold in agreement.holds:
        table.add_row(hold_label(hold), ",".join(f"{f * 1e3:.0f}" for f in hold.jet_forces_n),
                      str(hold.angle.count), _deg(hold.angle.mean_deg), _deg(hold.sd_deg), _deg(hold.bias_deg),
                      _deg(hold.mean_heading_deg, signed=True), _deg(hold.mean_tilt_deg),
                      _deg(hold.trend_deg_per_min, signed=True))
    console.print(table)


def print_estimation(console: Console, estimation: Estimation) -> None:
    comparison = estimation.comparison
    scored = f"{len(comparison.steps)} settled steps"
    if estimation.training is not None:
        scored += ", the calibration poses fitted: training errors, not held-out ones"
    table = render.table(f"Online estimation fed by EM or by IMU, scored against EM ({scored})", labels=("method",),
                         numbers=("orient. RMSE (deg)", "gain", "pos. RMSE (mm)", "gain"),
                         caption=f"{estimation.model_line}; gain: cut in RMS error from Ref. (constant disturbance)")
    for method in METHODS:
        summary = comparison.results[method].overall
        gain = position_gain = None
        if method != "ref":
            gain, position_gain = comparison.gain(method), comparison.position_gain(method)
        table.add_row(SHORT_LABELS[method], _deg(summary.orientation_rmse_deg),
                      "-" if gain is None else f"{gain:+.0%}",
                      "-" if summary.position_rmse_mm is None else f"{summary.position_rmse_mm:.2f}",
                      "-" if position_gain is None else f"{position_gain:+.0%}")
    console.print(table)
