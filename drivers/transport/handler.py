"""What an emulator must offer to be served over a pty or an in-process sim link.

An emulator is a byte-level state machine. Required:

* ``receive(data: bytes) -> bytes``: bytes the host wrote (any split, any garbage);
  returns the bytes the device sends back (may be b"").

Optional (looked up with ``getattr``):

* ``poll() -> bytes``: called periodically by the server (every ``poll_interval_s``)
  even when the host is silent, for time-driven behaviour (watchdogs, streaming);
  returns unsolicited bytes to send.
* ``on_break() -> bytes``: the host held a serial break (sim links only: a pty cannot
  convey a break).
* ``on_baudrate(baud: int) -> None``: the host changed its line rate (sim links only).

Servers may call a handler from a thread of their own, so an emulator that is also
touched from elsewhere (tests, the bench) must lock its state.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable


@runtime_checkable
class EmulatorHandler(Protocol):
    def receive(self, data: bytes) -> bytes:
        """Bytes from the host in, bytes to the host out."""
        ...


def poll_handler(handler: EmulatorHandler) -> bytes:
    """Call ``handler.poll()`` if it has one; returns the unsolicited bytes (or b"")."""
    poll = getattr(handler, "poll", None)
    return poll() if poll is not None else b""
