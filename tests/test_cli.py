"""The command line: its commands, the perf JSON, and user mistakes without tracebacks."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console

from hydrojet_bench import cli
from hydrojet_bench.cli import COMMAND_MODULES, main
from hydrojet_bench.commands import render
from hydrojet_bench.config.loading import PROFILES_DIR
from hydrojet_bench.errors import UserError
from hydrojet_bench.files import check_folder_target
from hydrojet_bench.logs import read_log
from hydrojet_bench.params import PARAMETER_NAMES, ModelParameters, get_parameter
from hydrojet_bench.params_io import ParameterFile, write_parameter_file


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
    assert main(["perf", "--runs", "200", "--no-session", "--json", str(path)]) == 0
    figures = json.loads(path.read_text())
    for name in ("cosserat_warm_solve", "cosserat_cold_solve", "prb_warm_solve", "sensitivity_6_columns"):
        assert figures[name]["median_us"] > 0 and figures[name]["target_us"] > 0
    comparison = figures["solve_bvp_comparison"]
    assert comparison["tip_difference_mm"] < 0.01  # accuracy, not speed: deterministic
    assert comparison["speedup_warm"] > 0
    assert figures["imu_fusion"]["update_us"] > 0 and figures["imu_fusion"]["target_us"] == 10.0
    # The diagnosis is timed after a first run that loads (or compiles) its kernels.
    diagnosis = figures["diagnose_229_steps"]
    assert diagnosis["warmup_s"] > 0 and diagnosis["seconds"] > 0 and diagnosis["candidates"] == 12


def test_user_mistakes_are_one_line_without_traceback(tmp_path):
    for args, message in (
        (["perf", "--runs", "10"], "--runs must be at least 200"),
        (["calibrate", str(tmp_path / "missing.csv"), "--position-weight", "-1", "-o", str(tmp_path / "p.toml")],
         "--position-weight must be from 0 to 10000 rad per m"),
        (["calibrate", str(tmp_path / "missing.csv"), "--position-weight", "1e308", "-o", str(tmp_path / "p.toml")],
         "--position-weight must be from 0 to 10000 rad per m"),
        (["run", "--plan", "hold:1e300", "--log", str(tmp_path / "h.mcap")],
         "plan 'hold:1e300': hold:SECONDS takes a number of seconds > 0 and at most 86400 (one day)"),
        # Refused before the figures are computed (a whole perf run), naming the folder.
        (["perf", "--runs", "200", "--no-session", "--json", str(tmp_path / "missing" / "out.json")],
         f"cannot write the JSON figures: its folder {tmp_path / 'missing'} does not exist"),
    ):
        result = run_cli(*args)
        assert result.returncode == 2, args
        assert message in result.stderr
        assert "Traceback" not in result.stderr


SIM_PROFILE = (PROFILES_DIR / "sim.toml").read_text()
# A parameter file's values at the nominal parameters.
NOMINAL = {name: get_parameter(ModelParameters(), name) for name in PARAMETER_NAMES}
TWO_STEPS = ("[[step]]\nq1 = 0.05\nq2 = 0.0\nq3 = 0.0\nsettle_s = 2.0\n"
             "[[step]]\nq1 = 0.0\nq2 = 0.05\nq3 = 0.0\nsettle_s = 2.0\n")


def one_line_error(capsys, argv: list[str]) -> str:
    """The message of a command that must fail as a user's mistake: exit 2, one line."""
    assert main(argv) == 2, argv
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    return err[len("error: "):].rstrip("\n")


@pytest.mark.parametrize("name", ["[bold]x.csv", "[/x].csv", "[red]"])
def test_file_names_with_markup_are_printed_as_written(tmp_path, capsys, name):
    path = tmp_path / name
    message = one_line_error(capsys, ["calibrate", str(path), "-o", str(tmp_path / "p.toml")])
    assert message.startswith(f"{path}"), message


def test_table_names_in_messages_keep_their_brackets(tmp_path, capsys):
    profile = tmp_path / "rig.toml"
    profile.write_text(SIM_PROFILE.replace("length_m = 0.070", "lenght_m = 0.070"))
    message = one_line_error(capsys, ["run", "--profile", str(profile), "--plan", "calibration"])
    assert "rod.lenght_m is not a known key; did you mean length_m? ([rod] takes length_m," in message


@pytest.mark.parametrize(("options", "expected"), [
    (["--seed", "-1"], "--seed must be an integer >= 0, got -1"),
    (["--time-scale", "1e9"], "--time-scale must be at least 1 (real time: the devices' timeouts are wall time) and "
                              "at most 1000 (the simulated rig cannot keep up beyond), got 1000000000.0"),
    (["--time-scale", "inf"], "--time-scale must be at least 1 "),
    # Once a traceback from the drivers' sleep (timestamp out of range for time_t).
    (["--time-scale", "1e-300"], "--time-scale must be at least 1 "),
    (["--time-scale", "0.5"], "--time-scale must be at least 1 "),
])
def test_run_options_are_blamed_not_the_profile(tmp_path, capsys, options, expected):
    message = one_line_error(capsys, ["run", "--plan", "calibration", "--log", str(tmp_path / "x.mcap"), *options])
    assert message.startswith(expected), message
    assert not (tmp_path / "x.mcap").exists()


def test_a_rig_with_a_real_device_runs_on_wall_time(tmp_path, capsys):
    """The sim profile with its valves on an external board: x25 from the parent profile
    is refused where the profile loads (naming the file that names the device), and
    --time-scale on a rig with a real device, though the others are emulated."""
    profile = tmp_path / "board.toml"
    profile.write_text('extends = "sim"\n[transports]\nvalves = "pty:///dev/pts/9"\n')
    command = ["run", "--profile", str(profile), "--plan", "hold:2", "--no-live", "--skip-checks",
               "--log", str(tmp_path / "x.mcap")]
    message = one_line_error(capsys, command)
    assert message.startswith(f"{profile}: transports.valves = 'pty:///dev/pts/9' is a real device, and a rig with "
                              "any real device runs on wall time, but session.time_scale = 25"), message
    profile.write_text(profile.read_text() + "[session]\ntime_scale = 1.0\n")
    message = one_line_error(capsys, [*command, "--time-scale", "25"])
    assert message == (f"--time-scale 25: {profile} drives a real device (transports.valves = 'pty:///dev/pts/9'), "
                       "and a rig with any real device runs on wall time (only the fully simulated rig takes "
                       "--time-scale)")
    assert not (tmp_path / "x.mcap").exists()


def test_a_plan_step_held_for_ever_is_refused_before_the_session(tmp_path, capsys):
    plan = tmp_path / "plan.csv"
    plan.write_text("q1,q2,q3,settle_s,sweep,step\n0.05,0,0,1e300,0,0\n")
    message = one_line_error(capsys, ["run", "--plan", str(plan), "--no-live", "--skip-checks",
                                      "--log", str(tmp_path / "x.mcap")])
    assert message == f"{plan}, row 1: settle_s must be at most 86400 s (one day), got 1e+300"
    assert not (tmp_path / "x.mcap").exists()


def test_simulate_blames_a_negative_seed(tmp_path, capsys):
    message = one_line_error(capsys, ["simulate", "-o", str(tmp_path / "x.csv"), "--seed", "-1"])
    assert message == "--seed must be an integer >= 0, got -1"


def test_a_missing_estimator_effect_names_the_profile(tmp_path, capsys):
    profile = tmp_path / "rig.toml"
    profile.write_text(SIM_PROFILE + '\n[estimator]\neffects = ["clogged.py:Clogged"]\n')
    message = one_line_error(capsys, ["run", "--profile", str(profile), "--plan", "calibration",
                                      "--log", str(tmp_path / "x.mcap")])
    assert message.startswith(f"{profile} (estimator.effects): effect 'clogged.py:Clogged': file clogged.py does not "
                              "exist"), message


@pytest.mark.skipif(Path("/dev/i2c-1").exists(), reason="this machine has an I2C bus 1")
def test_the_physical_rig_profile_without_its_i2c_bus_is_one_line(tmp_path, capsys):
    plan = tmp_path / "plan.toml"
    plan.write_text(TWO_STEPS)
    command = ["run", "--profile", "hydrojet-v1", "--plan", str(plan), "--no-live", "--log", str(tmp_path / "x.mcap")]
    message = one_line_error(capsys, command)
    assert message.endswith("hydrojet-v1.toml: transports.imu_bus = 1: cannot open /dev/i2c-1: No such file or "
                            "directory (is this the rig's PC? imu_bus = \"sim\" emulates the IMUs) (nothing was "
                            "measured: no log kept)"), message
    # No log of the request alone stands in the way of the retry.
    assert not (tmp_path / "x.mcap").exists()
    assert "cannot open /dev/i2c-1" in one_line_error(capsys, command)


@pytest.mark.parametrize("key", ["tracker", "valves"])
def test_a_serial_port_that_cannot_be_opened_names_the_profile_key(tmp_path, capsys, key):
    profile = tmp_path / "port.toml"
    # A real device runs on wall time; no gyro-bias wait at that pace before the port opens.
    profile.write_text(f'extends = "sim"\n[transports]\n{key} = "serial:///dev/ttyNOPE"\n'
                       "[session]\ntime_scale = 1.0\n[imu]\ngyro_bias_samples = 0\n")
    plan = tmp_path / "plan.toml"
    plan.write_text(TWO_STEPS)
    message = one_line_error(capsys, ["run", "--profile", str(profile), "--plan", str(plan), "--no-live", "--log",
                                      str(tmp_path / "x.mcap")])
    assert message.startswith(f"{profile}: transports.{key} = 'serial:///dev/ttyNOPE': "), message
    assert "cannot open /dev/ttyNOPE" in message and message.endswith("(nothing was measured: no log kept)")


def test_ctrl_c_while_the_commands_modules_load_is_no_traceback(monkeypatch, capsys):
    def interrupted(argv):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "build_parser", interrupted)
    assert main(["run"]) == 130
    assert capsys.readouterr().err.strip() == "interrupted"


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs a folder no one can create in")
def test_a_report_folder_that_cannot_be_made_is_refused_before_the_work(tmp_path):
    """Root passes every permission test, but not /proc's."""
    with pytest.raises(UserError, match="cannot create report folder /proc/x/y"):
        check_folder_target(Path("/proc/x/y"), "report folder")
    check_folder_target(tmp_path / "a" / "b", "report folder")
    assert not (tmp_path / "a").exists()  # tried, and taken away again


def test_calibrate_without_calibration_poses_says_so(tmp_path, capsys):
    data = tmp_path / "sweeps.csv"
    data.write_text("t,q1,q2,q3,base_qw,base_qx,base_qy,base_qz,tip_qw,tip_qx,tip_qy,tip_qz,sweep\n"
                    "0.0,0.05,0,0,0,1,0,0,0,1,0,0,0\n")
    message = one_line_error(capsys, ["calibrate", str(data), "-o", str(tmp_path / "p.toml")])
    assert message.startswith(f"{data}: no calibration poses (steps of sweep -1) to fit on"), message


def test_a_plan_of_steps_shorter_than_the_averaging_window_is_warned_before_and_after_it_runs(tmp_path, capsys):
    plan = tmp_path / "plan.csv"
    plan.write_text("q1,q2,q3,settle_s\n0.05,0,0,0.3\n0,0.05,0,5\n")
    log = tmp_path / "x.mcap"
    assert main(["run", "--plan", str(plan), "--no-live", "--time-scale", "20", "--no-calibration",
                 "--log", str(log)]) == 0
    warning = ("1 step(s) of the plan (1) hold no longer than the 1 s each step's settled state is averaged over "
               "(session.window_s)")
    turning = "in 1 of 2 steps the tip was still turning (by more than 0.25 deg) over the end of its hold"
    err = " ".join(capsys.readouterr().err.split())
    assert f"warning: {warning}" in err and turning in err
    events = read_log(log, topics=["/events"]).messages
    assert any(e.level == "warning" and e.message.startswith(warning) for e in events)
    # The log's settled steps say which step was no equilibrium, so that `compare` on the
    # log (which predicts the session's own steps) says it too.
    assert [step.flags for step in read_log(log, topics=["/bench/step"]).messages] == [16, 0]
    params = tmp_path / "p.toml"
    write_parameter_file(params, ParameterFile(model="cosserat", effects=("gravity",), parameters=NOMINAL))
    assert main(["compare", str(log), "--params", str(params), "--json", str(tmp_path / "c.json")]) == 0
    assert turning in " ".join(capsys.readouterr().err.split())
    assert json.loads((tmp_path / "c.json").read_text())["unsettled_steps"] == {
        "count": 1, "steps": 2, "window_s": None, "trend_deg": 0.25}


def test_a_step_above_the_valves_limit_is_predicted_at_the_clipped_force_with_a_warning(tmp_path, capsys):
    plan = tmp_path / "plan.csv"
    plan.write_text("q1,q2,q3,settle_s\n0.3,0,0,5\n")
    assert main(["run", "--plan", str(plan), "--no-live", "--time-scale", "20", "--no-calibration",
                 "--log", str(tmp_path / "x.mcap")]) == 0
    printed = capsys.readouterr()
    err = " ".join(printed.err.split())  # progress and warnings: standard error
    warning = "1 step(s) of the plan (1) ask more than the valves give (0.15, 0.15, 0.15 N per jet)"
    assert f"warning: {warning}" in err
    assert "step 1/1 sweep 0 (clipped to the valves' limit): tip error ref" in err
    # Not repeated on standard output, the report's stream.
    assert "session done: 1/1 steps" in printed.out and warning not in " ".join(printed.out.split())
    events = read_log(tmp_path / "x.mcap", topics=["/events"]).messages
    assert any(e.level == "warning" and e.message.startswith(warning) for e in events)
    assert events[-1].message == "closed: the controller acknowledged ALL_OFF"
    commands = [m.jet_forces_n for m in read_log(tmp_path / "x.mcap", topics=["/valves/command"]).messages]
    assert (0.15, 0.0, 0.0) in [tuple(c) for c in commands] and max(max(c) for c in commands) == 0.15
    (step,) = read_log(tmp_path / "x.mcap", topics=["/bench/step"]).messages
    np.testing.assert_allclose(step.jet_forces_n, (0.15, 0.0, 0.0), atol=1e-12)
    (prediction, *_) = read_log(tmp_path / "x.mcap", topics=["/model/prediction"]).messages
    assert prediction.orientation_error_deg < 5.0  # at 0.3 N the prediction was 24.7 deg off


@pytest.mark.parametrize("table", ["transport", "sesion", "valve", "rood"])
def test_a_misspelt_table_in_the_shipped_profile_stops_run_before_anything_runs(tmp_path, capsys, table):
    proper = {"transport": "transports", "sesion": "session", "valve": "valves", "rood": "rod"}[table]
    profile = tmp_path / "hydrojet-v1.toml"
    profile.write_text((PROFILES_DIR / "hydrojet-v1.toml").read_text().replace(f"[{proper}]", f"[{table}]"))
    message = one_line_error(capsys, ["run", "--profile", str(profile), "--plan", "calibration",
                                      "--log", str(tmp_path / "x.mcap")])
    assert message.startswith(f"{profile}: {table} is not a known key; did you mean {proper}?"), message
    assert not (tmp_path / "x.mcap").exists()


def test_a_twin_without_equilibrium_stops_run_with_one_line_naming_the_profile(tmp_path, capsys):
    profile = tmp_path / "soft.toml"
    profile.write_text(SIM_PROFILE.replace("youngs_modulus_base_pa = 3.0e5", "youngs_modulus_base_pa = 1.0e3")
                       .replace("youngs_modulus_tip_pa = 2.0e5", "youngs_modulus_tip_pa = 1.0e3"))
    plan = tmp_path / "plan.toml"
    plan.write_text(TWO_STEPS)
    message = one_line_error(capsys, ["run", "--profile", str(profile), "--plan", str(plan), "--no-live",
                                      "--time-scale", "20", "--log", str(tmp_path / "x.mcap")])
    assert message.startswith("cosserat model did not converge"), message
    assert message.endswith(f"check the parameters and forces in {profile}, {plan}"), message


def test_table_titles_show_file_names_as_written():
    console = Console(record=True, width=100)
    console.print(render.table("cosserat calibrated on 40 poses of [bold]x[/x].csv", labels=("a",), numbers=("b",)))
    assert "posesof[bold]x[/x].csv" in "".join(console.export_text().split())  # the title wraps to the table


def test_simulate_plays_the_paper_protocol_within_the_profiles_valves(tmp_path, capsys):
    from hydrojet_bench.data.csv_io import read_csv
    from hydrojet_bench.profile import load_profile

    profile = tmp_path / "weak.toml"
    profile.write_text('extends = "sim"\n[jets]\nmax_force_n = 0.05\n')
    table = tmp_path / "weak.csv"
    assert main(["simulate", "--profile", str(profile), "-o", str(table)]) == 0
    err = " ".join(capsys.readouterr().err.split())
    assert "ask more than the valves give (0.05, 0.05, 0.05 N per jet)" in err
    assert f"({profile}: [jets] max_force_n)" in err
    assert read_csv(table, load_profile(profile)).jet_forces_n.max() == pytest.approx(0.05)


@pytest.mark.parametrize("command", [["run", "--plan", "calibration", "--no-live"],
                                     ["compare", "x.csv", "--params", "p.toml"], ["diagnose", "x.csv"],
                                     ["replay", "x.mcap"], ["sensors", "x.mcap"]])
def test_a_report_folder_that_cannot_be_made_is_refused_before_the_work(tmp_path, capsys, command):
    blocker = tmp_path / "figures"
    blocker.write_text("not a folder")
    log = tmp_path / "run.mcap"
    extra = ["--log", str(log)] if command[0] == "run" else []
    message = one_line_error(capsys, [*command, *extra, "--report", str(blocker / "report")])
    assert message == f"cannot create report folder {blocker / 'report'}: {blocker} is a file, not a folder"
    assert not log.exists()  # the session never started


def test_an_empty_log_is_called_empty(tmp_path, capsys):
    """A 0-byte .mcap reads as a log cut before its first record; the error says what it is."""
    empty = tmp_path / "empty.mcap"
    empty.touch()
    message = one_line_error(capsys, ["calibrate", str(empty), "-o", str(tmp_path / "p.toml")])
    assert message == (f"{empty}: no /bench/sample samples from source 'em': it has no /bench/sample messages "
                       "(an empty file: 0 bytes)")


def test_an_output_file_given_as_a_folder_path_and_a_parameter_hidden_twice_are_refused(tmp_path, capsys):
    # Path("out/") is Path("out"): without the check a file named like the folder was written.
    with pytest.raises(SystemExit) as exit_info:
        main(["simulate", "-o", f"{tmp_path}/out/"])
    assert exit_info.value.code == 2 and "a folder; give a file name" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
    assert main(["simulate", "-o", str(tmp_path / "x.csv"), "--hidden", "jet_gain:gain_1=0.8",
                 "--hidden", "jet_gain:gain_1=0.7"]) == 2
    assert "jet_gain.gain_1 is already 0.8 from an earlier --hidden" in capsys.readouterr().err
