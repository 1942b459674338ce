"""What an emulator must offer to be served over a pty or an in-process sim link.

An emulator is a byte-level state machine deriving from `EmulatorHandler`. It must
implement ``receive``; the other hooks default to doing nothing, so an emulator overrides
only the events its device reacts to.

Servers may call a handler from a thread of their own, so an emulator that is also
touched from elsewhere (tests, the bench) must lock its state.
"""

from __future__ import annotations

from abc import ABC, abstractmethod


class EmulatorHandler(ABC):
    @abstractmethod
    def receive(self, data: bytes) -> bytes:
        """Bytes the host wrote (any split, any garbage) in; the bytes the device sends
        back out (may be b"")."""

    def poll(self) -> bytes:
        """Called by the server every ``poll_interval_s`` even when the host is silent,
        for time-driven behaviour (watchdogs, streaming); returns unsolicited bytes."""
        return b""

    def on_break(self) -> bytes:
        """The host held a serial break (sim links only: a pty cannot convey a break);
        returns the bytes the device sends in response."""
        return b""

    def on_baudrate(self, baud: int) -> None:
        """The host changed its line rate to ``baud`` bit/s (sim links only)."""


def require_handler(handler: object) -> EmulatorHandler:
    """``handler`` itself; TypeError now if it is not an `EmulatorHandler`, rather than an
    AttributeError later from a server's thread or poll task."""
    if not isinstance(handler, EmulatorHandler):
        raise TypeError(f"{handler!r} is not an EmulatorHandler: derive the emulator from it")
    return handler
