"""`hydrojet-bench run` as a user starts it: a clean stop on SIGINT, SIGTERM and SIGHUP (valves
off, log finished), the live view, and clear errors for a user's mistakes."""

from __future__ import annotations

import fcntl
import os
import pty
import select
import signal
import subprocess
import termios
import sys
import time
from pathlib import Path

import pytest
from rich.console import Console

from hydrojet_bench.bench.live_view import LiveView
from hydrojet_bench.bench.stream_rates import StreamRateFigure
from hydrojet_bench.bench.session import SessionStatus
from hydrojet_bench.logs import read_log
from hydrojet_bench.logs.topics import Event, Sample, SetupCheck, Step, ValveCommand
from hydrojet_bench.plans import PlanStep


def start_run(tmp_path: Path, *options: str) -> tuple[subprocess.Popen, Path]:
    log_path = tmp_path / "run.mcap"
    process = subprocess.Popen([sys.executable, "-m", "hydrojet_bench.cli", "run", "--plan", "sweeps", "--no-live",
                                "--time-scale", "5", "--log", str(log_path), *options],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    return process, log_path


def wait_for_commands(log_path: Path, timeout_s: float = 120.0, while_waiting=lambda: None) -> None:
    """Until the session has opened a jet (its log shows a non-zero command)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        while_waiting()
        if log_path.exists():
            commands = [m.jet_forces_n for m in read_log(log_path, topics=["/valves/command"]).messages]
            if any(max(forces) > 0 for forces in commands):
                return
        time.sleep(0.5)
    raise AssertionError("the session never commanded a jet")


@pytest.mark.parametrize("signal_number, exit_code", [(signal.SIGINT, 130), (signal.SIGTERM, 143),
                                                       (signal.SIGHUP, 129)])
def test_a_signal_stops_the_session_cleanly(tmp_path, signal_number, exit_code):
    process, log_path = start_run(tmp_path)
    try:
        wait_for_commands(log_path)
        process.send_signal(signal_number)
        output, _ = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == exit_code, output
    assert "Traceback" not in output
    assert "valves closed, log finished" in " ".join(output.split())
    contents = read_log(log_path)
    assert not contents.truncated  # finished: summary and footer written
    assert any("interrupted" in m.message for m in contents.on(Event))
    # The session's own last word to the valves: the driver's ALL_OFF is not a logged
    # command, but no command after the interruption may open a jet.
    interrupted_at = next(m.t_s for m in contents.on(Event) if "interrupted" in m.message)
    assert all(max(m.jet_forces_n) == 0 for m in contents.on(ValveCommand) if m.t_s > interrupted_at)
    # ...and the controller's acknowledgement of it, logged after the rig closed.
    assert [m.message for m in contents.on(Event) if m.source == "valves"][-1] == ("closed: the controller "
                                                                                  "acknowledged ALL_OFF")


def test_an_interrupted_session_says_it_wrote_no_report_and_what_writes_it(tmp_path):
    report = tmp_path / "report"
    process, log_path = start_run(tmp_path, "--report", str(report))
    try:
        deadline = time.monotonic() + 120
        while not (log_path.exists() and read_log(log_path, topics=[Step.topic]).on(Step)):
            assert time.monotonic() < deadline, "no step finished"
            time.sleep(0.5)
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 130, output
    replay = f"hydrojet-bench replay {log_path} --online --report {report}"
    assert (f"warning: no report written to {report}: the session was stopped before its end; {replay} writes it "
            "from the log's finished steps") in " ".join(output.split()), output
    assert not list(report.glob("*"))
    from hydrojet_bench.cli import main

    assert main(replay.split()[1:]) == 0  # as printed
    assert list(report.glob("*.png"))


def test_a_session_stopped_before_any_sweep_step_offers_no_replay_for_its_report(tmp_path):
    import argparse

    from hydrojet_bench.commands.run import _say_no_report

    console = Console(record=True, width=300)
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")  # reserved, and stopped before the session wrote to it
    _say_no_report(console, argparse.Namespace(report=tmp_path / "r", figure_format="png"), empty)
    assert console.export_text().strip() == (f"warning: no report written to {tmp_path / 'r'}: the session was "
                                             "stopped before its end, and its log holds no finished sweep step to "
                                             "report on")


def test_a_closed_terminal_stops_the_session_cleanly(tmp_path):
    """ssh or the terminal window closed under the live view: the kernel hangs up the
    terminal (a write to it fails from then on) and sends SIGHUP. The session still closes
    the valves and finishes its log, and exits 129."""
    master, slave = pty.openpty()
    log_path = tmp_path / "run.mcap"

    def take_the_terminal() -> None:  # in the child, a session leader: the pty becomes its terminal
        fcntl.ioctl(0, termios.TIOCSCTTY, 0)

    process = subprocess.Popen([sys.executable, "-m", "hydrojet_bench.cli", "run", "--plan", "sweeps",
                                "--time-scale", "5", "--log", str(log_path)], stdin=slave, stdout=slave,
                               stderr=slave, start_new_session=True, preexec_fn=take_the_terminal)
    os.close(slave)
    try:
        # The live view writes on: read it, or the terminal's buffer fills and stops the session.
        wait_for_commands(log_path, while_waiting=lambda: _drain(master))
        os.close(master)  # the hangup
        master = None
        process.wait(timeout=60)
    finally:
        if master is not None:
            os.close(master)
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 129
    contents = read_log(log_path)
    assert not contents.truncated
    assert any("interrupted" in m.message for m in contents.on(Event))
    assert [m.message for m in contents.on(Event) if m.source == "valves"][-1] == ("closed: the controller "
                                                                                  "acknowledged ALL_OFF")


def _drain(fd: int) -> None:
    while select.select([fd], [], [], 0)[0]:
        try:
            if not os.read(fd, 65536):
                return
        except OSError:  # the child's side closed
            return


def test_run_reports_a_bad_plan_file_without_traceback(tmp_path):
    plan = tmp_path / "plan.csv"
    plan.write_text("q1,q2,q3\n0.05,0,0\n0.05,-0.01,0\n")
    result = subprocess.run([sys.executable, "-m", "hydrojet_bench.cli", "run", "--plan", str(plan), "--no-live",
                             "--log", str(tmp_path / "x.mcap")], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert "plan.csv, row 2" in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "x.mcap").exists()


def test_live_view_renders_progress_errors_and_health():
    status = SessionStatus(step_count=229, phase="sweep 3", step_index=99, step=PlanStep((0.05, 0.0, 0.0), 3, 7),
                           remaining_session_s=600.0, ref_error_deg=1.234, online_error_deg=0.456,
                           disturbance_norm_nm=2.5e-4, em_frames=4000, em_missing=3, imu_samples=1000)
    status.stream_rates["em"] = StreamRateFigure("em", configured_hz=40.0, samples=199, interval_s=5.0)
    status.stream_rates["imu"] = StreamRateFigure("imu", configured_hz=100.0, samples=400, interval_s=5.0)
    status.events.append((12.0, "warning", "sensor not tracked: tip MISSING", "tracker"))
    status.events.append((13.0, "error", "stopped: effect [bold]my[/x].py:Twist: apply failed", "session"))
    console = Console(record=True, width=100)
    console.print(LiveView(console, time_scale=25.0, title="test").render(status))
    text = console.export_text()
    for expected in ("step 100/229", "sweep 3", "q1 0.050", "ref 1.23", "online 0.46", "0.25 mN m",
                     "4000 frames, 3 incomplete", "sensor not tracked", "ETA 00:24",
                     "effect [bold]my[/x].py:Twist", "em 39.8/40 Hz", "imu 80.0/100 Hz"):
        assert expected in text, (expected, text)


def test_without_the_live_view_the_sessions_warnings_are_printed_as_they_come():
    """A FIFO overflow or a stream falling behind was only in the live view and the log;
    what the command prints itself (the request's warnings before, calibration and
    setup checks in its report) is not said twice."""
    from hydrojet_bench.commands.run import _printer

    console = Console(record=True, width=200)
    update = _printer(console, frozenset())
    status = SessionStatus(step_count=3, phase="calibration poses", step_index=0, step=PlanStep((0.05, 0.0, 0.0), -1, 1))
    for event in [(1.0, "warning", "2 step(s) of the plan ...", "request"), (2.0, "info", "armed", "session"),
                  (3.0, "warning", "base IMU's FIFO overflowed", "imu"),
                  (4.0, "warning", "NOT converged", "calibration")]:
        status.events.append(event)
        status.event_count += 1
    update(status)
    status.events.append((6.0, "warning", "falling behind: em stream", "em"))
    status.event_count += 1
    status.step_index = 1
    update(status)
    text = console.export_text()
    assert "warning: base IMU's FIFO overflowed (3.0 s)" in text and "warning: falling behind: em stream" in text
    assert text.count("FIFO overflowed") == 1
    for said_elsewhere in ("2 step(s)", "armed", "NOT converged"):
        assert said_elsewhere not in text


def test_a_miswired_rig_stops_before_the_protocol_with_one_line(tmp_path):
    profile = tmp_path / "swapped.toml"
    profile.write_text((Path(__file__).parents[2] / "profiles" / "sim.toml").read_text()
                       + "\n[twin]\njet_wiring = [1, 3, 2]\n")
    log_path = tmp_path / "swapped.mcap"
    done = subprocess.run([sys.executable, "-m", "hydrojet_bench.cli", "run", "--profile", str(profile), "--plan",
                           "calibration:2", "--no-live", "--time-scale", "5", "--log", str(log_path)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "Traceback" not in done.stderr
    assert "jets 2 and 3 appear swapped: tip moved towards jet 3's side when jet 2 fired" in done.stderr
    contents = read_log(log_path)
    checks = {m.check: m.status for m in contents.on(SetupCheck)}
    assert checks["wiring"] == "fail" and checks["level"] == "pass"
    # No protocol data taken: no step, and no sample logged while a check fired a jet.
    assert not contents.on(Step)
    fired = [m.t_s for m in contents.on(ValveCommand) if max(m.jet_forces_n) > 0]
    assert len(fired) == 3
    assert not [m for m in contents.on(Sample) if fired[0] <= m.t_s <= fired[-1]]


def test_skipping_the_checks_is_logged(tmp_path):
    log_path = tmp_path / "skipped.mcap"
    done = subprocess.run([sys.executable, "-m", "hydrojet_bench.cli", "run", "--plan", "calibration:1", "--no-live",
                           "--time-scale", "5", "--skip-checks", "--no-calibration", "--log", str(log_path)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert {m.check: m.status for m in read_log(log_path).on(SetupCheck)} == {"wiring": "skipped",
                                                                               "level": "skipped"}


def test_a_tilted_field_generator_warns_with_both_gravity_vectors(tmp_path):
    profile = tmp_path / "tilted.toml"
    profile.write_text((Path(__file__).parents[2] / "profiles" / "sim.toml").read_text()
                       + "\n[twin]\ntracker_tilt_deg = [3.0, 0.0]\n")
    log_path = tmp_path / "tilted.mcap"
    done = subprocess.run([sys.executable, "-m", "hydrojet_bench.cli", "run", "--profile", str(profile), "--plan",
                           "calibration:1", "--no-live", "--no-calibration", "--time-scale", "5", "--log",
                           str(log_path)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    # A warning goes to standard error, beside the progress, not into the report.
    warned = " ".join(done.stderr.split())
    assert "warning: level check: gravity differs by" in warned and "base IMU gravity [" in warned
    assert "level check" not in done.stdout
    (level,) = [m for m in read_log(log_path).on(SetupCheck) if m.check == "level"]
    assert level.status == "warn" and abs(level.values["angle_deg"] - 3.0) < 0.2


def test_next_offers_diagnose_only_on_steps_it_can_split():
    """The imu-vs-em plan has sweeps (its ramps) but 8 training steps: `diagnose` on its
    log said it needs 10, after run's "next" had offered it."""
    from hydrojet_bench.commands.run import _diagnosable
    from hydrojet_bench.plans import imu_versus_em_plan, paper_protocol
    from hydrojet_bench.profile import load_profile
    from hydrojet_bench.twin import DigitalTwin, TwinConfig

    profile = load_profile("sim")
    twin = DigitalTwin(TwinConfig.from_profile(profile))
    paper = twin.run_plan(paper_protocol(), record_window_s=1.0).to_dataset(profile).quasistatic_steps()
    ramps = twin.run_plan(imu_versus_em_plan(), record_window_s=1.0).to_dataset(profile).quasistatic_steps()
    assert _diagnosable(paper) and not _diagnosable(ramps)


def test_a_failed_session_calibration_is_said_and_is_no_clean_exit(tmp_path, capsys):
    """One calibration pose cannot determine nine parameters: the session runs on with its
    starting parameters, and its summary says so (the log's event was all there was), the
    exit is calibrate's for an untrusted fit, and "next" offers no calibrate that would fail."""
    from hydrojet_bench.cli import main

    plan = tmp_path / "one.csv"
    plan.write_text("q1,q2,q3,sweep\n0.05,0,0,-1\n0.02,0,0,0\n0.04,0,0,0\n")
    log = tmp_path / "one.mcap"
    assert main(["run", "--plan", str(plan), "--no-live", "--skip-checks", "--time-scale", "20",
                 "--log", str(log)]) == 3
    out, err = capsys.readouterr()
    assert ("warning: the calibration on the calibration poses failed: 1 pose cannot determine 9 parameters; the "
            "session predicted and estimated with its starting parameters") in " ".join(err.split())
    assert "RMS errors" in out  # Table II of the sweep steps all the same
    assert f"replay {log} --online" in out and "calibrate" not in out and "--params p.toml" not in out
    # Without the session's own calibration, "next" still counts whether the poses can
    # determine a calibration before it offers one.
    uncalibrated = tmp_path / "no-fit.mcap"
    assert main(["run", "--plan", str(plan), "--no-live", "--skip-checks", "--time-scale", "20", "--no-calibration",
                 "--log", str(uncalibrated)]) == 0
    out, _ = capsys.readouterr()
    assert f"replay {uncalibrated} --online" in out and "hydrojet-bench calibrate" not in out
