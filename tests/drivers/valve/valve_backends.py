"""Valve test helpers: emulator backends (sim link, pty) behind one async context.

A plain module with a unique name (not conftest.py) so test files can import it
without clashing with other directories' helpers."""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import AsyncIterator
from dataclasses import dataclass

import pytest

from drivers.plant import StaticPlant
from drivers.transport.pty import PtyServer
from drivers.transport.sim import serve_sim
from drivers.valve.emulator import ValveEmulator

_names = itertools.count()


@dataclass
class Bench:
    url: str
    emulator: ValveEmulator
    plant: StaticPlant


@contextlib.asynccontextmanager
async def emulator_backend(kind: str, watchdog_s: float = 0.5) -> AsyncIterator[Bench]:
    """A fresh plant + emulator served on ``kind`` ("sim" or "pty")."""
    plant = StaticPlant()
    emulator = ValveEmulator(plant, watchdog_s=watchdog_s)
    if kind == "sim":
        async with serve_sim(f"valve-test-{next(_names)}", emulator, poll_interval_s=0.005) as url:
            yield Bench(url, emulator, plant)
    elif kind == "pty":
        with PtyServer(emulator, poll_interval_s=0.005) as server:
            yield Bench(f"pty://{server.path}", emulator, plant)
    else:
        raise ValueError(f"unknown backend {kind!r}")


# Parametrise a test over every emulator backend; the test gets ``backend`` ("sim" or
# "pty") and enters `emulator_backend(backend)` inside its coroutine.
every_backend = pytest.mark.parametrize("backend", ["sim", "pty"])
