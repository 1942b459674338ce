"""Incremental splitting of the device's byte stream into replies, and of the host's
byte stream into command lines.

The Combined API is strictly one reply per command, so the reader is told what it
expects: a text line, or a BX frame (which may also be a text ``ERRORxx`` line).
Framing only: CRCs are checked by `replies.decode_reply` / `frames.decode_bx`, except
the BX header CRC, which is needed to trust the length field.
"""

from __future__ import annotations

from drivers.aurora.errors import AuroraProtocolError
from drivers.aurora.frames import BX_HEADER_LEN, BX_START, bx_total_length

CR = b"\r"
_ERROR_PREFIX = b"ERROR"

# Longest text reply we accept before declaring the stream garbage (VER replies are a
# few hundred bytes; a real device never sends more than ~2 kB in one text reply).
MAX_TEXT_REPLY = 4096


class ReplyReader:
    """Accumulates device bytes; hands out one complete raw reply at a time."""

    def __init__(self) -> None:
        self._buffer = bytearray()

    def feed(self, data: bytes) -> None:
        self._buffer += data

    def clear(self) -> None:
        """Forget buffered bytes (before a retry: they belong to a failed exchange)."""
        self._buffer.clear()

    @property
    def pending(self) -> int:
        return len(self._buffer)

    def next_text(self) -> bytes | None:
        """A complete text reply (including CR) or None if not yet complete.

        Raises AuroraProtocolError (and drops the buffer) if no CR arrives within
        MAX_TEXT_REPLY bytes."""
        end = self._buffer.find(CR)
        if end < 0:
            if len(self._buffer) > MAX_TEXT_REPLY:
                self._buffer.clear()
                raise AuroraProtocolError("text reply without CR")
            return None
        line = bytes(self._buffer[: end + 1])
        del self._buffer[: end + 1]
        return line

    def next_binary(self) -> bytes | None:
        """A complete BX frame, or an ``ERRORxx<CRC><CR>`` line, or None if incomplete.

        Leading garbage is skipped up to the next possible start. A BX header with a
        bad CRC raises AuroraProtocolError after dropping its first byte (resync)."""
        while self._buffer:
            start = self._find_start()
            if start < 0:
                self._buffer.clear()
                return None
            del self._buffer[:start]
            if self._buffer.startswith(BX_START):
                if len(self._buffer) < BX_HEADER_LEN:
                    return None
                try:
                    total = bx_total_length(bytes(self._buffer[:BX_HEADER_LEN]))
                except AuroraProtocolError:
                    del self._buffer[:1]
                    raise
                if len(self._buffer) < total:
                    return None
                frame = bytes(self._buffer[:total])
                del self._buffer[:total]
                return frame
            if len(self._buffer) < len(_ERROR_PREFIX):
                return None
            if self._buffer.startswith(_ERROR_PREFIX):
                return self.next_text()
            del self._buffer[:1]  # an 'E' or 0xC4 that did not start a reply
        return None

    def _find_start(self) -> int:
        # A lone 0xC4 at the very end may be the first half of a start sequence.
        candidates = [i for i in (self._buffer.find(BX_START), self._buffer.find(_ERROR_PREFIX[:1])) if i >= 0]
        if self._buffer[-1:] == BX_START[:1]:
            candidates.append(len(self._buffer) - 1)
        return min(candidates) if candidates else -1


class CommandSplitter:
    """Accumulates host bytes and yields complete command lines (without the CR)."""

    def __init__(self, max_line: int = 1024) -> None:
        self._buffer = bytearray()
        self._max_line = max_line

    def feed(self, data: bytes) -> list[bytes]:
        self._buffer += data
        lines = []
        while True:
            end = self._buffer.find(CR)
            if end < 0:
                break
            lines.append(bytes(self._buffer[:end]))
            del self._buffer[: end + 1]
        if len(self._buffer) > self._max_line:
            # A real device would answer an over-long command with an error; dropping the
            # runaway bytes keeps the emulator bounded and lets the next line parse.
            self._buffer.clear()
        return lines

    def clear(self) -> None:
        self._buffer.clear()
