"""Session time: the clock every plan step, sample stamp and simulated device shares.

On the rig, session time is wall time. On the simulated rig it runs ``time_scale`` times
faster than the wall, so the paper's 19-minute protocol takes under a minute, while
everything that protects hardware or detects a dead link (the valve firmware's watchdog,
the drivers' reply timeouts, the heartbeat) stays in wall time: a host that stalls for
half a second is a stalled host, however fast the simulated rod moves.

``time_scale`` is what the simulated rig aims at, not a promise (`PacedClock`): a host
too slow for it would lose samples, as every emulated device makes its samples from
session time whether or not anyone reads them. Session time waits for the host instead,
like a simulator's real-time factor, and the session reports the scale it kept.
"""

from __future__ import annotations

import asyncio
import math
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
        await self.sleep_until(self.now() + max(0.0, seconds))

    async def sleep_until(self, t_s: float) -> None:
        # Re-check after waking: the event loop may wake a little early or late, and a
        # paced clock may have waited for the host meanwhile.
        while (remaining := t_s - self.now()) > 0:
            await asyncio.sleep(remaining / self.time_scale)


# How often the pacing timer runs, and how overdue it may be before session time waits,
# both in session seconds. A busy stretch of the event loop goes unnoticed for at most
# their sum, 25 ms: the Aurora's frame, and far under the 0.2 s an ICM-20948's FIFO holds.
# At x25 the timer runs every 0.4 ms of wall time. Measured over the paper protocol at
# x25 on the slow 2-core machine (IMUs 100 Hz, tracker 40 Hz): a tolerance of 5 ms kept
# x14.0 with both streams at 100 %; 15 ms kept x16.7-17.4 with the IMUs at 99.9-100 %
# and the tracker at 99.6-99.7 %; 30 ms kept x21.5, but the IMUs fell to 96.9 % and the
# tracker to 92.2 %.
PACE_PERIOD_S = 0.010
PACE_TOLERANCE_S = 0.015


class PacedClock(ScaledClock):
    """The simulated rig's clock: `ScaledClock`'s time, which waits for a host that falls
    behind instead of running on without it.

    `keep_pace` (a task on the session's event loop) runs a timer every `PACE_PERIOD_S`
    of session time. While that timer is more than `PACE_TOLERANCE_S` overdue, the loop
    is behind: session time stands still until the timer runs, and the wall time it
    stood still is held back for good. Every emulated device makes its samples from
    session time, so a stalled host misses none of them; it only takes longer. Session
    time never goes backwards. Without `keep_pace` running, this is a `ScaledClock`."""

    def __init__(self, time_scale: float = 1.0, wall: Callable[[], float] = time.monotonic) -> None:
        super().__init__(time_scale, wall)
        self._tolerance_wall_s = PACE_TOLERANCE_S / self.time_scale
        # (wall time the pacing timer is due, wall seconds held back so far): one tuple,
        # so a reader on another thread never sees one updated without the other.
        self._pace: tuple[float, float] = (math.inf, 0.0)
        self._latest_s = -math.inf

    @property
    def held_wall_s(self) -> float:
        """Wall seconds session time has waited for the host so far."""
        return self._pace[1]

    def now(self) -> float:
        due_wall_s, held_wall_s = self._pace
        wall = min(self._wall(), due_wall_s + self._tolerance_wall_s)
        # Where time stood still and where it goes on after the hold are the same
        # instant by two sums: rounding may put the second a hair before the first.
        self._latest_s = max(self._latest_s, (wall - self._start - held_wall_s) * self.time_scale)
        return self._latest_s

    async def keep_pace(self) -> None:
        """Hold session time back whenever the event loop falls behind; runs until
        cancelled (then session time runs freely again)."""
        period_wall_s = PACE_PERIOD_S / self.time_scale
        try:
            while True:
                self.timer_due(self._wall() + period_wall_s)
                await asyncio.sleep(period_wall_s)
                self.timer_ran(self._wall())
        finally:
            self._pace = (math.inf, self._pace[1])

    def timer_due(self, due_wall_s: float) -> None:
        """The pacing timer is set for wall time ``due_wall_s``."""
        self._pace = (due_wall_s, self._pace[1])

    def timer_ran(self, wall_s: float) -> None:
        """The pacing timer ran at wall time ``wall_s``: what it was late past the
        tolerance, session time stood still, and that is held back from now on."""
        due_wall_s, held_wall_s = self._pace
        late_wall_s = wall_s - due_wall_s - self._tolerance_wall_s
        if late_wall_s > 0.0:
            self._pace = (math.inf, held_wall_s + late_wall_s)
