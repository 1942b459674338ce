"""Running many independent tasks on Dask distributed: a `LocalCluster` of worker
processes by default, or an existing cluster by its scheduler's address
(``dask scheduler`` / ``dask worker``), with the same code.

Each finished task's row goes to the `RowStore` at once; ids already stored are skipped,
so a rerun resumes and a killed run loses only the tasks in flight. A rich progress bar
on stderr shows done/total, rate, ETA and failures.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, \
    TimeRemainingColumn

from ..errors import UserError
from .store import RowStore

# A scheduler that does not answer within this is a wrong address, not a slow cluster.
CONNECT_TIMEOUT_S = 10


@dataclass(frozen=True)
class Outcome:
    """What a run did: tasks submitted, skipped (already stored), failed (rows with an
    error), and its wall time (s)."""

    submitted: int
    skipped: int
    failed: int
    wall_s: float

    @property
    def cells_per_minute(self) -> float:
        return 60.0 * self.submitted / self.wall_s if self.wall_s > 0 else 0.0


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int = 2) -> Iterator[Any]:
    """A distributed ``Client``: on the cluster at ``scheduler`` (``tcp://host:port``),
    else on a fresh `LocalCluster` of ``workers`` single-threaded processes, closed on
    exit."""
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError) as error:
            raise UserError(f"--scheduler {scheduler}: cannot connect ({error})") from None
        except ValueError as error:  # distributed's words for an address it cannot parse
            raise UserError(f"--scheduler {scheduler!r} is no scheduler address ({error}); give "
                            "tcp://host:port") from None
        with client:
            yield client
        return
    if workers < 1:
        raise UserError(f"--workers must be at least 1, got {workers}")
    with _workers_deaf_to_ctrl_c() as interrupted:
        # Workers log errors only: their warnings on a stop ("task cancelled", "still
        # alive, killing") are the stop itself, and a failed cell's row says what failed.
        with warnings.catch_warnings():
            # distributed warns that its default dashboard port is taken even when no
            # dashboard is asked for (dashboard_address=None): no port of ours is used.
            warnings.filterwarnings("ignore", message=r"Port \d+ is already in use", category=UserWarning)
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                                   silence_logs=logging.ERROR)
    with cluster:
        if interrupted:
            raise KeyboardInterrupt  # the Ctrl-C of the start-up, now that the cluster closes
        with Client(cluster) as client:
            yield client


@contextlib.contextmanager
def _workers_deaf_to_ctrl_c() -> Iterator[list[int]]:
    """Start worker processes with SIGINT ignored (a process started so keeps it ignored,
    and Python then installs no KeyboardInterrupt handler): Ctrl-C reaches the terminal's
    whole process group, and each worker printed its own traceback before the study
    stopped them. A Ctrl-C meanwhile is kept for the caller to stop on once the cluster is
    up (the list yielded holds it): ignored alone, it was lost and the study ran on."""
    interrupted: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield interrupted  # signal handlers are the main thread's to set
        return
    # Linux keeps a blocked signal pending even while it is ignored: unblocked after the
    # handler is back, it is delivered then. It is still lost elsewhere, or when a thread
    # that does not block it (a native library's, started earlier) takes it.
    blocking = hasattr(signal, "pthread_sigmask")
    if blocking:
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield interrupted
    finally:
        signal.signal(signal.SIGINT, lambda number, frame: interrupted.append(number))
        if blocking:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # runs the handler on a pending SIGINT
        signal.signal(signal.SIGINT, previous)


def run_tasks(connect: Callable[[], contextlib.AbstractContextManager[Any]], function: Callable[[Any], dict],
              items: Sequence[Any], ids: Sequence[str], store: RowStore, *, error_row: Callable[[Any, str], dict],
              label: str = "cells", console: Console | None = None) -> Outcome:
    """Run ``function(item)`` for every item whose id has no stored row yet, or only a
    failed one (a failure may be the worker's, not the item's), storing each row as it
    arrives. ``connect()`` gives the client (see `dask_client`), only called when
    there is work left. ``error_row(item, text)`` makes the row of a task that raised (or
    whose worker died)."""
    from distributed import as_completed

    started = time.perf_counter()
    done = store.finished()
    todo = [(item, key) for item, key in zip(items, ids) if key not in done]
    if not todo:
        return Outcome(submitted=0, skipped=len(items), failed=0, wall_s=time.perf_counter() - started)
    failed = 0
    console = console or Console(stderr=True)
    columns = (TextColumn(f"[bold]{label}"), BarColumn(), MofNCompleteColumn(),
               TextColumn("{task.fields[rate]}"), TextColumn("ETA"), TimeRemainingColumn(),
               TextColumn("{task.fields[failures]} failed"), TimeElapsedColumn())
    with connect() as client, Progress(*columns, console=console, transient=False) as progress:
        task = progress.add_task(label, total=len(todo), rate="-", failures=0)
        futures = {client.submit(function, item, key=f"{label}-{key}", pure=False): item for item, key in todo}
        for count, future in enumerate(as_completed(futures), start=1):
            try:
                row = future.result()
            except Exception as error:  # noqa: BLE001 - a lost worker or an unpicklable row: record, go on
                row = error_row(futures[future], f"{type(error).__name__}: {error}")
            if row.get("error"):
                failed += 1
            store.append(row)
            elapsed = time.perf_counter() - started
            progress.update(task, advance=1, failures=failed, rate=f"{60.0 * count / elapsed:.1f}/min")
    return Outcome(submitted=len(todo), skipped=len(items) - len(todo), failed=failed,
                   wall_s=time.perf_counter() - started)
