"""Resume: a study killed (SIGKILL, its cluster with it) mid-run loses only the cells in
flight; rerunning the same spec into the same folder skips the finished ones."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

from study_helpers import TINY, run_study, stored_rows, study_command, write_spec

FIRST_ROW_TIMEOUT_S = 120.0


def test_a_killed_study_resumes_where_it_stopped(tmp_path: Path):
    spec = write_spec(tmp_path, TINY)  # four cells, one worker: killed after the first, three are left
    out = tmp_path / "out"
    rows_folder = out / "rows"
    process = subprocess.Popen(study_command(str(spec), "-o", str(out), "--workers", "1"),
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + FIRST_ROW_TIMEOUT_S
        while not list(rows_folder.glob("*.parquet")):
            assert process.poll() is None, "the study ended before it stored a row"
            assert time.monotonic() < deadline, "no row stored in time"
            time.sleep(0.1)
    finally:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait(timeout=30)
    finished = {path: path.stat().st_mtime_ns for path in rows_folder.glob("*.parquet")}
    assert 1 <= len(finished) < 4

    result = run_study(str(spec), "-o", str(out), "--workers", "2")
    assert result.returncode == 0, result.stderr
    assert f"{4 - len(finished)} cells run ({len(finished)} already done)" in " ".join(result.stdout.split())
    rows = stored_rows(out)
    assert len(rows) == 4 and rows["cell_id"].is_unique and rows["error"].isna().all()
    assert {path: path.stat().st_mtime_ns for path in finished} == finished

    again = run_study(str(spec), "-o", str(out), "--workers", "1")
    assert "0 cells run (4 already done)" in " ".join(again.stdout.split())


def stopped_after_its_first_row(tmp_path: Path, stop: Callable[[subprocess.Popen], None],
                                 workers: str) -> tuple[int, str, Path]:
    """Start a study of four cells, ``stop`` it once it stored a row; its exit code,
    standard error and result folder."""
    spec = write_spec(tmp_path, TINY)
    out = tmp_path / "out"
    process = subprocess.Popen(study_command(str(spec), "-o", str(out), "--workers", workers), stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + FIRST_ROW_TIMEOUT_S
        while not list((out / "rows").glob("*.parquet")):
            assert process.poll() is None, "the study ended before it stored a row"
            assert time.monotonic() < deadline, "no row stored in time"
            time.sleep(0.1)
        stop(process)
        _, err = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait(timeout=30)
    return process.returncode, err, out


def test_ctrl_c_stops_a_study_with_one_line(tmp_path: Path):
    """Ctrl-C at a terminal reaches the whole process group, Dask's worker processes
    too: each printed its own traceback and warnings before the study stopped."""
    code, err, _ = stopped_after_its_first_row(tmp_path, lambda process: os.killpg(process.pid, signal.SIGINT), "2")
    assert code == 130, err
    assert "Traceback" not in err and "WARNING" not in err, err
    assert err.rstrip().endswith("interrupted")


def test_sigterm_stops_a_study_with_one_line_and_keeps_its_rows(tmp_path: Path):
    """A scheduler's time limit or `kill` sends SIGTERM to the study alone: it stops as
    on Ctrl-C, closing its cluster, and says so (it ended with no word, exit 143)."""
    code, err, out = stopped_after_its_first_row(tmp_path, lambda process: process.send_signal(signal.SIGTERM), "1")
    assert code == 143, err
    assert "Traceback" not in err, err
    assert err.rstrip().endswith("terminated (SIGTERM)")
    assert list((out / "rows").glob("*.parquet"))
