"""Serial ports and pty slaves as an async `Transport` (pyserial + the event loop).

pyserial opens and configures the port (termios raw mode, baud, parity, break); the byte
traffic itself goes through ``os.read``/``os.write`` on the non-blocking fd watched with
``loop.add_reader``/``add_writer``, so no thread blocks on the port and a hang-up (EIO,
EOF) surfaces as `TransportClosed` instead of pyserial's generic SerialException.
"""

from __future__ import annotations

import asyncio
import errno
import os
from urllib.parse import parse_qsl, urlsplit

import serial

from drivers.transport.base import TransportClosed, TransportError, TransportOpenError
from drivers.transport.buffered import BufferedTransport

DEFAULT_BAUD = 115200
_URL_PARAMETERS = ("baud", "parity", "stopbits")
# Stop reading from the kernel once this much is buffered and unread: the kernel's own
# buffer then fills and the line applies back-pressure, as a real UART would overrun.
_MAX_BUFFERED_BYTES = 1 << 20
_PEER_GONE_ERRNOS = {errno.EIO, errno.ENXIO, errno.EBADF, errno.ENODEV, errno.EPIPE}


def _line_settings(url: str, query: str) -> dict[str, object]:
    """The baud/parity/stopbits of a URL query; ValueError names a bad parameter."""
    options: dict[str, object] = {}
    for key, value in parse_qsl(query, keep_blank_values=True, strict_parsing=False):
        if key not in _URL_PARAMETERS:
            raise ValueError(
                f"unknown query parameter {key!r} in transport URL {url!r}; "
                f"known: {', '.join(_URL_PARAMETERS)}"
            )
        if key == "baud":
            if not value.isdigit() or int(value) <= 0:
                raise ValueError(f"baud must be a positive integer, got {value!r} in {url!r}")
            options["baud"] = int(value)
        elif key == "parity":
            if value.upper() not in ("N", "E", "O"):
                raise ValueError(f"parity must be N, E or O, got {value!r} in {url!r}")
            options["parity"] = value.upper()
        else:
            if value not in ("1", "2"):
                raise ValueError(f"stopbits must be 1 or 2, got {value!r} in {url!r}")
            options["stopbits"] = int(value)
    return options


class SerialTransport(BufferedTransport):
    """A serial device (``serial:///dev/ttyUSB0``) or pty slave (``pty:///dev/pts/7``).

    baud: line rate in bit/s. parity: "N", "E" or "O". stopbits: 1 or 2.
    """

    def __init__(
        self, url: str, port: str, baud: int = DEFAULT_BAUD, parity: str = "N", stopbits: int = 1
    ) -> None:
        super().__init__(url)
        self.port = port
        self.baud = baud
        self.parity = parity
        self.stopbits = stopbits
        self._serial: serial.Serial | None = None
        self._fd: int | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._reading = False
        self._eof = False

    @classmethod
    def from_url(cls, url: str) -> SerialTransport:
        """``serial:///dev/X?baud=..&parity=..&stopbits=..``, ``pty:///dev/pts/N?...`` or a
        bare absolute device path (115200 8N1); ValueError names the offending part."""
        if url.startswith("/"):
            return cls(url, url)
        parts = urlsplit(url)
        if parts.netloc:
            raise ValueError(
                f"{parts.scheme} URL {url!r} has host part {parts.netloc!r}; "
                f"write {parts.scheme}:///dev/... (three slashes)"
            )
        if not parts.path or parts.path == "/":
            raise ValueError(f"{parts.scheme} URL {url!r} has no device path")
        return cls(url, parts.path, **_line_settings(url, parts.query))  # type: ignore[arg-type]

    async def open(self) -> None:
        if self._serial is not None:
            raise TransportError(f"{self.url}: already open")
        ser = serial.Serial()
        ser.port = self.port
        ser.baudrate = self.baud
        ser.parity = self.parity
        ser.stopbits = self.stopbits
        ser.timeout = 0
        try:
            ser.open()
        except (serial.SerialException, OSError, ValueError) as exc:
            raise TransportOpenError(f"{self.url}: cannot open {self.port}: {exc}") from exc
        self._serial = ser
        self._fd = ser.fileno()
        os.set_blocking(self._fd, False)
        self._loop = asyncio.get_running_loop()
        self._eof = False
        self._start_buffering()
        self._start_reading()

    def _start_reading(self) -> None:
        if not self._reading and self._fd is not None and self._loop is not None:
            self._loop.add_reader(self._fd, self._on_readable)
            self._reading = True

    def _stop_reading(self) -> None:
        if self._reading and self._fd is not None and self._loop is not None:
            self._loop.remove_reader(self._fd)
            self._reading = False

    def _on_readable(self) -> None:
        assert self._fd is not None
        try:
            data = os.read(self._fd, 65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            # EIO on a pty slave whose master closed, ENXIO/ENODEV on an unplugged adapter.
            data = b""
        if not data:
            self._eof = True
            self._stop_reading()
            self._peer_gone("peer hung up (EOF)")
            return
        self._deliver(data)
        if len(self._buffer) >= _MAX_BUFFERED_BYTES:
            self._stop_reading()

    def _bytes_taken(self) -> None:
        if not self._eof:
            self._start_reading()

    async def write(self, data: bytes) -> None:
        view = memoryview(bytes(data))
        while view:
            if self._fd is None:
                raise TransportClosed(f"{self.url}: transport is closed")
            try:
                written = os.write(self._fd, view)
            except (BlockingIOError, InterruptedError):
                await self._wait_writable()
                continue
            except OSError as exc:
                if exc.errno in _PEER_GONE_ERRNOS:
                    raise TransportClosed(f"{self.url}: write failed: {exc}") from exc
                raise TransportError(f"{self.url}: write failed: {exc}") from exc
            view = view[written:]

    async def _wait_writable(self) -> None:
        assert self._loop is not None and self._fd is not None
        fd = self._fd
        ready = self._loop.create_future()
        self._loop.add_writer(fd, lambda: ready.done() or ready.set_result(None))
        try:
            await ready
        finally:
            self._loop.remove_writer(fd)

    async def set_baudrate(self, baud: int) -> None:
        if self._serial is None:
            raise TransportClosed(f"{self.url}: transport is closed")
        try:
            self._serial.baudrate = baud
        except (serial.SerialException, OSError, ValueError) as exc:
            raise TransportError(f"{self.url}: cannot set baud {baud}: {exc}") from exc
        self.baud = baud

    async def send_break(self, duration_s: float = 0.25) -> None:
        if self._serial is None:
            raise TransportClosed(f"{self.url}: transport is closed")
        # TIOCSBRK/TIOCCBRK instead of tcsendbreak: the latter blocks the event loop for
        # the whole break. On a pty both are accepted and do nothing visible.
        try:
            self._serial.break_condition = True
            try:
                await asyncio.sleep(duration_s)
            finally:
                if self._serial is not None:
                    self._serial.break_condition = False
        except (serial.SerialException, OSError) as exc:
            raise TransportError(f"{self.url}: break failed: {exc}") from exc

    async def close(self) -> None:
        self._stop_reading()
        self._stop_buffering()
        if self._serial is None:
            return
        ser, self._serial, self._fd = self._serial, None, None
        try:
            ser.close()
        except (serial.SerialException, OSError):
            pass  # closing a port whose device vanished: nothing left to release

    def __repr__(self) -> str:
        return f"SerialTransport({self.url!r})"
