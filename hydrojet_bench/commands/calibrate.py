"""`hydrojet-bench calibrate INPUT [--model M] [--effect NAME ...] [--fit-on ROWS] -o params.toml [--json PATH]`.

Fits E0, EL, L and the constant disturbance wrench w_d (plus the parameters of the
--effect's) to the rows of the input that identify them, and writes them with their
standard errors as a parameter file. The rows: the calibration poses (sweep -1), as in
the paper's sec. V-B, unless an --effect is identified only by sweeps (a clamp with
play shows only along a path; pressure stiffening only over the range of jet forces
the sweeps cover, `Effect.identified_by`): then the poses and the sweeps. ``--fit-on``
chooses; the command says which rows it used and why.
"""

from __future__ import annotations

import argparse

import numpy as np

from ..errors import UserError
from ..files import make_folder_for
from ..effects import CALIBRATION_POSES, SWEEPS, identifying_rows
from ..estimation.calibration import (ALL_ROWS, DEFAULT_POSITION_WEIGHT_RAD_PER_M, FIT_ON, CalibrationResult,
                                      calibrate_widening, fit_mask, rows_that_identify)
from ..estimation.setup_warnings import calibration_warnings
from ..model_choice import COSSERAT, ModelChoice, model_choice
from ..params_io import calibration_parameter_file, check_parameter_output, effect_specs, write_parameter_file
from . import render
from .common import add_input_arguments, add_model_arguments, load_steps
from .next_steps import command, input_words, print_next
from .log_notice import (warn_if_incomplete, warn_if_recorded_elsewhere, warn_if_unsettled,
                         warn_if_unsettled_steps)


# Past this the orientations no longer count (a millimetre weighs ten radians) and the
# residuals overflow before the weight is absurd enough to be noticed (1e308 gave "array
# must not contain infs or NaNs" about the data file).
MAX_POSITION_WEIGHT_RAD_PER_M = 1e4
# Exit code of a calibration whose values are not to be trusted (see the warnings).
UNTRUSTED = 3


def calibration_exit_code(result: CalibrationResult | None) -> int:
    """`UNTRUSTED` for a calibration that did not converge or left a fitted value on a
    bound (what its warnings say), else 0; 0 for no calibration (a parameter file given)."""
    return UNTRUSTED if result is not None and (not result.converged or result.at_bound) else 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("calibrate", help="fit model parameters to the calibration poses")
    add_input_arguments(parser)
    add_model_arguments(parser, default=COSSERAT.model)
    parser.add_argument("-o", "--output", type=render.file_path, required=True, help="parameter file to write (TOML); replaced if it exists: it is derived "
                        "from the data, and calibrating again is meant to update it")
    parser.add_argument("--position-weight", type=float, default=DEFAULT_POSITION_WEIGHT_RAD_PER_M,
                        metavar="RAD_PER_M", help="weight of tip position errors when positions were "
                        f"measured (default {DEFAULT_POSITION_WEIGHT_RAD_PER_M:g}; 0 = orientation only)")
    parser.add_argument("--fit-on", choices=FIT_ON, default=None,
                        help="rows to fit: the calibration poses (sweep -1), the sweeps, or all (default: the "
                             "poses, and all when an --effect is identified only by sweeps)")
    render.add_json_argument(parser, "the parameter file's content, the unidentifiable pairs and the evaluations")
    render.add_exit_codes(parser, {UNTRUSTED: "the fit did not converge or a fitted value sits on a bound (the "
                                              "parameter file is written and says so; the warnings say which)"})
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not 0 <= args.position_weight <= MAX_POSITION_WEIGHT_RAD_PER_M:
        raise UserError(f"--position-weight must be from 0 to {MAX_POSITION_WEIGHT_RAD_PER_M:g} rad per m (there, "
                        f"a millimetre outweighs ten radians), got {args.position_weight}")
    choice = model_choice(args)  # validates --effect before the data is read
    # Before the fit: neither output may replace an input, other data or the other output.
    render.check_distinct_outputs({"-o": args.output, "--json": args.json})
    check_parameter_output(args.output)
    render.check_json_output(args.json)
    model = choice.model
    profile, steps = load_steps(args.input, args.profile)
    log_damage = warn_if_incomplete(args.input)
    profile_mismatch = warn_if_recorded_elsewhere(args.input, args.profile, profile)
    fit_on = args.fit_on or rows_that_identify(choice.requested)
    rows = fit_mask(steps, fit_on)
    if not rows.any():
        plan = "sweeps" if fit_on == SWEEPS else "calibration"
        raise UserError(f"{args.input}: no {_ROW_NAMES[fit_on]} to fit on; record some with "
                        f"`hydrojet-bench run --plan {plan}`")
    single_sample_steps = warn_if_unsettled(args.input, steps, log_damage)
    unsettled_steps = warn_if_unsettled_steps(args.input, steps.select(rows))
    used = _rows_used(steps, rows)
    try:
        fitted = calibrate_widening(model, choice.requested, steps, profile.model_parameters(),
                                    choice.calibration_names, fit_on=fit_on,
                                    position_weight_rad_per_m=args.position_weight)
    except ValueError as error:
        raise UserError(f"{args.input}: {error}") from None
    console = render.console_for(args)
    console.print(f"fitted on {used}{_why(args.fit_on, fit_on, choice)}", highlight=False)
    result, widened = fitted.result, fitted.widened
    if widened:
        console.print(f"{', '.join(widened)} ended on {'its' if len(widened) == 1 else 'their'} search bound: "
                      "refitted with the search widened to the physical limits, as diagnose does", highlight=False)
    table = render.table(f"{model.name} calibrated on {used} of {args.input}",
                         labels=("parameter",), numbers=("value", "standard error"))
    for name, value, error in zip(result.names, result.values, result.standard_errors):
        table.add_row(name, f"{value:.6g}", f"{error:.2g}")
    console.print(table)
    console.print(f"RMS orientation error on the {_FITTED_ROWS[fit_on]}: {result.rms_orientation_deg_before:.2f} deg "
                  f"before, {result.rms_orientation_deg_after:.2f} deg after ({result.evaluations} evaluations)")
    warnings = render.progress_console()  # warnings go to standard error, beside the results
    for warning in calibration_warnings(fitted.model, result):
        warnings.print(f"[yellow]warning:[/] {render.plain(warning)}")
    for first, second, correlation in result.unidentifiable:
        warnings.print(f"[yellow]warning:[/] {first} and {second} are not separately identifiable on these rows "
                       f"(correlation {correlation:+.3f}); their individual values mean little")
    make_folder_for(args.output)
    content = calibration_parameter_file(model.name, effect_specs(model.effects, args.output.parent), result,
                                         args.input, profile, fit_on, steps, rows)
    write_parameter_file(args.output, content)
    console.print(f"wrote {render.plain(args.output)}")
    if args.json:
        # The API (plots, data frames) only for its JSON: a large file's calibration
        # should not carry it in memory.
        from ..api import CalibrateResult

        render.write_json(args.json, {**CalibrateResult(model, choice.effect_specs, steps.select(rows), result,
                                                        content).as_dict(), "log_damage": log_damage,
                                    "profile_mismatch": profile_mismatch,
                                    "single_sample_steps": single_sample_steps,
                                    "unsettled_steps": unsettled_steps})
    compare = command("compare", *input_words(args), "--params", args.output, "--online")
    print_next(console, "see how it predicts the sweeps with", [compare])
    return calibration_exit_code(result)


_FITTED_ROWS = {CALIBRATION_POSES: "calibration poses", SWEEPS: "sweep steps", ALL_ROWS: "calibration poses and sweeps"}
_ROW_NAMES = {CALIBRATION_POSES: "calibration poses (steps of sweep -1)", SWEEPS: "sweep steps (sweep >= 0)",
              ALL_ROWS: "calibration poses or sweep steps"}


def _rows_used(steps, rows: np.ndarray) -> str:
    poses = int(np.sum(rows & (steps.sweep == -1)))
    sweeps = np.unique(steps.sweep[rows & (steps.sweep >= 0)])
    parts = [f"{poses} calibration poses"] if poses else []
    if len(sweeps):
        parts.append(f"{int(np.sum(rows & (steps.sweep >= 0)))} steps of {len(sweeps)} sweeps")
    return " and ".join(parts)


def _why(requested: str | None, fit_on: str, choice: ModelChoice) -> str:
    if requested is not None:
        return f" (--fit-on {requested})"
    needing = [effect.name for effect in choice.requested if identifying_rows(effect) == SWEEPS]
    if needing:
        return (f" ({', '.join(needing)} cannot be identified on the calibration poses alone; "
                "--fit-on calibration to fit the poses only)")
    return " (the paper's calibration; --fit-on all to fit the sweeps too)"
