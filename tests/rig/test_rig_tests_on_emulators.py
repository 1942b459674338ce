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


def test_a_rig_that_cannot_be_opened_fails_each_check_with_one_line(tmp_path):
    # A device path that is not there, as on a machine that is not the rig's PC.
    profile = tmp_path / "absent.toml"
    profile.write_text('extends = "sim"\n[transports]\nvalves = "serial:///dev/absent-valves"\n')
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rig", str(profile),
                             str(RIG_TESTS)], capture_output=True, text=True, timeout=300,
                            cwd=Path(__file__).parents[2])
    assert result.returncode == 1 and "3 failed" in result.stdout, result.stdout[-2000:]
    said = [line for line in result.stdout.splitlines() if line.startswith(f"--rig {profile}: cannot open the rig: ")]
    assert len(said) == 3 and "/dev/absent-valves" in said[0], result.stdout[-2000:]
    assert "Traceback" not in result.stdout and "raise " not in result.stdout
