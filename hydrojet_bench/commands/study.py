"""`hydrojet-bench study SPEC.toml [-o DIR] [--scheduler ADDRESS] [--workers N] [--csv]`.

Which effects can a protocol detect, and from what size? Every cell of the spec
(`hydrojet_bench.studies.spec`) is simulated on the twin and diagnosed, on Dask
distributed; rows go to ``DIR/rows/`` (Parquet) as they finish, and a rerun into the
same DIR skips the finished cells. The report (``DIR/report/``) is written at the end;
``--report-only DIR`` rebuilds it from the stored rows.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

from ..errors import UserError
from ..studies.cell import ROW_COLUMNS, cell_row, run_cell
from ..studies.cells import expand
from ..studies.engine import dask_client, run_tasks
from ..studies.spec import load_study
from ..studies.store import RowStore


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("study", help="what can a protocol detect? many twin scenarios, diagnosed (Dask)")
    parser.add_argument("spec", type=Path, nargs="?", metavar="SPEC.toml", help="the study spec (see docs/studies/)")
    parser.add_argument("-o", "--output", type=Path, metavar="DIR",
                        help="result folder (default: study-<spec name> in the working directory)")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="run on this Dask cluster (tcp://host:8786)")
    parser.add_argument("--workers", type=int, default=2, help="local worker processes (default: 2)")
    parser.add_argument("--csv", action="store_true", help="also write DIR/rows.csv")
    parser.add_argument("--report-only", type=Path, metavar="DIR", help="rebuild DIR/report/ from stored rows")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    console = Console()
    if args.report_only is not None:
        if not (args.report_only / "rows").is_dir():
            raise UserError(f"{args.report_only}: no study results here (no rows/ folder)")
        _report(console, RowStore(args.report_only, ROW_COLUMNS, "cell_id"))
        return 0
    if args.spec is None:
        raise UserError("study: give a SPEC.toml (or --report-only DIR)")
    if args.workers < 1:
        raise UserError(f"--workers must be at least 1, got {args.workers}")
    study = load_study(args.spec)
    cells = expand(study)
    if not cells:
        raise UserError(f"{args.spec}: the spec has no cells (none = false and no effects or pairs)")
    folder = args.output or Path(f"study-{study.name}")
    store = RowStore(folder, ROW_COLUMNS, "cell_id")
    where = args.scheduler or f"a local cluster of {args.workers} worker{'s' if args.workers != 1 else ''}"
    console.print(f"study {study.name}: {len(cells)} cells on {where}, rows in {store.rows_folder}")
    outcome = run_tasks(lambda: dask_client(args.scheduler, args.workers), run_cell, cells,
                        [cell.id for cell in cells], store, error_row=cell_row, label="cells")
    console.print(f"{outcome.submitted} cells run ({outcome.skipped} already done), {outcome.failed} failed, "
                  f"{outcome.wall_s:.1f} s ({outcome.cells_per_minute:.2f} cells/min)")
    if args.csv:
        console.print(f"wrote {store.write_csv()}")
    _report(console, store)
    return 0


def _report(console: Console, store: RowStore) -> None:
    from ..studies.report import write_report

    for path in write_report(store.table(), store.folder / "report"):
        console.print(f"wrote {path}")
