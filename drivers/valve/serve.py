"""Run the valve emulator standalone on a pty, for clients in other processes.

``serve()`` prints the pty slave path (give it to a client as ``pty://PATH`` or the bare
path), serves until Ctrl-C (KeyboardInterrupt) or ``stop`` is set, then closes all
valves (reported to the plant) and the pty.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from drivers.plant import Plant, StaticPlant
from drivers.transport.pty import PtyServer
from drivers.valve.emulator import ValveEmulator
from drivers.valve.protocol import DEFAULT_WATCHDOG_MS


def serve(
    plant: Plant | None = None,
    watchdog_s: float = DEFAULT_WATCHDOG_MS / 1000,
    *,
    poll_interval_s: float = 0.005,
    stop: threading.Event | None = None,
    announce: Callable[[str], None] = lambda line: print(line, flush=True),
) -> ValveEmulator:
    """Serve a `ValveEmulator` on a fresh pty until Ctrl-C or ``stop`` is set.

    plant: truth sink for valve duties (a `StaticPlant` if None). watchdog_s: firmware
    watchdog period (s). poll_interval_s: how often the watchdog is checked (s), which
    bounds how late a trip can be. announce: receives the line naming the pty path.
    Returns the emulator (valves closed) for inspection.
    """
    plant = plant if plant is not None else StaticPlant()
    emulator = ValveEmulator(plant, watchdog_s=watchdog_s)
    stop = stop if stop is not None else threading.Event()
    server = PtyServer(emulator, poll_interval_s=poll_interval_s, name="valve-emulator").start()
    try:
        announce(server.path)
        # Event.wait with a timeout, in a loop, stays responsive to Ctrl-C on the main thread.
        while not stop.wait(0.2):
            if not server.running:
                break  # the emulator died; stop() below re-raises why
    except KeyboardInterrupt:
        pass
    finally:
        try:
            server.stop()
        finally:
            emulator.shutdown()
    return emulator
