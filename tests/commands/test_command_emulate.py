"""`hydrojet-bench emulate`: the standalone emulators answer a real client on their pty
and stop cleanly on Ctrl-C."""

from __future__ import annotations

import asyncio
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import serial

from drivers.aurora.client import AuroraTracker
from drivers.aurora.commands import Command
from drivers.valve.client import ValveController
from hydrojet_bench.profile import load_profile
from hydrojet_bench.twin import DigitalTwin, TwinConfig


def start(device: str, *options: str) -> tuple[subprocess.Popen, str]:
    process = subprocess.Popen([sys.executable, "-m", "hydrojet_bench.cli", "emulate", device, *options],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = process.stdout.readline()
    path = line.strip().rsplit(" ", 1)[-1]
    assert path.startswith("/dev/"), line
    return process, path


def stop(process: subprocess.Popen) -> str:
    process.send_signal(signal.SIGINT)
    try:
        _, stderr = process.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        process.kill()  # not left serving a pty after the test
        process.communicate()
        raise
    assert process.returncode == 0, stderr
    assert "Traceback" not in stderr
    return stderr


def test_valve_emulator_serves_the_real_client(run_async):
    process, path = start("valves")
    try:
        async def session():
            async with ValveController(f"pty://{path}") as valves:
                await valves.set_duties([100, 200, 300])
                return (await valves.status()).duties_permille

        assert tuple(run_async(session)) == (100, 200, 300)
    finally:
        assert "emulator stopped" in stop(process)


def test_aurora_emulator_answers_init_on_its_pty():
    process, path = start("aurora")
    try:
        with serial.Serial(path, 9600, timeout=2.0) as port:
            port.write(Command("INIT", "").encode())
            deadline = time.monotonic() + 5.0
            reply = b""
            while not reply.endswith(b"\r") and time.monotonic() < deadline:
                reply += port.read(1)
        assert reply.startswith(b"OKAY"), reply
    finally:
        stop(process)


def read_tip_position_mm(run_async, path: str) -> np.ndarray:
    async def session():
        async with AuroraTracker(f"pty://{path}", ["base", "tip"]) as tracker:
            return np.array((await tracker.read_frame())["tip"].position_mm)

    return run_async(session, timeout_s=20.0)


def test_aurora_emulator_serves_the_sim_profiles_twin_at_rest(run_async):
    # The sim profile hangs the clamp 0.20 m above the tracker origin with its tip sensor
    # 10 mm ahead of the rod tip: the twin's rest pose, not the static default.
    twin = DigitalTwin(TwinConfig.from_profile(load_profile("sim")))
    expected_mm = twin.sensor_poses("tip", 0.0)[1] * 1e3
    process, path = start("aurora", "--profile", "sim")
    try:
        measured_mm = read_tip_position_mm(run_async, path)
    finally:
        stop(process)
    # Emulator position noise is 0.48 mm RMS per axis-combined; 3 mm is > 5 sigma.
    assert np.linalg.norm(measured_mm - expected_mm) < 3.0, (measured_mm, expected_mm)


def test_aurora_emulator_static_pose_on_request(run_async):
    process, path = start("aurora", "--static")
    try:
        measured_mm = read_tip_position_mm(run_async, path)
    finally:
        stop(process)
    assert np.linalg.norm(measured_mm - np.array([0.0, 0.0, -70.0])) < 3.0, measured_mm


def test_emulate_rejects_an_unknown_profile_without_traceback():
    result = subprocess.run([sys.executable, "-m", "hydrojet_bench.cli", "emulate", "aurora", "--profile",
                             "no-such-profile"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert "no-such-profile" in result.stderr and "Traceback" not in result.stderr


@pytest.mark.parametrize(("args", "message"), [
    (["valves", "--watchdog-ms", "inf"], "--watchdog-ms must be 1..65535 (the firmware's whole milliseconds), got inf"),
    (["valves", "--watchdog-ms", "0.4"], "got 0.4"),
    (["valves", "--watchdog-ms", "70000"], "got 70000"),
    (["valves", "--watchdog-ms", "nan"], "got nan"),
    (["aurora", "--watchdog-ms", "-5"], "--watchdog-ms is the valve controller's; the aurora emulator has none"),
])
def test_a_watchdog_the_firmware_cannot_hold_is_one_line(args, message, capsys):
    from hydrojet_bench.cli import main

    assert main(["emulate", *args]) == 2
    assert message in capsys.readouterr().err


def test_the_help_says_ctrl_c_is_the_emulators_normal_end():
    """Its help listed 130 for Ctrl-C, while a stop by Ctrl-C, the only one it has, exits 0."""
    done = subprocess.run([sys.executable, "-m", "hydrojet_bench.cli", "emulate", "--help"], capture_output=True,
                          text=True, timeout=60)
    text = " ".join(done.stdout.split())
    assert done.returncode == 0 and ("; 130 interrupted (Ctrl-C) before it serves; Ctrl-C while it serves is its "
                                     "normal end, exit 0 (valves and pty closed);") in text, text


def test_both_emulators_in_one_command_share_the_twin_so_the_tip_moves_when_a_valve_opens(run_async):
    process = subprocess.Popen([sys.executable, "-m", "hydrojet_bench.cli", "emulate", "aurora", "valves"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        paths = {}
        for _ in range(2):
            line = process.stdout.readline().strip()
            paths["valves" if line.startswith("valve") else "aurora"] = line.rsplit(" ", 1)[-1]

        async def session():
            async with ValveController(f"pty://{paths['valves']}") as valves, \
                    AuroraTracker(f"pty://{paths['aurora']}", ["base", "tip"]) as tracker:
                rest = np.array((await tracker.read_frame())["tip"].position_mm)
                await valves.set_duties([800, 0, 0])
                await asyncio.sleep(2.0)  # several of the twin's settling time constants
                return rest, np.array((await tracker.read_frame())["tip"].position_mm)

        rest_mm, moved_mm = run_async(session, timeout_s=30.0)
    finally:
        stderr = stop(process)
    assert "emulators stopped" in stderr
    # A jet at 80 % duty bends the sim rod by centimetres; the tracker noise is 0.48 mm.
    assert np.linalg.norm(moved_mm - rest_mm) > 5.0, (rest_mm, moved_mm)
