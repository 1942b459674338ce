"""`run_session`: asyncio.run on a loop whose timers are not rounded to milliseconds."""

from __future__ import annotations

import asyncio
import selectors

import pytest

from hydrojet_bench.bench.event_loop import run_session


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
