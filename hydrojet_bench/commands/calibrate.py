"""`hydrojet-bench calibrate INPUT [--model M] [--effect NAME ...] -o params.toml`.

Fits E0, EL, L and the constant disturbance wrench w_d (plus the parameters of the
--effect's) to the calibration rows (sweep -1) of the input, as in the paper's
sec. V-B, and writes them with their standard errors as a parameter file.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import UserError
from ..estimation.calibration import DEFAULT_POSITION_WEIGHT_RAD_PER_M, calibrate_dataset, parameter_bounds
from ..estimation.setup_warnings import setup_warnings
from ..model_choice import COSSERAT, model_choice
from ..params_io import ParameterFile, write_parameter_file
from . import render
from .common import add_input_arguments, add_model_arguments, load_steps
from .log_notice import warn_if_incomplete


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("calibrate", help="fit model parameters to the calibration poses")
    add_input_arguments(parser)
    add_model_arguments(parser, default=COSSERAT.model)
    parser.add_argument("-o", "--output", type=Path, required=True, help="parameter file to write (TOML); replaced if it exists: it is derived "
                        "from the data, and calibrating again is meant to update it")
    parser.add_argument("--position-weight", type=float, default=DEFAULT_POSITION_WEIGHT_RAD_PER_M,
                        metavar="RAD_PER_M", help="weight of tip position errors when positions were "
                        f"measured (default {DEFAULT_POSITION_WEIGHT_RAD_PER_M:g}; 0 = orientation only)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not args.position_weight >= 0:
        raise UserError(f"--position-weight must be >= 0, got {args.position_weight}")
    profile, steps = load_steps(args.input, args.profile)
    warn_if_incomplete(args.input)
    if len(steps.calibration_rows()) == 0:
        raise UserError(f"{args.input}: no calibration poses (steps of sweep -1) to fit on; record some "
                        "with `hydrojet-bench run --plan calibration`")
    choice = model_choice(args)
    model = choice.model
    try:
        result = calibrate_dataset(model, steps, profile.model_parameters(), choice.calibration_names,
                                   position_weight_rad_per_m=args.position_weight)
    except ValueError as error:
        raise UserError(f"{args.input}: {error}") from None
    console = render.console_for(args)
    table = render.table(f"{model.name} calibrated on {len(steps.calibration_rows())} poses of {args.input}",
                         labels=("parameter",), numbers=("value", "standard error"))
    for name, value, error in zip(result.names, result.values, result.standard_errors):
        table.add_row(name, f"{value:.6g}", f"{error:.2g}")
    console.print(table)
    console.print(f"RMS orientation error on the calibration poses: {result.rms_orientation_deg_before:.2f} deg "
                  f"before, {result.rms_orientation_deg_after:.2f} deg after ({result.evaluations} evaluations)")
    for warning in setup_warnings(result.names, tuple(result.values), lambda name: parameter_bounds(model, name)):
        console.print(f"[yellow]warning:[/] {render.plain(warning)}")
    for first, second, correlation in result.unidentifiable:
        console.print(f"[yellow]warning:[/] {first} and {second} are not separately identifiable on these poses "
                      f"(correlation {correlation:+.3f}); their individual values mean little")
    write_parameter_file(args.output, ParameterFile(
        model=model.name, effects=tuple(effect.name for effect in model.effects),
        parameters=dict(zip(result.names, map(float, result.values))),
        standard_errors=dict(zip(result.names, map(float, result.standard_errors))),
        calibration={"data": str(args.input), "profile": profile.source,
                     "poses": len(steps.calibration_rows()),
                     "rms_orientation_deg_before": round(result.rms_orientation_deg_before, 4),
                     "rms_orientation_deg_after": round(result.rms_orientation_deg_after, 4)}))
    console.print(f"wrote {render.plain(args.output)}")
    return 0
