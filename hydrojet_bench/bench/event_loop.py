"""The event loop a session runs on.

asyncio's default loop on Linux waits in epoll, which counts its timeout in whole
milliseconds and rounds up: a wait of 0.3 ms lasts 1 ms. On the real rig that is noise.
On the simulated rig at 25x, one Aurora frame lasts 1 ms of wall time, so a poll aimed at
the start of a frame would land anywhere in it, or in the next one: measured over the
paper protocol on the 2-core machine, 84 % of the tracker's frames were read with epoll
against 95 % with select(2), which waits to the microsecond. A session watches a handful
of descriptors (a pty or serial port per device), so select's limits (descriptor numbers
below 1024, a scan per wait) cost nothing here.

A session also shortens the interpreter's switch interval (`SESSION_SWITCH_INTERVAL_S`).
Its estimation and calibration run in worker threads so the loop never waits for a
solve, and they call thousands of short compiled kernels that release the GIL. Each
time such a thread wants the GIL back while the loop holds it, it waits for the switch
interval, 5 ms by default. Measured on the slow 2-core machine over the paper protocol at
x25: the 40-pose calibration took 8.5-16.5 s in its thread against 0.53 s alone, and the
plan, which waits for it, ran 1681 s of session time for its 1153 (67 s of wall time).
At 0.5 ms the calibration took 1.7 s and the session 1250-1313 s (50-53 s of wall time),
with the same stream rates.
"""

from __future__ import annotations

import asyncio
import selectors
import sys
from collections.abc import Coroutine
from typing import Any, TypeVar

T = TypeVar("T")

# The longest a worker thread waits for the GIL while the loop runs (s); see above.
SESSION_SWITCH_INTERVAL_S = 0.0005


def _loop_with_fine_timers() -> asyncio.AbstractEventLoop:
    return asyncio.SelectorEventLoop(selectors.SelectSelector())


def run_session(main: Coroutine[Any, Any, T]) -> T:
    """`asyncio.run` for a session: the same cancellation on Ctrl-C and clean-up, on a
    loop whose timers keep to a fraction of a millisecond, with the short switch
    interval (restored on the way out)."""
    previous = sys.getswitchinterval()
    sys.setswitchinterval(min(previous, SESSION_SWITCH_INTERVAL_S))
    try:
        with asyncio.Runner(loop_factory=_loop_with_fine_timers) as runner:
            return runner.run(main)
    finally:
        sys.setswitchinterval(previous)
