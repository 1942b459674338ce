"""Conformance: the real host library, scikit-surgerynditracker on ndicapi (C), drives
the emulator on a pty exactly as it would drive an Aurora on a serial port.

The library runs in a subprocess with a timeout: its C code blocks in read() and could
otherwise hang the test run. Skipped when the library is not installed
(``pip install scikit-surgerynditracker``).
"""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys

import numpy as np
import pytest
from aurora_testkit import HANDLES, truth_mm

from drivers.aurora import AuroraEmulator
from drivers.transport.pty import PtyServer
from hydrojet_bench.geometry import rotation_angle_deg

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("sksurgerynditracker") is None or importlib.util.find_spec("ndicapy") is None,
    reason="scikit-surgerynditracker/ndicapi not installed (pip install scikit-surgerynditracker)",
)

# Runs in the subprocess: connect, track a few frames, stop, close; print one JSON line.
CLIENT = r"""
import json, math, sys
from sksurgerynditracker.nditracker import NDITracker
tracker = NDITracker({"tracker type": "aurora", "serial port": sys.argv[1],
                      "use quaternions": True, "verbose": False})
tracker.start_tracking()
frames = []
for _ in range(int(sys.argv[2])):
    handles, _, numbers, tracking, quality = tracker.get_frame()
    frames.append({
        "handles": [int(h) for h in handles],
        "numbers": [int(n) for n in numbers],
        "tracking": [[None if math.isnan(v) else float(v) for v in row.ravel()] for row in tracking],
        "quality": [None if math.isnan(q) else float(q) for q in quality],
    })
tracker.stop_tracking()
tracker.close()
print(json.dumps(frames))
"""


def run_library(emulator: AuroraEmulator, frames: int = 3) -> list[dict]:
    with PtyServer(emulator, name="aurora-conformance") as server:
        result = subprocess.run(
            [sys.executable, "-c", CLIENT, server.path, str(frames)],
            capture_output=True,
            text=True,
            timeout=20,
        )
    assert result.returncode == 0, result.stderr[-2000:]
    return json.loads(result.stdout.strip().splitlines()[-1])


def check_row(row: list[float], plant, sensor: str, position_tol_mm: float, angle_tol_deg: float) -> None:
    q, p_mm = truth_mm(plant, sensor)
    assert rotation_angle_deg(row[:4], q) < angle_tol_deg
    assert np.linalg.norm(np.array(row[4:7]) - p_mm) < position_tol_mm


def test_library_reads_bx_poses_and_a_missing_tool(plant) -> None:
    emulator = AuroraEmulator(plant, tools=HANDLES)
    frames = run_library(emulator)
    log = list(emulator.command_log)
    # The library's own sequence (hardware-facts.md): probe, set up, BX:0801, TSTOP.
    assert log[:3] == ["INIT:", "GETINFO:Features.Firmware.Version", "VER:0"]
    for expected in ("COMM:50000", "PHSR:02", "PINIT:0a", "PHSR:03", "PENA:0aD", "TSTART:", "BX:0801"):
        assert expected in log
    assert log[-1] == "TSTOP:" and emulator.mode == "setup"
    for frame in frames:
        assert frame["handles"] == [0x0A, 0x0B]
        assert frame["quality"] == [pytest.approx(0.48), pytest.approx(0.48)]
        for row, sensor in zip(frame["tracking"], ("base", "tip")):
            check_row(row, plant, sensor, 0.48 * 5, 0.70 * 5)

    # Second session on the same pty, with the tip's coil giving no solution.
    emulator.set_tool_missing("tip")
    frames = run_library(emulator, frames=1)
    base, tip = frames[0]["tracking"]
    check_row(base, plant, "base", 0.48 * 5, 0.70 * 5)
    assert tip == [None] * 7  # the library's NaN row for MISSING
    assert frames[0]["quality"][1] is None


def test_library_uses_tx_for_old_firmware(plant) -> None:
    # scikit-surgerynditracker switches to TX for these freeze tags.
    emulator = AuroraEmulator(
        plant, tools=HANDLES, position_noise_mm=0, orientation_noise_deg=0,
        version_text="NDI Aurora\nFreeze Tag: AURORA Rev 008\nFreeze Date: 2010",
    )
    frames = run_library(emulator, frames=2)
    assert "TX:0801" in emulator.command_log and "BX:0801" not in emulator.command_log
    for row, sensor in zip(frames[-1]["tracking"], ("base", "tip")):
        check_row(row, plant, sensor, 0.01, 0.02)  # TX resolution only
        assert math.isclose(math.fsum(v * v for v in row[:4]), 1.0, abs_tol=1e-3)
