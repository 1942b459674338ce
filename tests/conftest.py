"""Suite-wide test configuration.

* `--rig PROFILE` enables tests marked `rig` (real hardware); they are skipped otherwise.
* `run_async` runs a coroutine on a fresh event loop and fails the test if it leaves any
  task running: a leaked task on the bench is a heartbeat or reader nobody will stop.
* SIGINT is handled even when the suite was started with it ignored (see
  `pytest_configure`).
* Hypothesis runs without its per-example deadline: the suite shares a busy 2-core
  machine, where a 10 ms example took 270 ms once and failed as "flaky"; speed is
  measured by `hydrojet-bench perf`, never by a test's timing.
"""

from __future__ import annotations

import asyncio
import signal
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

import pytest
from hypothesis import settings

T = TypeVar("T")

settings.register_profile("shared-machine", deadline=None)
settings.load_profile("shared-machine")


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--rig",
        action="store",
        default=None,
        metavar="PROFILE",
        help="run the opt-in hardware tests against the rig described by PROFILE (TOML)",
    )


def pytest_configure(config: pytest.Config) -> None:
    # A shell starts its background jobs with SIGINT ignored, and their children inherit
    # that: the tests that stop a bench or an emulator subprocess with Ctrl-C's signal
    # would wait for a process that never hears it. A handler here is reset to the
    # default in every child.
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--rig"):
        return
    skip = pytest.mark.skip(reason="hardware test: pass --rig PROFILE to run it")
    for item in items:
        if item.get_closest_marker("rig") is not None:
            item.add_marker(skip)


@pytest.fixture
def rig_profile(request: pytest.FixtureRequest) -> str:
    return request.config.getoption("--rig")


def _run_checked(main: Callable[[], Awaitable[T]], timeout_s: float) -> T:
    async def wrapper() -> T:
        result = await asyncio.wait_for(main(), timeout_s)
        # Give cancelled tasks one turn to finish their cleanup before we look.
        await asyncio.sleep(0)
        current = asyncio.current_task()
        leaked = [t for t in asyncio.all_tasks() if t is not current and not t.done()]
        if leaked:
            for task in leaked:
                task.cancel()
            await asyncio.gather(*leaked, return_exceptions=True)
            names = ", ".join(sorted(t.get_name() for t in leaked))
            raise AssertionError(f"test leaked {len(leaked)} running task(s): {names}")
        return result

    return asyncio.run(wrapper())


@pytest.fixture
def run_async() -> Callable[..., Any]:
    """`run_async(coroutine_function, timeout_s=10.0)`: run it and check for leaked tasks."""

    def runner(main: Callable[[], Awaitable[T]], timeout_s: float = 10.0) -> T:
        return _run_checked(main, timeout_s)

    return runner
