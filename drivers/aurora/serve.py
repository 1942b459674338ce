"""Run the Aurora emulator on a pseudo-terminal until interrupted.

    serve_pty(plant)  # prints "NDI Aurora emulator on /dev/pts/N", runs until Ctrl-C

Any serial client (our `AuroraTracker`, scikit-surgerynditracker, NDI ToolBox under a
serial redirector) can then open the printed path as the tracker's port.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping

from drivers.aurora.emulator import ORIENTATION_NOISE_DEG, POSITION_NOISE_MM, AuroraEmulator
from drivers.plant import Plant
from drivers.transport.pty import PtyServer


def serve_pty(
    plant: Plant,
    *,
    tools: Mapping[int, str] | None = None,
    clock: Callable[[], float] = time.monotonic,
    seed: int = 0,
    position_noise_mm: float = POSITION_NOISE_MM,
    orientation_noise_deg: float = ORIENTATION_NOISE_DEG,
    announce: Callable[[str], None] = print,
    stop: threading.Event | None = None,
) -> None:
    """Serve an `AuroraEmulator` of ``plant`` on a fresh pty; ``announce`` gets a line
    naming the slave path. Returns when ``stop`` is set or on KeyboardInterrupt (Ctrl-C),
    after closing the pty. Re-raises an emulator crash."""
    emulator = AuroraEmulator(
        plant,
        clock,
        tools,
        seed=seed,
        position_noise_mm=position_noise_mm,
        orientation_noise_deg=orientation_noise_deg,
    )
    stop = stop or threading.Event()
    with PtyServer(emulator, name="aurora-emulator") as server:
        announce(f"NDI Aurora emulator on {server.path}")
        try:
            while not stop.wait(0.2):
                if not server.running:
                    break  # the emulator thread died: leaving the block re-raises its error
        except KeyboardInterrupt:
            pass
