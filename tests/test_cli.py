"""The command line: its commands, the perf JSON, and user mistakes without tracebacks."""

from __future__ import annotations

import json
import subprocess
import sys

from hydrojet_bench.cli import COMMAND_MODULES, main


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hydrojet_bench.cli", *args], capture_output=True, text=True,
                          timeout=300)


def test_help_lists_every_command_and_no_retired_one(capsys):
    assert main([]) == 2
    out = capsys.readouterr().out
    for name in COMMAND_MODULES:
        assert f"    {name}" in out, name
    assert "demo" not in out  # retired: `make demo` runs `run`


def test_perf_writes_json_with_every_figure_and_its_target(tmp_path):
    path = tmp_path / "perf.json"
    assert main(["perf", "--runs", "200", "--json", str(path)]) == 0
    figures = json.loads(path.read_text())
    for name in ("cosserat_warm_solve", "cosserat_cold_solve", "prb_warm_solve", "sensitivity_6_columns"):
        assert figures[name]["median_us"] > 0 and figures[name]["target_us"] > 0
    comparison = figures["solve_bvp_comparison"]
    assert comparison["tip_difference_mm"] < 0.01  # accuracy, not speed: deterministic
    assert comparison["speedup_warm"] > 0
    assert figures["imu_fusion"]["update_us"] > 0 and figures["imu_fusion"]["target_us"] == 10.0


def test_user_mistakes_are_one_line_without_traceback(tmp_path):
    for args, message in (
        (["perf", "--runs", "10"], "--runs must be at least 200"),
        (["calibrate", str(tmp_path / "missing.csv"), "--position-weight", "-1", "-o", str(tmp_path / "p.toml")],
         "--position-weight must be >= 0"),
        (["perf", "--runs", "200", "--json", str(tmp_path / "missing" / "out.json")], "cannot write"),
    ):
        result = run_cli(*args)
        assert result.returncode == 2, args
        assert message in result.stderr
        assert "Traceback" not in result.stderr
