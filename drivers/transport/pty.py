"""Serve an emulator on a pseudo-terminal, so unmodified clients open it as a serial port.

`PtyPair` opens a master/slave pair, puts the slave in raw mode (no echo, no line
editing, no CR/LF translation: a binary protocol must pass byte for byte) and keeps its
own slave fd open. That last point matters: on Linux, once the last slave fd closes the
master reads EIO, so without it the emulator would see an error every time a client
closes the port, and a client re-opening it would race the emulator.

`PtyServer` runs the emulator on a thread: it reads the master, hands the bytes to
``handler.receive``, writes the reply back, and calls ``handler.poll()`` every
``poll_interval_s`` seconds even when the host is silent (watchdogs). Replies the slave's
queue cannot take yet wait in an outbox (bounded at 1 MiB) and go out when it drains. The
thread keeps serving after a client disappears, as real firmware would.
"""

from __future__ import annotations

import os
import select
import threading
import time
import tty
from types import TracebackType

from drivers.transport.handler import EmulatorHandler, require_handler

# Replies held back while the client is not reading; beyond this they are dropped.
_MAX_OUTBOX_BYTES = 1 << 20


class PtyPair:
    """A raw-mode pty. ``path`` is the slave device a client opens (e.g. /dev/pts/7);
    ``master_fd`` is the non-blocking emulator end."""

    def __init__(self) -> None:
        master_fd, slave_fd = os.openpty()
        try:
            tty.setraw(slave_fd)
            os.set_blocking(master_fd, False)
            self.path: str = os.ttyname(slave_fd)
        except BaseException:
            os.close(master_fd)
            os.close(slave_fd)
            raise
        self.master_fd: int | None = master_fd
        self._slave_fd: int | None = slave_fd

    def read_master(self, max_bytes: int = 4096) -> bytes:
        """Bytes the client wrote (b"" if none are waiting)."""
        if self.master_fd is None:
            return b""
        try:
            return os.read(self.master_fd, max_bytes)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError:
            # EIO can only mean no slave fd is open; ours is, unless we are closing.
            return b""

    def write_master(self, data: bytes) -> int:
        """Send bytes to the client without blocking; returns how many the kernel took
        (fewer than len(data) when the slave's input queue is full)."""
        if self.master_fd is None:
            return 0
        sent = 0
        view = memoryview(data)
        while sent < len(data):
            try:
                sent += os.write(self.master_fd, view[sent:])
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                break
        return sent

    def close(self) -> None:
        """Close both ends; a client still holding the slave then reads EOF/EIO."""
        for attr in ("master_fd", "_slave_fd"):
            fd = getattr(self, attr)
            if fd is not None:
                setattr(self, attr, None)
                os.close(fd)


class PtyServer:
    """Serve ``handler`` on a fresh pty from a daemon thread.

    Use as a context manager (or `start`/`stop`); ``path`` is the slave to give clients.
    If the handler raises, the server stops and `stop` re-raises that exception, so an
    emulator bug fails the test that used it instead of silently going quiet.
    """

    def __init__(
        self, handler: EmulatorHandler, poll_interval_s: float = 0.01, name: str = "pty-emulator"
    ) -> None:
        if poll_interval_s <= 0:
            raise ValueError(f"poll_interval_s must be > 0, got {poll_interval_s}")
        self.handler = require_handler(handler)
        self.poll_interval_s = poll_interval_s
        self._pty = PtyPair()
        self.path = self._pty.path
        self._wake_r, self._wake_w = os.pipe()
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self.error: BaseException | None = None
        self._outbox = bytearray()  # replies the slave's queue could not take yet

    def start(self) -> PtyServer:
        self._thread.start()
        return self

    def _send(self, data: bytes) -> None:
        if len(self._outbox) + len(data) > _MAX_OUTBOX_BYTES:
            # Nobody has read the slave for a long time: drop, as a UART's receiver would.
            data = data[: max(0, _MAX_OUTBOX_BYTES - len(self._outbox))]
        self._outbox += data
        self._flush()

    def _flush(self) -> None:
        if self._outbox:
            sent = self._pty.write_master(bytes(self._outbox))
            del self._outbox[:sent]

    def _run(self) -> None:
        master = self._pty.master_fd
        assert master is not None
        next_poll = time.monotonic()
        try:
            while not self._stopping.is_set():
                timeout = max(0.0, next_poll - time.monotonic())
                writers = [master] if self._outbox else []
                readable, writable, _ = select.select(
                    [master, self._wake_r], writers, [], timeout
                )
                if writable:
                    self._flush()
                if master in readable:
                    data = self._pty.read_master()
                    if data:
                        reply = self.handler.receive(data)
                        if reply:
                            self._send(reply)
                now = time.monotonic()
                if now >= next_poll:
                    out = self.handler.poll()
                    if out:
                        self._send(out)
                    next_poll = now + self.poll_interval_s
        except BaseException as exc:  # handed to stop(): a dead emulator must not hide
            self.error = exc

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop serving and close the pty. Idempotent. Re-raises a handler exception."""
        self._stopping.set()
        if self._wake_w is not None:
            try:
                os.write(self._wake_w, b"x")
            except OSError:
                pass
        if self._thread.is_alive():
            self._thread.join(timeout_s)
        if self._wake_w is not None:
            os.close(self._wake_r)
            os.close(self._wake_w)
            self._wake_w = None
        self._pty.close()
        if self.error is not None:
            error, self.error = self.error, None
            raise error

    def __enter__(self) -> PtyServer:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()
