"""The read side shared by every transport whose bytes arrive by callback.

Sim links, serial ports (and ptys) and the scripted mock all receive bytes at moments of
their own (a handler's reply, the event loop's reader callback, a scripted step) and
hand them out through `read`; `BufferedTransport` holds that buffer and the one read
loop, so "close wakes a blocked reader" and "read returns what is there" hold for all.
"""

from __future__ import annotations

import asyncio

from drivers.transport.base import TransportClosed

_CLOSED = "transport is closed"


class BufferedTransport:
    """Base class: subclasses call `_start_buffering` when they open, `_deliver` as bytes
    arrive, `_peer_gone` when no more will come and `_stop_buffering` when they close.

    A new instance counts as closed until `_start_buffering`.
    """

    def __init__(self, url: str) -> None:
        self.url = url
        self._buffer = bytearray()
        self._readable: asyncio.Event | None = None
        self._ended_because: str | None = _CLOSED

    def _start_buffering(self) -> None:
        # A fresh Event per open: an Event binds to the loop that first waits on it.
        self._readable = asyncio.Event()
        self._buffer.clear()
        self._ended_because = None

    def _deliver(self, data: bytes) -> None:
        self._buffer += data
        if self._readable is not None:
            self._readable.set()

    def _peer_gone(self, reason: str) -> None:
        """No more bytes will come (EOF, device unregistered); those already buffered can
        still be read, after which `read` raises TransportClosed naming ``reason``."""
        if self._ended_because is None:
            self._ended_because = reason
        if self._readable is not None:
            self._readable.set()

    def _stop_buffering(self) -> None:
        """Closed by the host: drop unread bytes and wake a blocked reader."""
        self._buffer.clear()
        self._ended_because = _CLOSED
        if self._readable is not None:
            self._readable.set()

    def _raise_if_ended(self) -> None:
        if self._ended_because is not None:
            raise TransportClosed(f"{self.url}: {self._ended_because}")

    def _bytes_taken(self) -> None:
        """Called after `read` takes bytes from the buffer; a subclass that paused its
        input while the buffer was full resumes it here."""

    async def read(self, max_bytes: int = 4096) -> bytes:
        """Wait for at least one byte and return 1..max_bytes of those buffered.

        Raises TransportClosed once the transport is closed (even while waiting), or once
        the peer is gone and the buffer is empty."""
        if max_bytes < 1:
            raise ValueError(f"max_bytes must be >= 1, got {max_bytes}")
        while True:
            if self._buffer:
                chunk = bytes(self._buffer[:max_bytes])
                del self._buffer[:max_bytes]
                self._bytes_taken()
                return chunk
            self._raise_if_ended()
            assert self._readable is not None  # set by _start_buffering, which ended "closed"
            self._readable.clear()
            await self._readable.wait()
