"""Shared pieces of the Aurora tests: a plant with non-trivial poses, helpers to talk to
an emulator, and serving an emulator over each simulated backend (sim://, pty).
(A uniquely named module rather than conftest.py, so test modules can import it.)"""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import AsyncIterator

import numpy as np

from drivers.aurora.commands import Command
from drivers.aurora.emulator import AuroraEmulator
from drivers.aurora.frames import decode_bx
from drivers.aurora.replies import decode_reply
from drivers.plant import StaticPlant
from drivers.transport.pty import PtyServer
from drivers.transport.sim import serve_sim
from hydrojet_bench.geometry import quat_from_rotvec

# Base tilted and offset, tip bent away: every quaternion component and axis matters.
POSES = {
    "base": (quat_from_rotvec([0.1, -0.2, 0.3]), (0.010, -0.020, 0.150)),
    "tip": (quat_from_rotvec([0.5, 0.1, -0.4]), (0.030, 0.012, 0.081)),
}
HANDLES = {0x0A: "base", 0x0B: "tip"}
SIM_BACKENDS = ["sim", "pty"]

_names = itertools.count()


def make_plant() -> StaticPlant:
    return StaticPlant(POSES)


def truth_mm(plant: StaticPlant, sensor: str) -> tuple[np.ndarray, np.ndarray]:
    """(quaternion, position in mm) of a plant sensor."""
    truth = plant.sensor_truth(sensor, 0.0)
    return truth.orientation_in_tracker, truth.position_in_tracker_m * 1000.0


def talk(emulator: AuroraEmulator, text: str):
    """Send one command (``NAME:params`` or ``NAME``) with CRC; decode the reply."""
    name, _, params = text.partition(":")
    raw = emulator.receive(Command(name, params).encode())
    if raw.startswith(b"\xc4\xa5"):
        return decode_bx(raw)
    return decode_reply(raw)


def set_up_tracking(emulator: AuroraEmulator) -> None:
    for text in ("INIT", "PINIT:0A", "PINIT:0B", "PENA:0AD", "PENA:0BD", "TSTART"):
        talk(emulator, text)
    assert emulator.mode == "tracking"


@contextlib.asynccontextmanager
async def served(emulator: AuroraEmulator, backend: str) -> AsyncIterator[str]:
    """Serve the emulator on ``backend`` ("sim" or "pty"); yields the client URL."""
    if backend == "sim":
        async with serve_sim(f"aurora-test-{next(_names)}", emulator) as url:
            yield url
    elif backend == "pty":
        with PtyServer(emulator, name="aurora-test-pty") as server:
            yield f"pty://{server.path}"
    else:
        raise ValueError(backend)
