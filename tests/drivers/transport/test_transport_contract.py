"""The `Transport` contract, checked on every transport (as python-can runs one test base
on several buses): round trip, partial reads, read timeouts, close, use after close.

Each backend is an echo: what the test writes comes back. The scripted mock echoes by
script, so each test declares up front the byte strings it will write.

pyserial's ``loop://`` is not among them: `SerialTransport` drives the port's file
descriptor from the event loop, and pyserial's URL handlers have none; the serial code
path is covered by a pty slave opened as a serial port.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
from collections.abc import AsyncIterator, Callable, Sequence
from typing import AsyncContextManager

import pytest

from drivers.testing import FaultyTransport, ScriptedTransport
from drivers.transport import Transport, TransportClosed, open_transport
from drivers.transport.handler import EmulatorHandler
from drivers.transport.pty import PtyServer
from drivers.transport.sim import serve_sim

LinkFactory = Callable[[Sequence[bytes]], AsyncContextManager[Transport]]
_sim_names = itertools.count()


class Echo(EmulatorHandler):
    def receive(self, data: bytes) -> bytes:
        return data


@contextlib.asynccontextmanager
async def _opened(transport: Transport) -> AsyncIterator[Transport]:
    await transport.open()
    try:
        yield transport
    finally:
        await transport.close()


@contextlib.asynccontextmanager
async def sim_link(writes: Sequence[bytes]) -> AsyncIterator[Transport]:
    async with serve_sim(f"contract-{next(_sim_names)}", Echo()) as url:
        async with _opened(open_transport(url)) as transport:
            yield transport


@contextlib.asynccontextmanager
async def pty_link(writes: Sequence[bytes]) -> AsyncIterator[Transport]:
    with PtyServer(Echo()) as server:
        async with _opened(open_transport(f"pty://{server.path}")) as transport:
            yield transport


@contextlib.asynccontextmanager
async def mock_link(writes: Sequence[bytes]) -> AsyncIterator[Transport]:
    transport = ScriptedTransport([(w, w) for w in writes])
    async with _opened(transport):
        yield transport
    transport.assert_done()


@contextlib.asynccontextmanager
async def faulty_sim_link(writes: Sequence[bytes]) -> AsyncIterator[Transport]:
    """FaultyTransport with no faults configured must be a transparent transport."""
    async with serve_sim(f"contract-{next(_sim_names)}", Echo()) as url:
        async with _opened(FaultyTransport(open_transport(url))) as transport:
            yield transport


@pytest.fixture(params=[sim_link, pty_link, mock_link, faulty_sim_link], ids=["sim", "pty", "mock", "faulty-sim"])
def link(request: pytest.FixtureRequest) -> LinkFactory:
    return request.param


async def read_exactly(transport: Transport, n: int, max_bytes: int = 4096) -> bytes:
    out = bytearray()
    async with asyncio.timeout(2.0):
        while len(out) < n:
            chunk = await transport.read(max_bytes)
            assert 1 <= len(chunk) <= max_bytes
            out += chunk
    return bytes(out)


def test_round_trip(link: LinkFactory, run_async) -> None:
    payload = bytes(range(256))

    async def main() -> None:
        async with link([payload]) as transport:
            await transport.write(payload)
            assert await read_exactly(transport, len(payload)) == payload

    run_async(main)


def test_read_returns_what_is_there_without_waiting_for_max_bytes(link: LinkFactory, run_async) -> None:
    async def main() -> None:
        async with link([b"abc"]) as transport:
            await transport.write(b"abc")
            first = await asyncio.wait_for(transport.read(4096), 1.0)
            assert 1 <= len(first) <= 3 and b"abc".startswith(first)
            assert first + await read_exactly(transport, 3 - len(first)) == b"abc"

    run_async(main)


def test_read_never_returns_more_than_max_bytes(link: LinkFactory, run_async) -> None:
    payload = b"0123456789"

    async def main() -> None:
        async with link([payload]) as transport:
            await transport.write(payload)
            assert await read_exactly(transport, len(payload), max_bytes=3) == payload

    run_async(main)


def test_read_rejects_max_bytes_below_one(link: LinkFactory, run_async) -> None:
    async def main() -> None:
        async with link([]) as transport:
            with pytest.raises(ValueError, match="max_bytes"):
                await transport.read(0)

    run_async(main)


def test_read_waits_for_data_and_a_timed_out_read_leaves_the_link_usable(link: LinkFactory, run_async) -> None:
    """A transport never times out by itself; the caller's timeout cancels the read
    without losing or corrupting later bytes."""

    async def main() -> None:
        async with link([b"late"]) as transport:
            with pytest.raises(TimeoutError):
                await asyncio.wait_for(transport.read(), 0.05)
            await transport.write(b"late")
            assert await read_exactly(transport, 4) == b"late"

    run_async(main)


def test_close_wakes_a_blocked_reader_with_transport_closed(link: LinkFactory, run_async) -> None:
    async def main() -> None:
        async with link([]) as transport:
            reader = asyncio.create_task(transport.read())
            await asyncio.sleep(0.02)
            assert not reader.done()
            await transport.close()
            with pytest.raises(TransportClosed):
                await asyncio.wait_for(reader, 1.0)

    run_async(main)


def test_use_after_close_raises_transport_closed_and_close_is_idempotent(link: LinkFactory, run_async) -> None:
    async def main() -> None:
        async with link([]) as transport:
            await transport.close()
            await transport.close()
            with pytest.raises(TransportClosed):
                await transport.write(b"x")
            with pytest.raises(TransportClosed):
                await transport.read()

    run_async(main)

