"""A scripted transport for client unit tests (the MOCK, not the simulation).

Like PyMeasure's ``expected_protocol``: give the exact bytes the client must write and
the bytes the "device" answers; a write that departs from the script fails at once with
`ScriptMismatch` (an AssertionError, so pytest shows it as a test failure), and
`assert_done` checks that the whole script was used.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterable

from drivers.transport.buffered import BufferedTransport


class ScriptMismatch(AssertionError):
    """The client wrote bytes the script did not expect."""


class ScriptedTransport(BufferedTransport):
    """script: (expected bytes written by the client, reply bytes) pairs, in order.

    The client may write an expected message in any number of pieces; the reply is
    released once the whole expected message has been written.
    """

    def __init__(self, script: Iterable[tuple[bytes, bytes]], url: str = "mock://scripted") -> None:
        super().__init__(url)
        self._script = [(bytes(w), bytes(r)) for w, r in script]
        self._step = 0
        self._written = bytearray()
        self.written_log: list[bytes] = []

    async def open(self) -> None:
        self._start_buffering()

    async def close(self) -> None:
        self._stop_buffering()

    async def write(self, data: bytes) -> None:
        self._raise_if_ended()
        self.written_log.append(bytes(data))
        self._written += data
        while self._written:
            if self._step >= len(self._script):
                raise ScriptMismatch(
                    f"script exhausted after {self._step} steps; client also wrote "
                    f"{bytes(self._written).hex(' ')}"
                )
            expected, reply = self._script[self._step]
            got = bytes(self._written[: len(expected)])
            if got != expected[: len(got)]:
                raise ScriptMismatch(
                    f"step {self._step}: expected {expected.hex(' ')}, got {got.hex(' ')}"
                )
            if len(got) < len(expected):
                break  # the rest of this message is still to come
            del self._written[: len(expected)]
            self._step += 1
            if reply:
                self._deliver(reply)
        await asyncio.sleep(0)

    async def set_baudrate(self, baud: int) -> None:
        self._raise_if_ended()

    async def send_break(self, duration_s: float = 0.25) -> None:
        self._raise_if_ended()

    @property
    def steps_done(self) -> int:
        return self._step

    def assert_done(self) -> None:
        """Fail unless every scripted exchange happened and nothing extra was written."""
        if self._step != len(self._script) or self._written:
            raise ScriptMismatch(
                f"script used {self._step}/{len(self._script)} steps; "
                f"unmatched written bytes: {bytes(self._written).hex(' ')}"
            )
