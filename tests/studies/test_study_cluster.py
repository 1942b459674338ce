"""The same study on a cluster started as separate processes on 127.0.0.1 (`dask
scheduler`, two `dask worker`s), reached by --scheduler; always torn down."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
from study_helpers import run_study, stored_rows

START_TIMEOUT_S = 60.0


def _start(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", *args], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})


def _scheduler_address(process: subprocess.Popen) -> str:
    deadline = time.monotonic() + START_TIMEOUT_S
    seen = []
    while time.monotonic() < deadline:
        line = process.stderr.readline()
        if not line and process.poll() is not None:
            break
        seen.append(line)
        match = re.search(r"Scheduler at:\s+(tcp://127\.0\.0\.1:\d+)", line)
        if match:
            return match.group(1)
    raise AssertionError("the scheduler did not say its address:\n" + "".join(seen))


def _wait_for_workers(address: str, count: int) -> None:
    from distributed import Client

    with Client(address, timeout=START_TIMEOUT_S) as client:
        client.wait_for_workers(count, timeout=START_TIMEOUT_S)


@pytest.fixture
def cluster():
    processes = []
    try:
        scheduler = _start("distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
                           "--no-dashboard")
        processes.append(scheduler)
        address = _scheduler_address(scheduler)
        for _ in range(2):
            processes.append(_start("distributed.cli.dask_worker", address, "--nthreads", "1", "--nworkers", "1",
                                    "--no-dashboard", "--host", "127.0.0.1"))
        _wait_for_workers(address, 2)
        yield address
    finally:
        for process in reversed(processes):
            process.terminate()
        for process in reversed(processes):
            try:
                process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(timeout=10)
            process.stderr.close()


def test_study_runs_on_a_scheduler_by_address(cluster: str, tiny_spec: Path, tmp_path: Path):
    out = tmp_path / "out"
    result = run_study(str(tiny_spec), "-o", str(out), "--scheduler", cluster)
    assert result.returncode == 0, result.stderr
    assert cluster in " ".join(result.stderr.split())  # the start line is progress: standard error
    rows = stored_rows(out)
    assert len(rows) == 4 and rows["error"].isna().all()
    assert sorted(rows["verdict"]) == ["jet_gain", "jet_gain", "none", "none"]

