"""Async byte transports chosen by URL, plus the emulator-side servers.

Client side: ``t = open_transport(url); await t.open(); await t.write(b); await t.read()``
for ``serial://``, ``pty://`` (or a bare path) and ``sim://NAME`` URLs; `FaultyTransport`
wraps any of them to inject line faults. Emulator side: `PtyServer` (a pty + thread) and
`serve_sim`/`register_device` (in-process). Timeouts are the caller's job.
"""

from drivers.transport.base import Transport, TransportClosed, TransportError
from drivers.transport.faults import FaultyTransport
from drivers.transport.handler import EmulatorHandler
from drivers.transport.mock import ScriptedTransport, ScriptMismatch
from drivers.transport.pty import PtyPair, PtyServer
from drivers.transport.serial_link import SerialTransport
from drivers.transport.sim import SimTransport, register_device, serve_sim, unregister_device
from drivers.transport.url import open_transport

__all__ = [
    "EmulatorHandler",
    "FaultyTransport",
    "PtyPair",
    "PtyServer",
    "ScriptMismatch",
    "ScriptedTransport",
    "SerialTransport",
    "SimTransport",
    "Transport",
    "TransportClosed",
    "TransportError",
    "open_transport",
    "register_device",
    "serve_sim",
    "unregister_device",
]
