"""`hydrojet-bench study SPEC.toml [-o DIR] [--scheduler ADDRESS] [--workers N] [--csv] [--json PATH]`.

Which effects can a protocol detect, and from what size? Every cell of the spec
(`hydrojet_bench.studies.spec`) is simulated on the twin and diagnosed, on Dask
distributed (`hydrojet_bench.api.study`); rows go to ``DIR/rows/`` (Parquet) as they
finish, and a rerun into the same DIR skips the finished cells. The report
(``DIR/report/``) is written at the end; ``--report-only DIR`` rebuilds it from the
stored rows. Progress goes to standard error, the outcome and the files written to
standard output.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import UserError
from . import render


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("study", help="what can a protocol detect? many twin scenarios, diagnosed (Dask)")
    parser.add_argument("spec", type=Path, nargs="?", metavar="SPEC.toml", help="the study spec (see docs/studies/)")
    parser.add_argument("-o", "--output", type=Path, metavar="DIR",
                        help="result folder (default: study-<spec name> in the working directory)")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="run on this Dask cluster (tcp://host:8786)")
    parser.add_argument("--workers", type=int, default=2, help="local worker processes (default: 2)")
    parser.add_argument("--csv", action="store_true", help="also write DIR/rows.csv")
    parser.add_argument("--report-only", type=Path, metavar="DIR", help="rebuild DIR/report/ from stored rows")
    render.add_json_argument(parser, "the outcome, the files written and every row")
    render.add_exit_codes(parser, {1: "some cell failed (its row names the error; the others are reported)",
                                   143: "stopped by SIGTERM (the rows stored so far are kept: run again to resume)"})
    parser.set_defaults(func=run, stops_on_sigterm=True)


def run(args: argparse.Namespace) -> int:
    from ..api import study

    progress = render.progress_console()
    if args.spec is None and args.report_only is None:
        raise UserError("study: give a SPEC.toml to run, or --report-only DIR to rebuild a report")
    if args.workers < 1:
        raise UserError(f"--workers must be at least 1, got {args.workers}")
    if args.report_only is not None:
        if args.spec is not None:
            raise UserError(f"study: --report-only {args.report_only} rebuilds that folder's report from its stored "
                            f"rows and runs no spec; give {args.spec} or --report-only, not both")
        result = study(output=args.report_only, report_only=True)
    else:
        result = study(args.spec, args.output, workers=args.workers, scheduler=args.scheduler, csv=args.csv,
                       progress=lambda line: progress.print(line, markup=False, highlight=False))
    console = render.console_for(args)
    outcome = result.outcome
    if outcome is not None:
        console.print(f"{outcome.submitted} cells run ({outcome.skipped} already done), {outcome.failed} failed, "
                      f"{outcome.wall_s:.1f} s ({outcome.cells_per_minute:.2f} cells/min)")
    if result.left_out:
        progress.print(f"[yellow]warning:[/] {result.left_out} row(s) under {render.plain(result.folder / 'rows')} "
                       "belong to no cell of this spec (an edited spec or a moved effect file): left out of the "
                       "tables and report")
    for path in ([result.csv] if result.csv else []) + list(result.report):
        console.print(f"wrote {render.plain(path)}")
    if args.json:
        render.write_json(args.json, {
            "study": result.name, "folder": str(result.folder),
            "outcome": None if outcome is None else {"run": outcome.submitted, "skipped": outcome.skipped,
                                                     "failed": outcome.failed, "wall_s": outcome.wall_s},
            "rows_left_out": result.left_out,
            "files": [str(path) for path in ([result.csv] if result.csv else []) + list(result.report)],
            "rows": [render.json_row(row) for row in result.rows.to_dict("records")]})
    failed = int(result.rows["error"].notna().sum())
    if failed:
        progress.print(f"[yellow]warning:[/] {failed} of {len(result.rows)} cells failed (their rows name the "
                       "error); a rerun into the same folder tries them again")
    return 1 if failed else 0

