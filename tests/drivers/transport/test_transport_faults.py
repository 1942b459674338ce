"""FaultyTransport: each fault happens, is seeded, and only what is asked for."""

from __future__ import annotations

import asyncio

import pytest

from drivers.testing import FaultyTransport, ScriptedTransport, ScriptMismatch
from drivers.transport import TransportClosed, open_transport
from drivers.transport.handler import EmulatorHandler
from drivers.transport.sim import register_device, unregister_device


class Echo(EmulatorHandler):
    def __init__(self) -> None:
        self.received = bytearray()

    def receive(self, data: bytes) -> bytes:
        self.received += data
        return data


@pytest.fixture
def echo_url():
    handler = Echo()
    name = f"faults-echo-{id(handler)}"
    register_device(name, handler)
    yield f"sim://{name}", handler
    unregister_device(name)


async def collect(t, n: int, timeout_s: float = 1.0) -> bytes:
    out = bytearray()
    try:
        async with asyncio.timeout(timeout_s):
            while len(out) < n:
                out += await t.read()
    except TimeoutError:
        pass
    return bytes(out)


def test_no_faults_is_transparent(run_async, echo_url) -> None:
    url, handler = echo_url

    async def main() -> None:
        t = FaultyTransport(open_transport(url))
        await t.open()
        await t.write(b"0123456789")
        assert await collect(t, 10) == b"0123456789"
        await t.close()
        assert not t.stats

    run_async(main)


def test_split_delivers_same_bytes_in_more_pieces(run_async, echo_url) -> None:
    url, handler = echo_url

    async def main() -> None:
        t = FaultyTransport(open_transport(url), split=True, seed=3)
        await t.open()
        payload = bytes(range(64))
        await t.write(payload)
        pieces = []
        async with asyncio.timeout(1):
            while sum(map(len, pieces)) < len(payload):
                pieces.append(await t.read())
        assert b"".join(pieces) == payload
        assert len(pieces) > 1
        assert t.stats["split_writes"] == 1 and t.stats["split_reads"] >= 1
        await t.close()

    run_async(main)


def test_corrupt_flips_bytes_but_keeps_length(run_async, echo_url) -> None:
    url, handler = echo_url

    async def main() -> None:
        t = FaultyTransport(open_transport(url), corrupt=0.2, seed=1, direction="tx")
        await t.open()
        payload = bytes(200)
        await t.write(payload)
        got = await collect(t, 200)
        assert len(got) == 200
        flipped = sum(1 for b in got if b)
        assert flipped == t.stats["corrupted_bytes"] > 0
        assert bytes(handler.received) == got  # corrupted on the way out, echoed intact
        await t.close()

    run_async(main)


def test_drop_loses_whole_chunks_and_is_reproducible_by_seed(run_async, echo_url) -> None:
    url, handler = echo_url

    async def run(seed: int) -> bytes:
        handler.received.clear()
        t = FaultyTransport(open_transport(url), drop=0.5, seed=seed, direction="tx")
        await t.open()
        for i in range(40):
            await t.write(bytes([i]))
        await t.close()
        return bytes(handler.received)

    async def main() -> None:
        first, again, other = await run(7), await run(7), await run(8)
        assert first == again
        assert first != other
        assert 0 < len(first) < 40

    run_async(main)


def test_rx_drop_discards_reads(run_async, echo_url) -> None:
    url, _ = echo_url

    async def main() -> None:
        t = FaultyTransport(open_transport(url), drop=1.0, direction="rx")
        await t.open()
        await t.write(b"abc")
        assert await collect(t, 3, timeout_s=0.05) == b""
        assert t.stats["dropped_reads"] >= 1
        await t.close()

    run_async(main)


def test_delay_postpones_delivery(run_async, echo_url) -> None:
    url, _ = echo_url

    async def main() -> None:
        t = FaultyTransport(open_transport(url), delay_s=0.2, direction="rx")
        await t.open()
        await t.write(b"x")
        with pytest.raises(TimeoutError):
            await asyncio.wait_for(t.read(), 0.02)
        t2 = FaultyTransport(open_transport(url), delay_s=0.05, direction="rx")
        await t2.open()
        await t2.write(b"y")
        assert await asyncio.wait_for(t2.read(), 1) == b"y"
        await t.close()
        await t2.close()

    run_async(main)


def test_disconnect_after_cuts_mid_write_and_stays_disconnected(run_async, echo_url) -> None:
    url, handler = echo_url

    async def main() -> None:
        t = FaultyTransport(open_transport(url), disconnect_after=6)
        await t.open()
        await t.write(b"ab")  # 2 out
        assert await collect(t, 2) == b"ab"  # 2 back: 4 passed
        with pytest.raises(TransportClosed, match="injected"):
            await t.write(b"cdef")  # only "cd" makes it
        assert bytes(handler.received) == b"abcd"
        with pytest.raises(TransportClosed):
            await t.read()
        with pytest.raises(TransportClosed):
            await t.send_break()
        assert t.stats["disconnects"] == 1
        await t.close()

    run_async(main)


@pytest.mark.parametrize(
    "kwargs",
    [{"drop": 1.5}, {"corrupt": -0.1}, {"delay_s": -1}, {"disconnect_after": -1}, {"direction": "up"}],
)
def test_invalid_parameters_are_rejected(kwargs) -> None:
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        FaultyTransport(ScriptedTransport([]), **kwargs)


def test_scripted_transport_checks_bytes(run_async) -> None:
    async def main() -> None:
        t = ScriptedTransport([(b"PING", b"PONG"), (b"Q", b"")])
        await t.open()
        await t.write(b"PI")
        await t.write(b"NG")
        assert await t.read() == b"PONG"
        with pytest.raises(ScriptMismatch, match="step 1"):
            await t.write(b"X")
        with pytest.raises(ScriptMismatch):
            t.assert_done()
        await t.close()

    run_async(main)
