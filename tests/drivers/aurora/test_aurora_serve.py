"""The standalone pty server: announces its slave path, serves a client, stops cleanly."""

from __future__ import annotations

import queue
import threading

from aurora_testkit import HANDLES

from drivers.aurora import AuroraTracker, ToolStatus
from drivers.aurora.serve import serve_pty


def test_serve_pty_until_stopped(run_async, plant) -> None:
    lines: queue.Queue[str] = queue.Queue()
    stop = threading.Event()
    thread = threading.Thread(
        target=serve_pty, args=(plant,), kwargs={"tools": HANDLES, "announce": lines.put, "stop": stop},
        name="aurora-serve-test", daemon=True,
    )
    thread.start()
    try:
        line = lines.get(timeout=5)
        assert line.startswith("NDI Aurora emulator on /dev/")
        path = line.rsplit(" ", 1)[1]

        async def main() -> None:
            async with AuroraTracker(path, ["base", "tip"], command_timeout_s=0.5) as tracker:
                frame = await tracker.read_frame()
            assert frame["tip"].status is ToolStatus.VALID

        run_async(main)
    finally:
        stop.set()
        thread.join(5)
    assert not thread.is_alive()
