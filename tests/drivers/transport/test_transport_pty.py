"""Emulators on a pty, reached through SerialTransport exactly as a real port."""

from __future__ import annotations

import asyncio
import os
import threading
import time

import pytest

from drivers.transport import TransportClosed, TransportError, open_transport
from drivers.transport.handler import EmulatorHandler
from drivers.transport.pty import PtyPair, PtyServer


class Echo(EmulatorHandler):
    def __init__(self) -> None:
        self.received = bytearray()
        self.polls = 0
        self.lock = threading.Lock()

    def receive(self, data: bytes) -> bytes:
        with self.lock:
            self.received += data
        return data

    def poll(self) -> bytes:
        self.polls += 1
        return b""


async def read_exactly(t, n: int, timeout_s: float = 2.0) -> bytes:
    out = bytearray()
    async with asyncio.timeout(timeout_s):
        while len(out) < n:
            out += await t.read(n - len(out))
    return bytes(out)


def test_every_byte_value_passes_unchanged(run_async) -> None:
    """Raw mode: no echo, no CR/LF translation, no ^C/^D/^S handling on either side."""
    payload = bytes(range(256)) * 4
    handler = Echo()

    async def main() -> None:
        with PtyServer(handler) as server:
            t = open_transport(server.path)
            await t.open()
            await t.write(payload)
            assert await read_exactly(t, len(payload)) == payload
            await t.close()

    run_async(main)
    assert bytes(handler.received) == payload


def test_large_write_applies_back_pressure_without_loss(run_async) -> None:
    payload = os.urandom(200_000)  # far beyond the pty's kernel buffer

    async def main() -> None:
        with PtyServer(Echo()) as server:
            t = open_transport(server.path)
            await t.open()
            writer = asyncio.create_task(t.write(payload))
            got = await read_exactly(t, len(payload), timeout_s=8.0)
            await writer
            assert got == payload
            await t.close()

    run_async(main, timeout_s=15)


def test_client_can_close_and_reopen_and_server_keeps_serving(run_async) -> None:
    handler = Echo()

    async def main() -> None:
        with PtyServer(handler) as server:
            for i in range(5):
                t = open_transport(f"pty://{server.path}?baud=9600")
                await t.open()
                await t.set_baudrate(115200)
                await t.send_break(0.0)
                msg = f"round {i}".encode()
                await t.write(msg)
                assert await read_exactly(t, len(msg)) == msg
                await t.close()
                await t.close()  # idempotent
            assert server.running

    run_async(main)


def test_stale_replies_are_flushed_when_a_client_opens(run_async) -> None:
    async def main() -> None:
        with PtyServer(Echo()) as server:
            t = open_transport(server.path)
            await t.open()
            await t.write(b"old")
            await asyncio.sleep(0.05)  # the echo sits unread in the slave's queue
            await t.close()
            t = open_transport(server.path)
            await t.open()
            await t.write(b"new")
            assert await read_exactly(t, 3) == b"new"
            await t.close()

    run_async(main)


def test_poll_runs_while_host_is_silent() -> None:
    handler = Echo()
    with PtyServer(handler, poll_interval_s=0.005):
        deadline = time.monotonic() + 2.0
        while handler.polls < 5 and time.monotonic() < deadline:
            time.sleep(0.005)
    assert handler.polls >= 5


def test_server_stop_gives_the_client_transport_closed(run_async) -> None:
    async def main() -> None:
        server = PtyServer(Echo()).start()
        t = open_transport(server.path)
        await t.open()
        reader = asyncio.create_task(t.read())
        await asyncio.sleep(0.02)
        server.stop()
        with pytest.raises(TransportClosed):
            await asyncio.wait_for(reader, 2)
        await t.close()

    run_async(main)


def test_close_wakes_a_blocked_reader(run_async) -> None:
    async def main() -> None:
        with PtyServer(Echo()) as server:
            t = open_transport(server.path)
            await t.open()
            reader = asyncio.create_task(t.read())
            await asyncio.sleep(0.01)
            await t.close()
            with pytest.raises(TransportClosed):
                await asyncio.wait_for(reader, 1)

    run_async(main)


def test_handler_exception_is_reraised_by_stop(run_async) -> None:
    class Broken(EmulatorHandler):
        def receive(self, data: bytes) -> bytes:
            raise RuntimeError("emulator bug")

    async def main() -> None:
        server = PtyServer(Broken()).start()
        t = open_transport(server.path)
        await t.open()
        await t.write(b"x")
        deadline = time.monotonic() + 2
        while server.running and time.monotonic() < deadline:
            await asyncio.sleep(0.01)
        await t.close()
        with pytest.raises(RuntimeError, match="emulator bug"):
            server.stop()

    run_async(main)


def test_opening_a_missing_port_is_a_transport_error(run_async) -> None:
    async def main() -> None:
        t = open_transport("serial:///dev/does-not-exist-hydrojet")
        with pytest.raises(TransportError, match="does-not-exist-hydrojet"):
            await t.open()
        with pytest.raises(TransportClosed):
            await t.write(b"x")
        await t.close()

    run_async(main)


def test_pty_pair_survives_no_client() -> None:
    """With our slave fd held, the master neither errors nor blocks with no client."""
    pair = PtyPair()
    try:
        assert pair.read_master() == b""
        assert pair.write_master(b"hello") == 5
        assert pair.path.startswith("/dev/")
    finally:
        pair.close()
        pair.close()


def test_server_refuses_a_handler_that_is_not_an_emulator_handler() -> None:
    class DuckTyped:
        def receive(self, data: bytes) -> bytes:
            return data

    with pytest.raises(TypeError, match="EmulatorHandler"):
        PtyServer(DuckTyped())  # type: ignore[arg-type]
