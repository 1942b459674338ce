"""`hydrojet-bench replay LOG [--model M] [--params P] [--effect NAME ...] [--online]`.

Re-runs a session's estimation offline. With the live model and parameters (the
default) it reproduces the live estimates exactly and says so; with another model,
effects or parameter file it shows what those would have done on the same session
(without --params, a changed model is first calibrated on the log's calibration poses).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from rich.console import Console

from ..analysis.compare import compare_steps
from ..effects import qualified_parameter_names
from ..errors import ConvergenceError, UserError
from ..estimation import OnlineSettings
from ..estimation.calibration import DEFAULT_NAMES, calibrate_dataset
from ..params_io import read_parameter_file
from .common import build_model


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("replay", help="re-run a session log's estimation offline")
    parser.add_argument("log", type=Path, help="session log (.mcap) from `hydrojet-bench run`")
    parser.add_argument("--profile", help="rig profile (default: the one embedded in the log)")
    parser.add_argument("--model", choices=("cosserat", "prb"), help="kinematic model (default: the live one)")
    parser.add_argument("--params", type=Path, help="parameter file from `calibrate` (default: the live parameters)")
    parser.add_argument("--effect", action="append", default=[], metavar="NAME",
                        help="add an effect: a library name or path/to/file.py:Class (repeatable)")
    parser.add_argument("--online", action="store_true", help="online disturbance estimation, as live")
    parser.add_argument("--report", type=Path, metavar="DIR", help="write figures to this folder")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..bench.replay import live_difference_deg, read_session, replay
    from .compare import print_tables

    session = read_session(args.log, args.profile)
    console = Console()
    model_name = args.model or session.model_name
    effect_specs = list(session.effects) + args.effect
    params = None
    if args.params is not None:
        parameter_file = read_parameter_file(args.params)
        params = parameter_file.apply(session.profile.model_parameters(), args.params)
        effect_specs = list(parameter_file.effects) + effect_specs
        model_name = args.model or parameter_file.model
    model, requested = build_model(model_name, effect_specs)
    live_settings = params is None and model_name == session.model_name and not args.effect
    if params is None and not live_settings:
        names = DEFAULT_NAMES + tuple(n for effect in requested for n in qualified_parameter_names(effect))
        try:
            calibration = calibrate_dataset(model, session.steps, session.profile.model_parameters(), names)
        except (ValueError, ConvergenceError) as error:
            raise UserError(f"{args.log}: cannot calibrate {model.name} on the logged calibration poses: {error}") \
                from None
        params = calibration.params
        console.print(f"calibrated {model.name} on {len(session.steps.calibration_rows())} logged poses: RMS "
                      f"{calibration.rms_orientation_deg_before:.2f} -> {calibration.rms_orientation_deg_after:.2f} deg")
    online = OnlineSettings() if args.online else None
    estimates = replay(session, model, online, params)
    if session.truncated:
        console.print(f"[yellow]{args.log} is truncated: replaying the {len(session.steps)} steps before the cut[/]")
    kept = [i for i, estimate in enumerate(estimates) if estimate is not None]
    validation = [i for i in kept if session.steps.sweep[i] >= 0] or kept
    if not validation:
        raise UserError(f"{args.log}: the model converged on none of the logged steps")
    steps = session.steps.select(validation)
    results = compare_steps([estimates[i] for i in validation], steps)
    print_tables(console, results, f"{model.name} replayed on {args.log}")
    if live_settings:
        difference = live_difference_deg(session, estimates)
        if difference is None:
            console.print("the log holds no live predictions to compare with")
        else:
            console.print(f"largest difference from the live estimates: {difference:.3g} deg "
                          f"({'identical' if difference == 0 else 'differs'})")
    if args.report:
        from ..analysis.report import write_report

        for path in write_report(args.report, results, steps, model.name):
            console.print(f"wrote {path}")
    missed = len(estimates) - len(kept)
    if missed:
        console.print(f"[yellow]{missed} step(s) did not converge and were left out[/]")
    return 0 if np.isfinite(results["ref"].overall.orientation_rmse_deg) else 1
