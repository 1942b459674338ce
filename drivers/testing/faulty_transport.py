"""Fault injection around any `Transport`, for testing clients against a bad line.

`FaultyTransport` wraps a transport and, driven by a seeded RNG so a failing test
replays exactly:

* drop:      probability that a whole write() or read() chunk vanishes;
* corrupt:   per-byte probability of flipping 1-8 random bits;
* delay_s:   extra latency (s) added before each write is forwarded and each read is
             returned;
* split:     writes go out in random pieces and reads return random-length prefixes
             (frames arrive in fragments, as from a USB-serial adapter);
* disconnect_after: after this many bytes have passed (both directions together) the
             link breaks: the inner transport is closed and every call raises
             TransportClosed, as if the cable were pulled;
* direction: "tx" (host -> device), "rx" (device -> host) or "both": where drop,
             corrupt, delay and split apply.

``stats`` counts what was injected, so a test can check that faults really happened.
"""

from __future__ import annotations

import asyncio
import random
from collections import Counter

from drivers.transport.base import Transport, TransportClosed


class FaultyTransport:
    def __init__(
        self,
        inner: Transport,
        drop: float = 0.0,
        corrupt: float = 0.0,
        delay_s: float = 0.0,
        split: bool = False,
        disconnect_after: int | None = None,
        seed: int = 0,
        direction: str = "both",
    ) -> None:
        for name, p in (("drop", drop), ("corrupt", corrupt)):
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"{name} must be a probability in [0, 1], got {p}")
        if delay_s < 0:
            raise ValueError(f"delay_s must be >= 0, got {delay_s}")
        if disconnect_after is not None and disconnect_after < 0:
            raise ValueError(f"disconnect_after must be >= 0 bytes, got {disconnect_after}")
        if direction not in ("tx", "rx", "both"):
            raise ValueError(f"direction must be 'tx', 'rx' or 'both', got {direction!r}")
        self.inner = inner
        self.url = inner.url
        self.drop = drop
        self.corrupt = corrupt
        self.delay_s = delay_s
        self.split = split
        self.disconnect_after = disconnect_after
        self.direction = direction
        self._rng = random.Random(seed)
        self._pending = bytearray()  # rx bytes held back by split
        self._bytes_passed = 0
        self._disconnected = False
        self.stats: Counter[str] = Counter()

    def _applies(self, way: str) -> bool:
        return self.direction in ("both", way)

    def _take_budget(self, n: int) -> int:
        """How many of n bytes may pass before the injected disconnect (all if none)."""
        if self.disconnect_after is None:
            self._bytes_passed += n
            return n
        allowed = max(0, min(n, self.disconnect_after - self._bytes_passed))
        self._bytes_passed += allowed
        return allowed

    def _budget_spent(self) -> bool:
        return self.disconnect_after is not None and self._bytes_passed >= self.disconnect_after

    async def _pull_plug(self) -> None:
        if not self._disconnected:
            self._disconnected = True
            self.stats["disconnects"] += 1
            await self.inner.close()

    def _mangle(self, data: bytes) -> bytes:
        if self.corrupt <= 0.0:
            return data
        out = bytearray(data)
        for i in range(len(out)):
            if self._rng.random() < self.corrupt:
                out[i] ^= self._rng.randrange(1, 256)
                self.stats["corrupted_bytes"] += 1
        return bytes(out)

    async def open(self) -> None:
        await self.inner.open()

    async def close(self) -> None:
        self._pending.clear()
        await self.inner.close()

    async def write(self, data: bytes) -> None:
        if self._disconnected:
            raise TransportClosed(f"{self.url}: injected disconnect")
        data = bytes(data)
        allowed = self._take_budget(len(data))
        if allowed < len(data):
            if allowed:
                await self.inner.write(data[:allowed])  # the cable goes mid-frame
            await self._pull_plug()
            raise TransportClosed(f"{self.url}: injected disconnect")
        await self._write_faulty(data)
        if self._budget_spent():
            await self._pull_plug()  # the next call finds the cable gone

    async def _write_faulty(self, data: bytes) -> None:
        if not self._applies("tx"):
            await self.inner.write(data)
            return
        if self.delay_s:
            await asyncio.sleep(self.delay_s)
        if self.drop and self._rng.random() < self.drop:
            self.stats["dropped_writes"] += 1
            return
        data = self._mangle(data)
        if self.split and len(data) > 1:
            self.stats["split_writes"] += 1
            for piece in self._cut(data):
                await self.inner.write(piece)
                await asyncio.sleep(0)
        else:
            await self.inner.write(data)

    def _cut(self, data: bytes) -> list[bytes]:
        k = min(len(data) - 1, self._rng.randint(1, 3))
        cuts = sorted(self._rng.sample(range(1, len(data)), k))
        bounds = [0, *cuts, len(data)]
        return [data[a:b] for a, b in zip(bounds, bounds[1:])]

    async def read(self, max_bytes: int = 4096) -> bytes:
        if max_bytes < 1:
            raise ValueError(f"max_bytes must be >= 1, got {max_bytes}")
        while True:
            if self._pending:
                n = self._rng.randint(1, min(max_bytes, len(self._pending)))
                chunk = bytes(self._pending[:n])
                del self._pending[:n]
                return chunk
            if self._disconnected:
                raise TransportClosed(f"{self.url}: injected disconnect")
            data = await self.inner.read(max_bytes)
            allowed = self._take_budget(len(data))
            if allowed < len(data) or self._budget_spent():
                data = data[:allowed]
                await self._pull_plug()
                if not data:
                    raise TransportClosed(f"{self.url}: injected disconnect")
            if not self._applies("rx"):
                return data
            if self.delay_s:
                await asyncio.sleep(self.delay_s)
            if self.drop and self._rng.random() < self.drop:
                self.stats["dropped_reads"] += 1
                continue
            data = self._mangle(data)
            if self.split and len(data) > 1:
                self.stats["split_reads"] += 1
                self._pending += data
                continue
            return data

    async def set_baudrate(self, baud: int) -> None:
        if self._disconnected:
            raise TransportClosed(f"{self.url}: injected disconnect")
        await self.inner.set_baudrate(baud)

    async def send_break(self, duration_s: float = 0.25) -> None:
        if self._disconnected:
            raise TransportClosed(f"{self.url}: injected disconnect")
        await self.inner.send_break(duration_s)

    def __repr__(self) -> str:
        return f"FaultyTransport({self.inner!r})"
