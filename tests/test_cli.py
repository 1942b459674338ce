"""The command line: the demo, the perf JSON, and user mistakes without tracebacks."""

from __future__ import annotations

import json
import subprocess
import sys

from hydrojet_bench.cli import main


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hydrojet_bench.cli", *args], capture_output=True, text=True,
                          timeout=300)


def test_demo_prints_both_models(capsys):
    assert main(["demo", "--steps", "2", "--max-force", "0.1"]) == 0
    out = capsys.readouterr().out
    assert "Cosserat" in out and "PRB" in out and "0.100" in out


def test_perf_writes_json_with_every_figure_and_its_target(tmp_path):
    path = tmp_path / "perf.json"
    assert main(["perf", "--runs", "200", "--json", str(path)]) == 0
    figures = json.loads(path.read_text())
    for name in ("cosserat_warm_solve", "cosserat_cold_solve", "prb_warm_solve", "sensitivity_6_columns"):
        assert figures[name]["median_us"] > 0 and figures[name]["target_us"] > 0
    comparison = figures["solve_bvp_comparison"]
    assert comparison["tip_difference_mm"] < 0.01  # accuracy, not speed: deterministic
    assert comparison["speedup_warm"] > 0


def test_user_mistakes_are_one_line_without_traceback(tmp_path):
    for args, message in (
        (["perf", "--runs", "10"], "--runs must be at least 200"),
        (["demo", "--max-force", "-1"], "--max-force must be a positive number"),
        (["perf", "--runs", "200", "--json", str(tmp_path / "missing" / "out.json")], "cannot write"),
    ):
        result = run_cli(*args)
        assert result.returncode == 2, args
        assert message in result.stderr
        assert "Traceback" not in result.stderr
