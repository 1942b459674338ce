"""Async byte transports chosen by URL.

``t = open_transport(url); await t.open(); await t.write(b); await t.read()`` for
``serial://``, ``pty://`` (or a bare path) and ``sim://NAME`` URLs (`drivers.transport.url`).
Timeouts are the caller's job. Importing this package loads no transport: each is imported
when a URL of its scheme is opened.

Emulator side, imported from their modules: `drivers.transport.handler.EmulatorHandler`
(the base class of every emulator), `drivers.transport.pty.PtyServer` (serve one on a pty
from a thread) and `drivers.transport.sim` (`serve_sim`, `register_device`: in-process).
Test doubles (scripted mock, fault injection) live in `drivers.testing`.
"""

from drivers.transport.base import Transport, TransportClosed, TransportError, TransportOpenError
from drivers.transport.url import open_transport

__all__ = ["Transport", "TransportClosed", "TransportError", "TransportOpenError", "open_transport"]
