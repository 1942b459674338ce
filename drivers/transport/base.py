"""The byte-stream interface every device client talks through, and its errors.

A `Transport` is an async, bidirectional byte stream (a UART, a pty, an in-process link
to an emulator). It does not frame, retry or time out: those are the device client's job
(wrap awaits in `asyncio.wait_for` / `asyncio.timeout`).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable


class TransportError(Exception):
    """Base class for every transport failure (cannot open, I/O error, ...)."""


class TransportOpenError(TransportError):
    """The link could not be opened at all (no such port, no permission, in use): most
    often the configuration's to fix, not the device's."""


class TransportClosed(TransportError):
    """The peer is gone: EOF, hang-up, unplugged adapter, or the transport was closed."""


@runtime_checkable
class Transport(Protocol):
    """An async byte stream selected by URL (see `drivers.transport.open_transport`)."""

    url: str

    async def open(self) -> None:
        """Open the link; raises TransportError if it cannot."""
        ...

    async def close(self) -> None:
        """Close the link. Idempotent; never raises for an already closed link."""
        ...

    async def write(self, data: bytes) -> None:
        """Send all of ``data``; raises TransportClosed if the peer is gone or the
        transport is closed."""
        ...

    async def read(self, max_bytes: int = 4096) -> bytes:
        """Wait for at least one byte and return 1..max_bytes bytes.

        Raises TransportClosed on EOF/hang-up or when the transport is closed, also
        while waiting; ValueError if ``max_bytes`` < 1. Never returns b"" and never
        times out by itself. tests/drivers/transport/test_transport_contract.py checks
        this contract on every transport.
        """
        ...

    async def set_baudrate(self, baud: int) -> None:
        """Change the line rate (bit/s); a no-op where meaningless (sim links)."""
        ...

    async def send_break(self, duration_s: float = 0.25) -> None:
        """Hold the line in break for ``duration_s`` seconds; no-op where meaningless."""
        ...
