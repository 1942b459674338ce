"""`hydrojet-bench batch diagnose LOGS...` and `batch replay LOGS...`: every log of a lab
at once, on the study engine (Dask distributed: local worker processes, or a cluster
with --scheduler). One row per log: a table on stdout, ``--json``, and Parquet rows
under ``-o DIR`` (a rerun into the same DIR reuses the rows of logs unchanged since and
not failed).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path


from ..errors import UserError
from ..logs.records import MAGIC
from ..studies.batch import DIAGNOSE_COLUMNS, REPLAY_COLUMNS, LogTask, diagnose_log, log_row, replay_log
from ..studies.engine import dask_client, run_tasks
from ..studies.store import RowStore
from . import render

# Per action: the task, its columns, the columns shown in the table.
ACTIONS = {
    "diagnose": (diagnose_log, DIAGNOSE_COLUMNS,
                 ("verdict", "alternatives", "baseline_heldout_rmse_deg", "noise_floor_deg", "seconds")),
    "replay": (replay_log, REPLAY_COLUMNS,
               ("model", "steps", "validation_orientation_rmse_deg", "live_difference_deg", "seconds")),
}


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("batch", help="diagnose or replay many logs at once (Dask)")
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    for action in ACTIONS:
        sub = actions.add_parser(action, help=f"{action} every log, one row each")
        if action == "replay":
            # Replay re-runs a session's live estimation: only a session log holds it.
            sub.add_argument("logs", type=Path, nargs="+", metavar="LOG", help="MCAP session logs")
        else:
            sub.add_argument("logs", type=Path, nargs="+", metavar="LOG", help="CSV files or MCAP session logs")
            sub.add_argument("--profile", help="rig profile for CSV files (default: sim; a session log brings its own)")
        if action == "diagnose":
            sub.add_argument("--model", default="cosserat", choices=("cosserat", "prb"),
                             help="model to diagnose (default: cosserat)")
        sub.add_argument("-o", "--output", type=Path, metavar="DIR", help="store the rows as Parquet under DIR")
        sub.add_argument("--scheduler", metavar="ADDRESS", help="run on this Dask cluster (tcp://host:8786)")
        sub.add_argument("--workers", type=int, default=2, help="local worker processes (default: 2)")
        render.add_json_argument(sub, "the rows")
        render.add_exit_codes(sub, {1: "some log failed (its row names the error; the others are reported)"})
        sub.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    function, columns, shown = ACTIONS[args.action]
    missing = [str(path) for path in args.logs if not path.is_file()]
    if missing:
        raise UserError(f"{missing[0]}: no such log")
    if args.workers < 1:
        raise UserError(f"--workers must be at least 1, got {args.workers}")
    if args.action == "replay":
        for path in args.logs:
            try:
                with path.open("rb") as file:
                    start = file.read(len(MAGIC))
            except OSError as error:
                raise UserError(f"{path}: cannot read: {error.strerror or error}") from None
            if not start or not MAGIC.startswith(start):
                raise UserError(f"{path}: not an MCAP session log; replay re-runs a session's live estimation, which "
                                "only its log holds (batch diagnose takes CSV tables)")
    warnings = render.console(stderr=True)
    tasks: list[LogTask] = []
    for path in args.logs:
        task = LogTask.of(path, getattr(args, "profile", None), getattr(args, "model", "cosserat"))
        if any(task.path == earlier.path for earlier in tasks):
            warnings.print(f"warning: {path} is given more than once: analysed once", markup=False, highlight=False)
        else:
            tasks.append(task)
    with tempfile.TemporaryDirectory(prefix="hydrojet-batch-") as scratch:
        store = RowStore(args.output or Path(scratch), columns, "log_id")
        outcome = run_tasks(lambda: dask_client(args.scheduler, args.workers), function, tasks,
                            [task.id for task in tasks], store,
                            error_row=lambda task, text: log_row(task, columns, text), label="logs")
        table = store.table({task.id for task in tasks})
    order = {task.path: index for index, task in enumerate(tasks)}
    # pandas holds an integer column with gaps as floats: counts are integers again here.
    integers = [name for name, kind in columns.items() if kind == "int64"]
    rows = sorted(({**row, **{name: int(row[name]) for name in integers if row[name] is not None}}
                   for row in map(render.json_row, table.to_dict("records"))), key=lambda row: order[row["log"]])
    console = render.console_for(args)
    view = render.table(f"batch {args.action}: {len(rows)} logs", labels=("log",), numbers=shown)
    view.add_column("error")
    for row in rows:
        view.add_row(Path(row["log"]).name, *(_cell(row[name]) for name in shown), row["error"] or "")
    console.print(view)
    for row in rows:
        for notice in (row["log_damage"], row.get("profile_mismatch")):
            if notice:
                warnings.print(f"warning: {notice}", markup=False, highlight=False)
    if args.output:
        console.print(f"{outcome.submitted} logs analysed ({outcome.skipped} already done: their rows are reused "
                      f"unless the file changed since); rows stored under {store.rows_folder}")
    if args.json:
        render.write_json(args.json, rows)
    return 1 if any(row["error"] for row in rows) else 0


def _cell(value: object) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.3f}"
    return str(value)
