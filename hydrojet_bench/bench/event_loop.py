"""The event loop a session runs on.

asyncio's default loop on Linux waits in epoll, which counts its timeout in whole
milliseconds and rounds up: a wait of 0.3 ms lasts 1 ms. On the real rig that is noise.
On the simulated rig at 25x, one Aurora frame lasts 1 ms of wall time, so a poll aimed at
the start of a frame would land anywhere in it, or in the next one: measured over the
paper protocol on the 2-core machine, 84 % of the tracker's frames were read with epoll
against 95 % with select(2), which waits to the microsecond. A session watches a handful
of descriptors (a pty or serial port per device), so select's limits (descriptor numbers
below 1024, a scan per wait) cost nothing here.
"""

from __future__ import annotations

import asyncio
import selectors
from collections.abc import Coroutine
from typing import Any, TypeVar

T = TypeVar("T")


def _loop_with_fine_timers() -> asyncio.AbstractEventLoop:
    return asyncio.SelectorEventLoop(selectors.SelectSelector())


def run_session(main: Coroutine[Any, Any, T]) -> T:
    """`asyncio.run` for a session: the same cancellation on Ctrl-C and clean-up, on a
    loop whose timers keep to a fraction of a millisecond."""
    with asyncio.Runner(loop_factory=_loop_with_fine_timers) as runner:
        return runner.run(main)
