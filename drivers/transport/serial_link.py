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

import serial

from drivers.transport.base import TransportClosed, TransportError

# Stop reading from the kernel once this much is buffered and unread: the kernel's own
# buffer then fills and the line applies back-pressure, as a real UART would overrun.
_MAX_BUFFERED_BYTES = 1 << 20
_PEER_GONE_ERRNOS = {errno.EIO, errno.ENXIO, errno.EBADF, errno.ENODEV, errno.EPIPE}


class SerialTransport:
    """A serial device (``serial:///dev/ttyUSB0``) or pty slave (``pty:///dev/pts/7``).

    baud: line rate in bit/s. parity: "N", "E" or "O". stopbits: 1 or 2.
    """

    def __init__(
        self, url: str, port: str, baud: int = 115200, parity: str = "N", stopbits: int = 1
    ) -> None:
        self.url = url
        self.port = port
        self.baud = baud
        self.parity = parity
        self.stopbits = stopbits
        self._serial: serial.Serial | None = None
        self._fd: int | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._buffer = bytearray()
        self._readable = asyncio.Event()
        self._reading = False
        self._eof = False
        self._closed = False

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
            raise TransportError(f"{self.url}: cannot open {self.port}: {exc}") from exc
        self._serial = ser
        self._fd = ser.fileno()
        os.set_blocking(self._fd, False)
        self._loop = asyncio.get_running_loop()
        self._readable = asyncio.Event()  # bound to the loop that opened the port
        self._closed = False
        self._eof = False
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
        else:
            self._buffer += data
            if len(self._buffer) >= _MAX_BUFFERED_BYTES:
                self._stop_reading()
        self._readable.set()

    async def read(self, max_bytes: int = 4096) -> bytes:
        if max_bytes < 1:
            raise ValueError(f"max_bytes must be >= 1, got {max_bytes}")
        while True:
            if self._closed or self._serial is None:
                raise TransportClosed(f"{self.url}: transport is closed")
            if self._buffer:
                chunk = bytes(self._buffer[:max_bytes])
                del self._buffer[:max_bytes]
                if not self._eof:
                    self._start_reading()
                return chunk
            if self._eof:
                raise TransportClosed(f"{self.url}: peer hung up (EOF)")
            self._readable.clear()
            await self._readable.wait()

    async def write(self, data: bytes) -> None:
        view = memoryview(bytes(data))
        while view:
            if self._closed or self._fd is None:
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
        if self._serial is None:
            self._closed = True
            return
        self._stop_reading()
        ser, self._serial, self._fd = self._serial, None, None
        self._closed = True
        self._buffer.clear()
        self._readable.set()  # wake a waiting reader so it raises TransportClosed
        try:
            ser.close()
        except (serial.SerialException, OSError):
            pass  # closing a port whose device vanished: nothing left to release

    def __repr__(self) -> str:
        return f"SerialTransport({self.url!r})"
