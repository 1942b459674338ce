"""`hydrojet-bench emulate`: the standalone emulators answer a real client on their pty
and stop cleanly on Ctrl-C."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import serial

from drivers.aurora.commands import Command
from drivers.valve.client import ValveController


def start(device: str) -> tuple[subprocess.Popen, str]:
    process = subprocess.Popen([sys.executable, "-m", "hydrojet_bench.cli", "emulate", device],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = process.stdout.readline()
    path = line.strip().rsplit(" ", 1)[-1]
    assert path.startswith("/dev/"), line
    return process, path


def stop(process: subprocess.Popen) -> str:
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=10)
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
