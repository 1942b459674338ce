"""Session time: the clock every plan step, sample stamp and simulated device shares.

On the rig, session time is wall time. On the simulated rig it runs ``time_scale`` times
faster than the wall, so the paper's 19-minute protocol takes under a minute, while
everything that protects hardware or detects a dead link (the valve firmware's watchdog,
the drivers' reply timeouts, the heartbeat) stays in wall time: a host that stalls for
half a second is a stalled host, however fast the simulated rod moves.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from typing import Protocol, runtime_checkable


@runtime_checkable
class Clock(Protocol):
    """Session seconds since the clock started; ``time_scale`` session seconds pass per
    wall second (waits in wall time, such as a driver's, divide by it)."""

    time_scale: float

    def now(self) -> float: ...

    async def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` of session time."""
        ...

    async def sleep_until(self, t_s: float) -> None:
        """Wait until session time ``t_s`` (returns at once if it has passed)."""
        ...


class ScaledClock:
    """Session time = ``time_scale`` x wall seconds since construction (1: real time)."""

    def __init__(self, time_scale: float = 1.0, wall: Callable[[], float] = time.monotonic) -> None:
        if not time_scale > 0:
            raise ValueError(f"time_scale must be > 0, got {time_scale!r}")
        self.time_scale = float(time_scale)
        self._wall = wall
        self._start = self._wall()

    def now(self) -> float:
        return (self._wall() - self._start) * self.time_scale

    def wall_seconds(self, session_seconds: float) -> float:
        return session_seconds / self.time_scale

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(max(0.0, seconds) / self.time_scale)

    async def sleep_until(self, t_s: float) -> None:
        # Re-check after waking: the event loop may wake a little early or late.
        while (remaining := t_s - self.now()) > 0:
            await asyncio.sleep(remaining / self.time_scale)
