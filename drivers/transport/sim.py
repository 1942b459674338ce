"""In-process links to emulators: ``sim://NAME`` without a pty or a thread.

Register an emulator under a name, then any client opening ``sim://NAME`` talks to it:
each `write` hands the bytes to ``handler.receive`` at once and queues the reply for
`read`. Several links may be open to one device (as with a real port shared by mistake);
unsolicited bytes from ``poll()`` go to all of them.

Time-driven emulator behaviour (a watchdog) needs ``poll()`` called even when no client
is connected: `serve_sim` registers the device and runs that polling task on the current
event loop; `register_device` alone leaves polling to the caller (e.g. a bench stepping
virtual time).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from urllib.parse import urlsplit

from drivers.transport.base import TransportError
from drivers.transport.buffered import BufferedTransport
from drivers.transport.handler import EmulatorHandler, require_handler


@dataclass
class _SimDevice:
    name: str
    handler: EmulatorHandler
    links: set[SimTransport] = field(default_factory=set)

    def broadcast(self, data: bytes) -> None:
        for link in list(self.links):
            link._deliver(data)


_devices: dict[str, _SimDevice] = {}


def register_device(name: str, handler: EmulatorHandler) -> None:
    """Make ``handler`` reachable as ``sim://name``. Raises ValueError if taken."""
    if not name:
        raise ValueError("sim device name must not be empty")
    if name in _devices:
        raise ValueError(f"sim device {name!r} is already registered")
    _devices[name] = _SimDevice(name, require_handler(handler))


def unregister_device(name: str) -> None:
    """Remove the device; open links see the peer vanish (TransportClosed). Idempotent."""
    device = _devices.pop(name, None)
    if device is not None:
        for link in list(device.links):
            link._unregistered()


def registered_devices() -> list[str]:
    return sorted(_devices)


def poll_device(name: str) -> None:
    """Run one ``poll()`` of the named device and deliver its output to open links."""
    device = _devices.get(name)
    if device is not None:
        out = device.handler.poll()
        if out:
            device.broadcast(out)


@contextlib.asynccontextmanager
async def serve_sim(
    name: str, handler: EmulatorHandler, poll_interval_s: float = 0.01
) -> AsyncIterator[str]:
    """Register ``handler`` as ``sim://name`` and poll it every ``poll_interval_s`` s
    until the block exits; yields the URL."""
    register_device(name, handler)

    async def poller() -> None:
        while True:
            await asyncio.sleep(poll_interval_s)
            poll_device(name)

    task = asyncio.create_task(poller(), name=f"sim-poll:{name}")
    try:
        yield f"sim://{name}"
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        unregister_device(name)


class SimTransport(BufferedTransport):
    """Client end of an in-process link to a registered emulator."""

    def __init__(self, url: str, name: str) -> None:
        super().__init__(url)
        self.name = name
        self._device: _SimDevice | None = None

    @classmethod
    def from_url(cls, url: str) -> SimTransport:
        """``sim://NAME``; raises ValueError naming the offending part."""
        parts = urlsplit(url)
        if not parts.netloc:
            raise ValueError(f"sim URL {url!r} has no device name (sim://NAME)")
        if parts.path not in ("", "/") or parts.query:
            raise ValueError(f"sim URL {url!r} must be just sim://NAME, no path or query")
        return cls(url, parts.netloc)

    async def open(self) -> None:
        if self._device is not None:
            raise TransportError(f"{self.url}: already open")
        device = _devices.get(self.name)
        if device is None:
            raise TransportError(
                f"{self.url}: no sim device registered as {self.name!r} "
                f"(registered: {registered_devices()})"
            )
        self._device = device
        self._start_buffering()
        device.links.add(self)

    def _unregistered(self) -> None:
        self._device = None
        self._peer_gone("device was unregistered")

    def _require_open(self) -> _SimDevice:
        self._raise_if_ended()
        assert self._device is not None  # only an ended link has no device
        return self._device

    async def write(self, data: bytes) -> None:
        device = self._require_open()
        reply = device.handler.receive(bytes(data))
        if reply:
            self._deliver(reply)
        # Yield once, as a real write would, so a tight write loop cannot starve readers.
        await asyncio.sleep(0)

    async def set_baudrate(self, baud: int) -> None:
        self._require_open().handler.on_baudrate(baud)

    async def send_break(self, duration_s: float = 0.25) -> None:
        device = self._require_open()
        await asyncio.sleep(duration_s)
        reply = device.handler.on_break()
        if reply:
            self._deliver(reply)

    async def close(self) -> None:
        if self._device is not None:
            self._device.links.discard(self)
        self._device = None
        self._stop_buffering()

    def __repr__(self) -> str:
        return f"SimTransport({self.url!r})"
