"""`hydrojet-bench compare DATA --params P [--online] [--json FILE] [--report DIR]`.

Predicts every validation step (sweep >= 0; all steps when there are no sweeps) with the
calibrated, constant disturbance ("Ref.") and, with --online, with online disturbance
estimation ("Proposed"), and reports the errors as the paper's Table II does.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rich.console import Console
from rich.table import Table

from ..analysis.compare import Comparison, compare, predict
from ..errors import UserError
from ..estimation import OnlineSettings
from ..params_io import read_parameter_file
from .common import add_data_arguments, add_model_arguments, build_model, load_steps


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("compare", help="model predictions against measurements (Table II)")
    add_data_arguments(parser)
    add_model_arguments(parser, default_model=None)
    parser.add_argument("--params", type=Path, required=True, help="parameter file from `calibrate`")
    parser.add_argument("--online", action="store_true", help="also run online disturbance estimation")
    parser.add_argument("--json", type=Path, metavar="FILE", help="write the figures as JSON")
    parser.add_argument("--report", type=Path, metavar="DIR", help="write figures (PNG) to this folder")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    parameter_file = read_parameter_file(args.params)
    model_name = args.model or parameter_file.model
    profile, steps = load_steps(args)
    model, _ = build_model(model_name, list(parameter_file.effects) + args.effect)
    params = parameter_file.apply(profile.model_parameters(), args.params)
    validation = steps.select(steps.sweep >= 0) if (steps.sweep >= 0).any() else steps
    if len(validation) == 0:
        raise UserError(f"{args.data}: no steps to compare")
    results = {"ref": compare(predict(model, params, validation), validation)}
    if args.online:
        results["online"] = compare(predict(model, params, validation, OnlineSettings()), validation)
    print_tables(Console(), results, f"{model.name} on {args.data}")
    if args.json:
        write_json(args.json, results)
    if args.report:
        from ..analysis.report import write_report

        for path in write_report(args.report, results, validation, model.name):
            Console().print(f"wrote {path}")
    return 0


def print_tables(console: Console, results: dict[str, Comparison], title: str) -> None:
    labels = {"ref": "Ref.", "online": "Proposed"}
    table = Table(title=f"RMS errors, {title}", caption="bend bins in degrees, as the paper's Table II")
    table.add_column("group", no_wrap=True)
    for key in results:
        table.add_column(f"{labels[key]} orient. (deg)", justify="right")
        table.add_column(f"{labels[key]} pos. (mm)", justify="right")
    reference = results["ref"]

    def row(label: str, pick) -> None:
        cells = []
        for comparison in results.values():
            summary = pick(comparison)
            cells += [f"{summary.orientation_rmse_deg:.2f}",
                      "-" if summary.position_rmse_mm is None else f"{summary.position_rmse_mm:.2f}"]
        table.add_row(label, *cells)

    row("all", lambda c: c.overall)
    for sweep in reference.by_sweep:
        row(f"sweep {sweep}", lambda c, s=sweep: c.by_sweep[s])
    for bend in reference.by_bend:
        row(f"bend <={bend}" if not str(bend).startswith(">") else f"bend {bend}",
            lambda c, b=bend: c.by_bend[b])
    console.print(table)


def write_json(path: Path, results: dict[str, Comparison]) -> None:
    figures = {key: comparison.as_dict() for key, comparison in results.items()}
    document = {
        "orientation_rmse_deg": {key: value["orientation_rmse_deg"] for key, value in figures.items()},
        "position_rmse_mm": {key: value["position_rmse_mm"] for key, value in figures.items()},
        "by_sweep": {key: value["by_sweep"] for key, value in figures.items()},
        "by_bend": {key: value["by_bend"] for key, value in figures.items()},
    }
    try:
        path.write_text(json.dumps(document, indent=2) + "\n")
    except OSError as error:
        raise UserError(f"cannot write {path}: {error.strerror}") from None
