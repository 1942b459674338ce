"""`hydrojet-bench replay INPUT [--model M] [--params P] [--effect NAME ...] [--online] [--json PATH]`.

Re-runs a session's estimation offline (`hydrojet_bench.api.replay`). With the live model
and parameters (the default) it reproduces the live estimates exactly and says so; with
another model, effects or parameter file it shows what those would have done on the same
session (without --params, a changed model is first calibrated on the log's calibration
poses).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ..estimation.setup_warnings import calibration_warnings
from ..model_choice import choose_model
from ..profile import load_profile
from . import render
from .calibrate import UNTRUSTED, calibration_exit_code
from .common import SESSION_LOG, add_input_arguments, add_model_arguments
from .figure_options import add_format_argument
from .log_notice import warn_if_fitted_on, warn_if_incomplete, warn_if_recorded_elsewhere, warn_if_scored_on_own_fit


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("replay", help="re-run a session log's estimation offline")
    add_input_arguments(parser, SESSION_LOG)
    add_model_arguments(parser, default="the live one",
                        params="the parameters to replay with (default: the live ones)")
    parser.add_argument("--online", action="store_true", help="online disturbance estimation, as live")
    render.add_json_argument(parser)
    parser.add_argument("--report", type=Path, metavar="DIR", help="write figures to this folder")
    add_format_argument(parser)
    render.add_exit_codes(parser, {1: "the replayed errors are not finite (no answer)",
                                   UNTRUSTED: "its own calibration (another model, no --params) did not converge "
                                              "or left a value on a bound: the figures are of untrusted parameters"})
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..api import replay
    from .compare import print_tables

    result = replay(args.input, model=args.model, effects=args.effect, params=args.params, online=args.online,
                    profile=args.profile)
    warn_if_incomplete(args.input)
    profile_mismatch = (None if args.profile is None
                        else warn_if_recorded_elsewhere(args.input, args.profile, load_profile(args.profile)))
    # Parameters calibrated on this log's sweeps replay training errors, not held-out ones.
    # So do those calibrated here on its poses when it has no sweeps to hold out.
    if args.params is not None:
        fitted_on = warn_if_fitted_on(choose_model(None, (), args.params), args.input, result.steps)
    else:
        fitted_on = None if result.calibration is None else warn_if_scored_on_own_fit(args.input, result.steps)
    console = render.console_for(args)
    warnings = render.progress_console()
    model = result.model
    for note in result.uncalibrated:
        warnings.print(f"[yellow]warning:[/] {render.plain(note)}")
    if result.calibration is not None:
        console.print(f"calibrated {model.name} on {result.calibration_poses} logged poses: RMS "
                      f"{result.calibration.rms_orientation_deg_before:.2f} -> "
                      f"{result.calibration.rms_orientation_deg_after:.2f} deg")
        for warning in calibration_warnings(model, result.calibration):
            warnings.print(f"[yellow]warning:[/] {render.plain(warning)}")
    print_tables(console, result.results, f"{model.name} replayed on {args.input}")
    if result.live_settings:
        if result.live_difference_deg is None:
            console.print("the log holds no live predictions to compare with")
        else:
            missing = result.logged_steps - result.live_steps_compared
            over = (f" over {result.live_steps_compared} of {result.logged_steps} steps (the log holds no live "
                    f"prediction of the other {missing})" if missing else "")
            console.print(f"largest difference from the live estimates: {result.live_difference_deg:.3g} deg "
                          f"({'identical' if result.live_difference_deg == 0 else 'differs'}){over}")
    if args.report:
        from ..analysis.report import write_report

        for path in write_report(args.report, result.results, result.steps, model.name,
                                 figure_format=args.figure_format):
            console.print(f"wrote {render.plain(path)}")
    if result.skipped:
        warnings.print(f"[yellow]warning:[/] {result.skipped} step(s) did not converge and were left out")
    if args.json:
        render.write_json(args.json, {**result.as_dict(), "profile_mismatch": profile_mismatch,
                                      "held_out": fitted_on is None})
    if not np.isfinite(result.results["ref"].overall.orientation_rmse_deg):
        return 1
    return calibration_exit_code(result.calibration)
