"""simulate -> calibrate -> compare on the twin, through the command line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from hydrojet_bench.cli import main

# The documented example hidden effect: jet 2 delivers 60 % of its commanded force.
CLOGGED_JET = Path(__file__).resolve().parents[2] / "docs/examples/clogged_jet.py"


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    folder = tmp_path_factory.mktemp("twin")
    data = folder / "twin.csv"
    assert main(["simulate", "-o", str(data), "--hidden", f"{CLOGGED_JET}:CloggedJet", "--seed", "5"]) == 0
    return folder, data


def test_calibrate_then_compare_reports_table_2_figures(recorded, capsys):
    folder, data = recorded
    params = folder / "params.toml"
    assert main(["calibrate", str(data), "--model", "prb", "-o", str(params)]) == 0
    assert 'model = "prb"' in params.read_text() and "[standard_errors]" in params.read_text()
    out = folder / "figures.json"
    assert main(["compare", str(data), "--params", str(params), "--online", "--json", str(out),
                 "--report", str(folder / "report")]) == 0
    figures = json.loads(out.read_text())
    for key in ("orientation_rmse_deg", "position_rmse_mm", "by_bend", "by_sweep"):
        assert set(figures[key]) == {"ref", "online"}
    assert figures["orientation_rmse_deg"]["online"] < 0.6 * figures["orientation_rmse_deg"]["ref"]
    assert set(figures["by_bend"]["ref"]) <= {"10", "25", "50", "75", ">75"}
    assert len(figures["by_sweep"]["ref"]) == 9
    assert {"disturbance.png", "error_boxes.png", "tip_paths.png"} <= {p.name for p in (folder / "report").iterdir()}
    assert "Proposed" in capsys.readouterr().out


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "hydrojet_bench.cli", *args], capture_output=True, text=True,
                          timeout=300)


def test_user_mistakes_name_the_file_and_key(recorded, tmp_path):
    folder, data = recorded
    broken = tmp_path / "bad.toml"
    broken.write_text('model = "cosserat"\n[parameters]\nE0 = -5.0\n')
    bad_csv = tmp_path / "bad.csv"
    bad_csv.write_text("t,q1\n0,0\n")
    for args, message in (
        (["compare", str(data), "--params", str(tmp_path / "none.toml")], "no such parameter file"),
        (["compare", str(data), "--params", str(broken)], "parameters.E0 = -5 Pa is outside the plausible range"),
        (["calibrate", str(bad_csv), "-o", str(tmp_path / "p.toml")], "bad.csv"),
        (["calibrate", str(data), "--effect", "warp_drive", "-o", str(tmp_path / "p.toml")], "unknown effect"),
    ):
        result = run_cli(*args)
        assert result.returncode == 2, (args, result.stderr)
        assert message in result.stderr, result.stderr
        assert "Traceback" not in result.stderr
