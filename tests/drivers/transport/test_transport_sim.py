"""In-process sim links: request/reply, polling, unregistering, hooks, errors."""

from __future__ import annotations

import asyncio

import pytest

from drivers.transport import TransportClosed, TransportError, open_transport
from drivers.transport.handler import EmulatorHandler
from drivers.transport.sim import poll_device, register_device, registered_devices, serve_sim, unregister_device


class Recorder(EmulatorHandler):
    """Upper-cases input; counts polls and emits one tick byte per poll if asked."""

    def __init__(self, tick: bytes = b"") -> None:
        self.received = bytearray()
        self.polls = 0
        self.tick = tick
        self.breaks = 0
        self.bauds: list[int] = []

    def receive(self, data: bytes) -> bytes:
        self.received += data
        return data.upper()

    def poll(self) -> bytes:
        self.polls += 1
        return self.tick

    def on_break(self) -> bytes:
        self.breaks += 1
        return b"RESET"

    def on_baudrate(self, baud: int) -> None:
        self.bauds.append(baud)


def test_request_reply_and_hooks(run_async) -> None:
    dev = Recorder()

    async def main() -> None:
        async with serve_sim("t-sim-1", dev) as url:
            t = open_transport(url)
            await t.open()
            await t.write(b"abc")
            assert await asyncio.wait_for(t.read(), 1) == b"ABC"
            await t.write(b"defgh")
            assert await asyncio.wait_for(t.read(2), 1) == b"DE"
            assert await asyncio.wait_for(t.read(), 1) == b"FGH"
            await t.send_break(0.0)
            assert await asyncio.wait_for(t.read(), 1) == b"RESET"
            await t.set_baudrate(9600)
            await t.close()
            await t.close()  # idempotent
            with pytest.raises(TransportClosed):
                await t.read()
            with pytest.raises(TransportClosed):
                await t.write(b"x")
        assert dev.received == b"abcdefgh"
        assert dev.breaks == 1 and dev.bauds == [9600]
        assert "t-sim-1" not in registered_devices()

    run_async(main)


def test_serve_sim_polls_even_without_clients(run_async) -> None:
    dev = Recorder(tick=b".")

    async def main() -> None:
        async with serve_sim("t-sim-2", dev, poll_interval_s=0.005):
            await asyncio.sleep(0.05)
            assert dev.polls >= 3
            t = open_transport("sim://t-sim-2")
            await t.open()
            data = await asyncio.wait_for(t.read(), 1)
            assert data and set(data) == {ord(".")}
            await t.close()

    run_async(main)


def test_unknown_device_and_duplicate_name(run_async) -> None:
    async def main() -> None:
        t = open_transport("sim://nobody-here")
        with pytest.raises(TransportError, match="nobody-here"):
            await t.open()
        register_device("t-sim-3", Recorder())
        try:
            with pytest.raises(ValueError, match="already registered"):
                register_device("t-sim-3", Recorder())
        finally:
            unregister_device("t-sim-3")

    run_async(main)


def test_unregister_wakes_a_blocked_reader_with_transport_closed(run_async) -> None:
    async def main() -> None:
        register_device("t-sim-4", Recorder())
        t = open_transport("sim://t-sim-4")
        await t.open()
        reader = asyncio.create_task(t.read())
        await asyncio.sleep(0.01)
        assert not reader.done()
        unregister_device("t-sim-4")
        with pytest.raises(TransportClosed, match="unregistered"):
            await asyncio.wait_for(reader, 1)

    run_async(main)


def test_poll_output_goes_to_every_open_link(run_async) -> None:
    async def main() -> None:
        register_device("t-sim-5", Recorder(tick=b"!"))
        try:
            a, b = open_transport("sim://t-sim-5"), open_transport("sim://t-sim-5")
            await a.open()
            await b.open()
            poll_device("t-sim-5")
            assert await asyncio.wait_for(a.read(), 1) == b"!"
            assert await asyncio.wait_for(b.read(), 1) == b"!"
            await a.close()
            await b.close()
        finally:
            unregister_device("t-sim-5")

    run_async(main)


def test_register_refuses_a_handler_that_is_not_an_emulator_handler() -> None:
    class DuckTyped:
        def receive(self, data: bytes) -> bytes:
            return data

    with pytest.raises(TypeError, match="EmulatorHandler"):
        register_device("t-sim-6", DuckTyped())  # type: ignore[arg-type]
    assert "t-sim-6" not in registered_devices()
