"""`run_session`: asyncio.run on a loop whose timers are not rounded to milliseconds."""

from __future__ import annotations

import asyncio
import contextlib
import selectors
import sys

import pytest

from hydrojet_bench.bench.event_loop import SESSION_SWITCH_INTERVAL_S, run_session


def test_a_session_runs_on_a_select_loop_and_returns_its_result() -> None:
    async def main() -> selectors.BaseSelector:
        await asyncio.sleep(0.0003)
        return asyncio.get_running_loop()._selector  # type: ignore[attr-defined]

    assert isinstance(run_session(main()), selectors.SelectSelector)


def test_an_error_in_the_session_reaches_the_caller_and_the_loop_is_closed() -> None:
    loops = []

    async def main() -> None:
        loops.append(asyncio.get_running_loop())
        raise RuntimeError("device failure")

    with pytest.raises(RuntimeError, match="device failure"):
        run_session(main())
    assert loops[0].is_closed()


@pytest.mark.parametrize("fails", [False, True], ids=["returns", "raises"])
def test_the_session_runs_with_a_short_switch_interval_and_restores_the_previous_one(fails) -> None:
    # Worker threads (estimation, calibration) wait this long for the GIL at most.
    previous = sys.getswitchinterval()
    seen = []

    async def main() -> None:
        seen.append(sys.getswitchinterval())
        if fails:
            raise RuntimeError("device failure")

    with contextlib.suppress(RuntimeError):
        run_session(main())
    assert seen[0] == pytest.approx(SESSION_SWITCH_INTERVAL_S)
    assert SESSION_SWITCH_INTERVAL_S < previous
    assert sys.getswitchinterval() == previous
