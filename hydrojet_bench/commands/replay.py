"""`hydrojet-bench replay INPUT [--model M] [--params P] [--effect NAME ...] [--online]`.

Re-runs a session's estimation offline. With the live model and parameters (the
default) it reproduces the live estimates exactly and says so; with another model,
effects or parameter file it shows what those would have done on the same session
(without --params, a changed model is first calibrated on the log's calibration poses).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ..analysis.compare import compare_steps
from ..errors import ConvergenceError, UserError
from ..estimation import OnlineSettings
from ..estimation.calibration import calibrate_dataset
from ..model_choice import ModelDefaults, model_choice
from . import render
from .figure_options import add_format_argument
from .common import SESSION_LOG, add_input_arguments, add_model_arguments
from .log_notice import warn_if_incomplete


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("replay", help="re-run a session log's estimation offline")
    add_input_arguments(parser, SESSION_LOG)
    add_model_arguments(parser, default="the live one",
                        params="the parameters to replay with (default: the live ones)")
    parser.add_argument("--online", action="store_true", help="online disturbance estimation, as live")
    parser.add_argument("--report", type=Path, metavar="DIR", help="write figures to this folder")
    add_format_argument(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..bench.replay import live_difference_deg, read_session, replay
    from .compare import print_tables

    session = read_session(args.input, args.profile)
    warn_if_incomplete(args.input)
    console = render.console_for(args)
    choice = model_choice(args, ModelDefaults(session.model_name, session.effects))
    model = choice.model
    params = None if args.params is None else choice.parameters(session.profile.model_parameters())
    live_settings = params is None and model.name == session.model_name and not args.effect
    if params is None and not live_settings:
        try:
            calibration = calibrate_dataset(model, session.steps, session.profile.model_parameters(),
                                            choice.calibration_names)
        except (ValueError, ConvergenceError) as error:
            raise UserError(f"{args.input}: cannot calibrate {model.name} on the logged calibration poses: "
                            f"{error}") from None
        params = calibration.params
        console.print(f"calibrated {model.name} on {len(session.steps.calibration_rows())} logged poses: RMS "
                      f"{calibration.rms_orientation_deg_before:.2f} -> {calibration.rms_orientation_deg_after:.2f} deg")
    online = OnlineSettings() if args.online else None
    estimates = replay(session, model, online, params)
    kept = [i for i, estimate in enumerate(estimates) if estimate is not None]
    validation = [i for i in kept if session.steps.sweep[i] >= 0] or kept
    if not validation:
        raise UserError(f"{args.input}: the model converged on none of the logged steps")
    steps = session.steps.select(validation)
    results = compare_steps([estimates[i] for i in validation], steps)
    print_tables(console, results, f"{model.name} replayed on {args.input}")
    if live_settings:
        difference = live_difference_deg(session, estimates)
        if difference is None:
            console.print("the log holds no live predictions to compare with")
        else:
            console.print(f"largest difference from the live estimates: {difference:.3g} deg "
                          f"({'identical' if difference == 0 else 'differs'})")
    if args.report:
        from ..analysis.report import write_report

        for path in write_report(args.report, results, steps, model.name,
                                 figure_format=args.figure_format):
            console.print(f"wrote {render.plain(path)}")
    missed = len(estimates) - len(kept)
    if missed:
        console.print(f"[yellow]{missed} step(s) did not converge and were left out[/]")
    return 0 if np.isfinite(results["ref"].overall.orientation_rmse_deg) else 1
