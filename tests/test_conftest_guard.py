"""The leaked-task guard must actually catch a leak."""

import asyncio

import pytest


def test_run_async_returns_result(run_async):
    async def main():
        await asyncio.sleep(0)
        return 42

    assert run_async(main) == 42


def test_run_async_fails_on_leaked_task(run_async):
    async def main():
        asyncio.get_running_loop().create_task(asyncio.sleep(10), name="forgotten-heartbeat")

    with pytest.raises(AssertionError, match="forgotten-heartbeat"):
        run_async(main)
