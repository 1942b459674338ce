"""SIGKILL the bench mid-session: the valve board (an emulator in its own process) closes
the valves within its watchdog period, and the log is recoverable up to about a second
before the kill."""

from __future__ import annotations

import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from hydrojet_bench.logs import read_log, recover_log
from hydrojet_bench.profile import PROFILES_DIR

WATCHDOG_S = 0.5
HEARTBEAT_S = 0.1


def cli(*args: str, **kwargs) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "hydrojet_bench.cli", *args], text=True, **kwargs)


def lines_of(stream) -> queue.Queue:
    lines: queue.Queue = queue.Queue()

    def pump() -> None:
        for line in stream:
            lines.put(line.rstrip("\n"))

    threading.Thread(target=pump, daemon=True).start()
    return lines


def next_valve_change(lines: queue.Queue, timeout_s: float) -> tuple[tuple[int, ...], float]:
    """The next "valves D1 D2 D3 at monotonic T s" line of the emulator."""
    deadline = time.monotonic() + timeout_s
    while (remaining := deadline - time.monotonic()) > 0:
        try:
            line = lines.get(timeout=remaining)
        except queue.Empty:
            break
        if line.startswith("valves "):
            words = line.split()
            return tuple(int(w) for w in words[1:4]), float(words[6])
    raise AssertionError(f"no valve change within {timeout_s} s")


def test_sigkill_of_the_bench_closes_the_valves_and_leaves_a_recoverable_log(tmp_path: Path):
    emulator = cli("emulate", "valves", "--static", "--watchdog-ms", str(int(WATCHDOG_S * 1000)),
                   stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    bench = bench_output = None
    try:
        emulator_lines = lines_of(emulator.stdout)
        announce = emulator_lines.get(timeout=60)
        pty_path = announce.rsplit(" ", 1)[-1]
        assert pty_path.startswith("/dev/"), announce
        # The sim profile with its valves on the external board; the tracker and the IMUs
        # stay emulated in the bench process.
        profile = tmp_path / "external-valves.toml"
        sim = (PROFILES_DIR / "sim.toml").read_text()
        assert 'valves = "sim"' in sim
        # No gyro-bias sampling at start-up: at x1 it holds the bench 20 s (100 samples a
        # chip at 10 Hz) before the valves are armed, and the IMUs are not under test.
        assert "\n[imu]\n" in sim
        # A real device in the loop: the session runs on wall time.
        assert "time_scale = 25.0" in sim
        profile.write_text(sim.replace('valves = "sim"', f'valves = "pty://{pty_path}"')
                           .replace("time_scale = 25.0", "time_scale = 1.0")
                           .replace("\n[imu]\n", "\n[imu]\ngyro_bias_samples = 0\n"))
        plan = tmp_path / "hold.toml"
        plan.write_text("[[step]]\nq1 = 0.06\nq2 = 0.0\nq3 = 0.0\nsettle_s = 120.0\n")
        log_path = tmp_path / "killed.mcap"
        bench_output = (tmp_path / "bench.txt").open("w")
        bench = cli("run", "--profile", str(profile), "--plan", str(plan), "--no-live",
                    "--skip-checks", "--log", str(log_path), stdout=bench_output, stderr=subprocess.STDOUT)
        duties, opened_at = next_valve_change(emulator_lines, timeout_s=120)
        assert duties[0] > 0, duties
        time.sleep(3.0)  # let the log grow past a few flushes
        killed_monotonic, killed_unix = time.monotonic(), time.time()
        os.kill(bench.pid, signal.SIGKILL)
        bench.wait(timeout=10)
        duties, closed_at = next_valve_change(emulator_lines, timeout_s=5)
        assert duties == (0, 0, 0)
        # The last frame left up to one heartbeat before the kill; the board then waits out
        # its watchdog. 0.1 s of margin for the emulator's 5 ms poll and a busy machine.
        silence = closed_at - killed_monotonic
        assert WATCHDOG_S - HEARTBEAT_S - 0.05 <= silence <= WATCHDOG_S + 0.1, silence

        contents = read_log(log_path)
        assert contents.truncated
        last_unix = contents.start_time_unix_s + contents.messages[-1].t_s  # time scale 1: session s = wall s
        assert killed_unix - last_unix < 1.5, killed_unix - last_unix
        report = recover_log(log_path, tmp_path / "recovered.mcap")
        assert report.truncated and report.messages == len(contents.messages)
        assert not read_log(tmp_path / "recovered.mcap").truncated
    finally:
        if bench is not None and bench.poll() is None:
            bench.kill()
            bench.wait(timeout=10)
        if bench_output is not None:
            bench_output.close()
        emulator.send_signal(signal.SIGINT)
        emulator.communicate(timeout=10)
