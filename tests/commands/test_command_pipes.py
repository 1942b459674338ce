"""Output that pipes: every command run with its standard output on a pipe, as a script
or `| grep` sees it. Tables and lines are whole (nothing cut to "…", no file name wrapped
whatever COLUMNS says), ``--json -`` puts the JSON alone on standard output, progress
and warnings go to standard error, and every --help states the exit codes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from hydrojet_bench.cli import _all_subparsers, build_parser
from hydrojet_bench.data.csv_io import write_csv
from hydrojet_bench.plans import calibration_plan, validation_sweeps
from hydrojet_bench.profile import load_profile
from hydrojet_bench.twin import DigitalTwin, TwinConfig

# Longer than a terminal's 80 columns, so that a table titled with it would be cut or wrapped.
LONG_NAME = "a_session_recorded_on_the_bench_with_a_name_longer_than_any_terminal_is_wide"


def piped(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    environment = {**os.environ, "COLUMNS": "50"}  # a narrow terminal's setting must not matter on a pipe
    return subprocess.run([sys.executable, "-m", "hydrojet_bench.cli", *args], capture_output=True, text=True,
                          timeout=300, cwd=cwd, env=environment)


def whole(result: subprocess.CompletedProcess) -> subprocess.CompletedProcess:
    assert result.returncode == 0, result.stderr
    assert "…" not in result.stdout + result.stderr
    assert "Traceback" not in result.stderr
    return result


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """A short twin recording (jet 3 at 85 %) and a six-pose session log, long-named."""
    folder = tmp_path_factory.mktemp("pipes")
    profile = load_profile("sim")
    twin = DigitalTwin(TwinConfig.from_profile(profile, hidden_effects=("jet_gain",),
                                               hidden_effect_values=(("jet_gain.gain_3", 0.85),), seed=3))
    plan = calibration_plan(20) + validation_sweeps(0.1, steps_up=5, repetitions=2)
    write_csv(twin.run_plan(plan).to_dataset(profile, "short twin"), folder / f"{LONG_NAME}.csv")
    # x25, not faster: at x50 the emulated IMUs fall so far behind (issue 15) that `sensors`
    # may find no IMU sample close enough to an EM sample to align them.
    run = whole(piped("run", "--plan", "calibration:6", "--time-scale", "25", "--log", f"{LONG_NAME}.mcap",
                      cwd=folder))
    assert "step 6/6" in run.stderr and "step 6/6" not in run.stdout  # progress
    assert "session done: 6/6 steps" in run.stdout and f"replay {LONG_NAME}.mcap --online" in run.stdout
    return folder


def test_tables_keep_whole_names_on_a_pipe(folder):
    data = f"{LONG_NAME}.csv"
    calibrated = whole(piped("calibrate", data, "-o", "p.toml", cwd=folder))
    assert f"cosserat calibrated on 20 calibration poses of {data}" in calibrated.stdout.splitlines()
    assert calibrated.stderr == ""
    compared = whole(piped("compare", data, "--params", "p.toml", "--online", cwd=folder))
    assert f"RMS errors, cosserat on {data}" in compared.stdout.splitlines()
    assert any(line.startswith("┃ group") and "Proposed orient. (deg)" in line for line in compared.stdout.splitlines())
    assert compared.stderr == ""
    simulated = whole(piped("simulate", "-o", "twin.csv", cwd=folder))
    assert simulated.stdout.startswith("wrote 45800 samples") and simulated.stderr == ""


@pytest.mark.parametrize("command", [
    ["calibrate", f"{LONG_NAME}.csv", "-o", "q.toml"],
    ["compare", f"{LONG_NAME}.csv", "--params", "q.toml", "--online"],
    ["diagnose", f"{LONG_NAME}.csv", "--candidate", "jet_gain", "--candidate", "gravity", "--workers", "1"],
    ["replay", f"{LONG_NAME}.mcap", "--online"],
    ["sensors", f"{LONG_NAME}.mcap"],
], ids=lambda command: command[0])
def test_json_to_standard_output_alone(folder, command):
    if command[0] == "compare" and not (folder / "q.toml").exists():
        whole(piped("calibrate", f"{LONG_NAME}.csv", "-o", "q.toml", cwd=folder))
    result = whole(piped(*command, "--json", "-", cwd=folder))
    document = json.loads(result.stdout)
    assert isinstance(document, dict) and document
    assert "┃" in result.stderr  # the tables moved to standard error
    expected = {"calibrate": "parameters", "compare": "per_step", "diagnose": "verdict", "replay": "live_difference_deg",
                "sensors": "online_estimation"}[command[0]]
    assert expected in document
    if command[0] == "replay":
        assert document["live_difference_deg"] == 0.0 and document["steps"] == 6
    if command[0] == "calibrate":
        assert set(document["parameters"]) == set(document["standard_errors"]) and document["evaluations"] > 0


@pytest.mark.parametrize("json_option", [[], ["--json", "-"]], ids=["tables", "json"])
def test_a_reader_that_stops_early_is_exit_code_141_without_a_traceback(folder, json_option):
    process = subprocess.Popen([sys.executable, "-m", "hydrojet_bench.cli", "calibrate", f"{LONG_NAME}.csv",
                                "-o", "r.toml", *json_option], cwd=folder, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    process.stdout.close()  # as `| head -0` would: every write to standard output fails
    _, err = process.communicate(timeout=300)
    assert process.returncode == 141, err
    assert "Traceback" not in err and "Exception ignored" not in err


def test_every_help_states_the_exit_codes():
    main = build_parser()
    every = [main, *_all_subparsers(main)]
    assert len(every) == 1 + 13 + 2  # the commands, and batch's two actions
    for parser in every:
        text = " ".join(parser.format_help().split())
        assert "exit codes: 0 done; 1 internal error" in text and "; 2 a mistake in the command line" in text, \
            parser.prog
    run = next(parser for parser in every if parser.prog.endswith(" run"))
    assert "143 stopped by SIGTERM" in " ".join(run.format_help().split())
