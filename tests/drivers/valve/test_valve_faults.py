"""A bad line between client and emulator: the client recovers or raises a typed error,
never hangs; and a host that dies mid-session leaves the valves closed by the watchdog."""

from __future__ import annotations

import asyncio
import contextlib
import os
import select
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from drivers.plant import StaticPlant
from drivers.testing import FaultyTransport
from drivers.transport import TransportClosed, open_transport
from drivers.transport.pty import PtyServer
from drivers.valve import ValveController, ValveError, ValveFaultError
from drivers.valve.emulator import ValveEmulator
from valve_backends import emulator_backend, every_backend

REPO = Path(__file__).resolve().parents[3]

FAULTS = {
    "drop": {"drop": 0.2},
    "corrupt": {"corrupt": 0.02},
    "drop+corrupt+split": {"drop": 0.1, "corrupt": 0.01, "split": True},
    "rx-only-drop": {"drop": 0.3, "direction": "rx"},
}


async def _run_ops_under_faults(bench, faulty: FaultyTransport, fault_kwargs: dict) -> tuple[int, int]:
    """Open on a clean line, switch faults on, run commands, switch them off, close."""
    ok = failed = 0
    async with ValveController(transport=faulty, reply_timeout_s=0.05, retries=3) as valves:
        for name, value in fault_kwargs.items():
            setattr(faulty, name, value)
        for i in range(25):
            duties = (i * 40, 1000 - i * 40, (i * 137) % 1001)
            try:
                await valves.set_duties(duties)
            except ValveFaultError:
                failed += 1
                await _until_ok(valves.arm)
                continue
            except ValveError:
                failed += 1
                continue
            ok += 1
            # A success means the device holds exactly what we asked for.
            assert bench.emulator.duties_permille == duties
        for name in fault_kwargs:
            setattr(faulty, name, False if name == "split" else ("both" if name == "direction" else 0.0))
        status = await _until_ok(valves.status)  # the decoder has resynced on good frames
        assert status.duties_permille == bench.emulator.duties_permille
    assert bench.plant.valve_duties_permille == (0, 0, 0)
    return ok, failed


async def _until_ok(call, attempts: int = 5):
    for _ in range(attempts - 1):
        with contextlib.suppress(ValveError):
            return await call()
    return await call()


@every_backend
@pytest.mark.parametrize("fault", sorted(FAULTS))
def test_client_recovers_or_raises_typed_errors(run_async, backend: str, fault: str) -> None:
    async def main() -> None:
        async with emulator_backend(backend) as bench:
            faulty = FaultyTransport(open_transport(bench.url), seed=11)
            ok, failed = await _run_ops_under_faults(bench, faulty, FAULTS[fault])
            assert ok >= 15, (ok, failed, faulty.stats)  # retries absorb most faults
            assert sum(faulty.stats.values()) > 0  # faults really were injected

    run_async(main, timeout_s=20)


@every_backend
def test_split_and_delay_need_no_retries_at_all(run_async, backend: str) -> None:
    async def main() -> None:
        async with emulator_backend(backend) as bench:
            faulty = FaultyTransport(open_transport(bench.url), split=True, delay_s=0.005, seed=2)
            async with ValveController(transport=faulty, reply_timeout_s=0.2, retries=0) as valves:
                for i in range(10):
                    await valves.set_duty(i % 3, i * 100)
                assert (await valves.status()).duties_permille == (900, 700, 800)
            assert valves.timeouts == 0 and faulty.stats["split_reads"] > 0

    run_async(main)


@every_backend
def test_disconnect_raises_transport_closed_and_watchdog_closes_valves(run_async, backend: str) -> None:
    async def main() -> None:
        async with emulator_backend(backend, watchdog_s=0.15) as bench:
            faulty = FaultyTransport(open_transport(bench.url), disconnect_after=200)
            valves = ValveController(transport=faulty, heartbeat_interval_s=0.02)
            await valves.open()
            with pytest.raises(TransportClosed):
                async with asyncio.timeout(5):
                    for i in range(1000):
                        await valves.set_duties((500, 500, 500 + i % 2))
            await valves.close()  # cable gone: cannot send ALL_OFF, must not hang
            async with asyncio.timeout(3):
                while bench.plant.valve_duties_permille != (0, 0, 0):
                    await asyncio.sleep(0.01)
            assert bench.emulator.watchdog_trips == 1

    run_async(main)


CHILD = textwrap.dedent(
    """
    import asyncio, sys
    from drivers.valve import ValveController

    async def main():
        async with ValveController(sys.argv[1]) as valves:
            await valves.set_duties((600, 700, 800))
            print("OPEN", flush=True)
            await asyncio.sleep(60)

    asyncio.run(main())
    """
)


def _read_line(proc: subprocess.Popen, timeout_s: float) -> str:
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], timeout_s)
    if not ready:
        raise AssertionError(f"child said nothing within {timeout_s} s")
    return proc.stdout.readline().strip()


def test_sigkilled_host_leaves_valves_closed_within_the_watchdog_period() -> None:
    watchdog_s = 0.3
    margin_s = 0.3  # watchdog poll (5 ms) plus scheduling on a busy 2-core machine
    plant = StaticPlant()
    emulator = ValveEmulator(plant, watchdog_s=watchdog_s)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    with PtyServer(emulator, poll_interval_s=0.005) as server:
        proc = subprocess.Popen(
            [sys.executable, "-c", CHILD, f"pty://{server.path}"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO, env=env,
        )
        try:
            line = _read_line(proc, 20.0)
            assert line == "OPEN", proc.stderr.read() if proc.poll() is not None else line
            assert plant.valve_duties_permille == (600, 700, 800)
            time.sleep(3 * watchdog_s)  # the child's heartbeat keeps the valves open
            assert emulator.watchdog_trips == 0
            assert plant.valve_duties_permille == (600, 700, 800)
            killed_at = time.monotonic()
            proc.send_signal(signal.SIGKILL)
            proc.wait(5)
            deadline = killed_at + 5.0
            while plant.valve_duties_permille != (0, 0, 0) and time.monotonic() < deadline:
                time.sleep(0.005)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(5)
            proc.stdout.close()
            proc.stderr.close()
    closed_at, duties = plant.valve_history[-1]
    assert duties == (0, 0, 0)
    assert emulator.watchdog_trips == 1
    assert killed_at < closed_at <= killed_at + watchdog_s + margin_s
