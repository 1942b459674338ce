"""`hydrojet-bench batch diagnose LOGS...` and `batch replay LOGS...`: every log of a lab
at once, on the study engine (Dask distributed: local worker processes, or a cluster
with --scheduler). One row per log: a table on stdout, ``--json``, and Parquet rows
under ``-o DIR`` (a rerun into the same DIR reuses the rows of logs unchanged since and
not failed).
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

from ..analysis.diagnosis import UNDECIDED
from ..errors import UserError
from ..logs.records import MAGIC
from ..studies.batch import DIAGNOSE_COLUMNS, REPLAY_COLUMNS, LogTask, diagnose_log, log_row, replay_log
from ..studies.engine import dask_client, run_tasks
from ..studies.store import RowStore
from ..profile import load_profile
from . import render
from .diagnose import UNDECIDED_EXIT

# Per action: the task, its columns, the columns shown in the table.
ACTIONS = {
    "diagnose": (diagnose_log, DIAGNOSE_COLUMNS,
                 ("verdict", "alternatives", "baseline_heldout_rmse_deg", "noise_floor_deg", "converged",
                  "bound_clipped", "seconds")),
    "replay": (replay_log, REPLAY_COLUMNS,
               ("model", "steps", "scored_steps", "skipped_steps", "validation_orientation_rmse_deg",
                "live_difference_deg", "seconds")),
}
# What each action's exit codes add to the common ones: the single commands' meanings,
# for any of the logs.
EXIT_CODES = {
    "diagnose": {1: "some log failed (its row names the error; the others are reported)",
                 UNDECIDED_EXIT: "some log's verdict is undecided, as diagnose says it (its fits did not converge)"},
    "replay": {1: "some log failed (its row names the error; the others are reported) or its replayed errors are "
                  "not finite (no answer), as replay says it"},
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
        render.add_exit_codes(sub, {**EXIT_CODES[action],
                                    143: "stopped by SIGTERM (the rows stored so far are kept: run again to resume)"})
        sub.set_defaults(func=run, stops_on_sigterm=True)


def run(args: argparse.Namespace) -> int:
    function, columns, shown = ACTIONS[args.action]
    missing = [str(path) for path in args.logs if not path.is_file()]
    if missing:
        raise UserError(f"{missing[0]}: no such log")
    if args.workers < 1:
        raise UserError(f"--workers must be at least 1, got {args.workers}")
    if getattr(args, "profile", None) is not None:
        # Every log would fail on it, each in a worker of a cluster started for nothing.
        try:
            load_profile(args.profile)
        except UserError as error:
            raise UserError(f"--profile {args.profile}: {error}") from None
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
        store.create()
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
        for notice in (row["log_damage"], row.get("profile_mismatch"), *_untrusted(row)):
            if notice:
                warnings.print(f"warning: {notice}", markup=False, highlight=False)
    if args.output:
        console.print(f"{outcome.submitted} logs analysed ({outcome.skipped} already done: their rows are reused "
                      f"unless the file changed since); rows stored under {store.rows_folder}")
    if args.json:
        render.write_json(args.json, rows)
    return exit_code(rows)


def _untrusted(row: dict) -> list[str]:
    """What the single command warns of in this log's row, one line each."""
    notices = []
    if row.get("skipped_steps"):
        notices.append(f"{row['log']}: {row['skipped_steps']} step(s) did not converge and were left out")
    if _no_answer(row):
        notices.append(f"{row['log']}: the replayed errors are not finite (no answer)")
    if row.get("verdict") == UNDECIDED:
        notices.append(f"{row['log']}: the verdict is undecided (the fits did not converge); `diagnose` on the log "
                       "says which")
    return notices


def _no_answer(row: dict) -> bool:
    # json_row holds a NaN figure as None: a replayed row without an error and without
    # an RMSE is one whose errors were not finite.
    value = row.get("validation_orientation_rmse_deg", 0.0)
    return not row["error"] and (value is None or not math.isfinite(value))


def exit_code(rows: list[dict]) -> int:
    """The single commands' exit code for the worst of ``rows``: 1 a failed log or
    replayed errors not finite, else 3 an undecided verdict, else 0."""
    if any(row["error"] or _no_answer(row) for row in rows):
        return 1
    return UNDECIDED_EXIT if any(row.get("verdict") == UNDECIDED for row in rows) else 0


def _cell(value: object) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.3f}"
    return str(value)
