"""The opt-in rig smoke tests pass against the simulated rig's emulators, so they are
known to work before anyone points them at hardware."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

RIG_TESTS = Path(__file__).with_name("test_rig_smoke.py")


def test_rig_smoke_tests_pass_on_the_simulated_rig():
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                             "--rig", "profiles/sim.toml", str(RIG_TESTS)],
                            capture_output=True, text=True, timeout=300, cwd=Path(__file__).parents[2])
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-2000:]
    assert "3 passed" in result.stdout, result.stdout[-2000:]


def test_rig_smoke_tests_are_skipped_without_the_option():
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(RIG_TESTS)],
                            capture_output=True, text=True, timeout=300, cwd=Path(__file__).parents[2])
    assert result.returncode == 0 and "3 skipped" in result.stdout, result.stdout[-2000:]
