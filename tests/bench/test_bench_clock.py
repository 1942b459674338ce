"""Session clocks: `ScaledClock` runs time_scale x the wall; `PacedClock` stands still
while the event loop is behind, so emulated devices lose no samples to a slow host."""

from __future__ import annotations

import asyncio
import math
import time

import pytest
from hypothesis import given, strategies as st

from hydrojet_bench.bench.clock import PACE_PERIOD_S, PACE_TOLERANCE_S, PacedClock, ScaledClock


class FakeWall:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_scaled_time_runs_time_scale_times_the_wall():
    wall = FakeWall()
    clock = ScaledClock(25.0, wall)
    wall.t += 2.0
    assert clock.now() == pytest.approx(50.0)
    with pytest.raises(ValueError, match="time_scale"):
        ScaledClock(0.0)


def test_paced_time_stands_still_once_the_timer_is_overdue_and_holds_that_back():
    wall, scale = FakeWall(), 10.0
    clock = PacedClock(scale, wall)
    tolerance_wall = PACE_TOLERANCE_S / scale
    wall.t += 1.0
    assert clock.now() == pytest.approx(10.0)  # no timer yet: scaled time
    clock.timer_due(wall.t + 0.001)
    wall.t += 0.001 + tolerance_wall  # on time within the tolerance: runs on
    assert clock.now() == pytest.approx(10.0 + (0.001 + tolerance_wall) * scale)
    frozen = clock.now()
    wall.t += 0.5  # the loop is behind: session time waits
    assert clock.now() == pytest.approx(frozen, abs=1e-12)
    clock.timer_ran(wall.t)
    assert clock.held_wall_s == pytest.approx(0.5)
    assert clock.now() == pytest.approx(frozen)  # and goes on from there
    wall.t += 0.002
    assert clock.now() == pytest.approx(frozen + 0.002 * scale)
    clock.timer_due(wall.t + 0.001)
    wall.t += 0.001
    clock.timer_ran(wall.t)  # on time: nothing held
    assert clock.held_wall_s == pytest.approx(0.5)


@given(st.lists(st.tuples(st.floats(0.0, 0.05), st.floats(0.0, 0.05)), min_size=1, max_size=40),
       st.floats(1.0, 100.0))
def test_paced_time_never_goes_backwards_and_holds_only_lateness(beats, scale):
    """Any timings of the pacing timer (how long until it is due, how late it runs)."""
    wall = FakeWall()
    clock = PacedClock(scale, wall)
    tolerance_wall = PACE_TOLERANCE_S / scale
    last, expected_held = clock.now(), 0.0
    for wait, late in beats:
        clock.timer_due(wall.t + wait)
        for step in (wait, late):
            for _ in range(3):
                wall.t += step / 3
                assert clock.now() >= last
                last = clock.now()
        clock.timer_ran(wall.t)
        expected_held += max(0.0, late - tolerance_wall)
        assert clock.now() >= last
        last = clock.now()
    assert clock.held_wall_s == pytest.approx(expected_held, abs=1e-9)
    assert math.isclose(clock.now(), (wall.t - 100.0 - clock.held_wall_s) * scale, rel_tol=1e-9, abs_tol=1e-9)


@pytest.mark.parametrize("paced", [False, True])
def test_a_blocked_loop_costs_session_time_only_on_a_scaled_clock(run_async, paced):
    scale, blocked_wall_s = 10.0, 0.2

    async def main():
        clock = (PacedClock if paced else ScaledClock)(scale)
        pacing = asyncio.create_task(clock.keep_pace()) if paced else None
        await clock.sleep(0.1)
        before = clock.now()
        time.sleep(blocked_wall_s)  # a callback holding the loop
        await asyncio.sleep(0)
        await asyncio.sleep(2 * PACE_PERIOD_S / scale)  # the pacing timer runs
        passed = clock.now() - before
        if pacing is not None:
            pacing.cancel()
            await asyncio.gather(pacing, return_exceptions=True)
        return passed, getattr(clock, "held_wall_s", 0.0)

    passed, held = run_async(main)
    if paced:
        # What ran unnoticed (one period and the tolerance at most) and the two turns after.
        assert passed < PACE_PERIOD_S + PACE_TOLERANCE_S + 0.05 * scale
        assert held > blocked_wall_s - 0.05
    else:
        assert passed >= blocked_wall_s * scale
        assert held == 0.0
