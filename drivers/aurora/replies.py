"""Device-to-host text replies of the NDI Combined API, and the PHSR port-handle list.

Every text reply is ``<payload><CRC16 as 4 hex><CR>``; the payload is ``OKAY``,
``ERRORxx`` (xx = 2 hex digits), ``RESET`` (after a break or the RESET command) or
command-specific data (printable ASCII, lines separated by LF, never CR).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import IntEnum, IntFlag

from drivers.aurora.crc import crc16
from drivers.aurora.errors import AuroraProtocolError

CR = b"\r"


@dataclass(frozen=True)
class OkayReply:
    """``OKAY``: the command was accepted."""


@dataclass(frozen=True)
class ErrorReply:
    """``ERRORxx``: the command was rejected with device error ``code`` (0..255)."""

    code: int

    def __post_init__(self) -> None:
        if not 0 <= self.code <= 0xFF:
            raise AuroraProtocolError(f"error code out of range: {self.code}")


@dataclass(frozen=True)
class ResetReply:
    """``RESET``: the device was reset (break or RESET command) and is at 9600 baud."""


@dataclass(frozen=True)
class DataReply:
    """Any other payload (PHSR list, VER text, TX frame, BEEP answer ...)."""

    text: str

    def __post_init__(self) -> None:
        if not _is_payload(self.text):
            raise AuroraProtocolError(f"reply payload must be printable ASCII or LF: {self.text!r}")
        if self.text in ("OKAY", "RESET") or _ERROR.match(self.text):
            raise AuroraProtocolError(f"{self.text!r} is not a data payload")


TextReply = OkayReply | ErrorReply | ResetReply | DataReply

_ERROR = re.compile(r"ERROR([0-9A-Fa-f]{2})\Z")
_HEX = re.compile(r"[0-9A-Fa-f]+\Z")


def _is_payload(text: str) -> bool:
    return all(" " <= ch <= "~" or ch == "\n" for ch in text)


def reply_payload(reply: TextReply) -> str:
    """The payload text of a reply (without CRC)."""
    if isinstance(reply, OkayReply):
        return "OKAY"
    if isinstance(reply, ResetReply):
        return "RESET"
    if isinstance(reply, ErrorReply):
        return f"ERROR{reply.code:02X}"
    return reply.text


def encode_payload(text: str) -> bytes:
    """``text<CRC><CR>`` for any payload string."""
    body = text.encode("ascii")
    return body + f"{crc16(body):04X}".encode("ascii") + CR


def encode_reply(reply: TextReply) -> bytes:
    """Wire bytes of a text reply."""
    return encode_payload(reply_payload(reply))


def decode_reply(line: bytes) -> TextReply:
    """Check the CRC of one reply line (with or without its CR) and classify it."""
    if line.endswith(CR):
        line = line[:-1]
    if len(line) < 4:
        raise AuroraProtocolError(f"reply too short: {line!r}")
    try:
        text = line.decode("ascii")
    except UnicodeDecodeError:
        raise AuroraProtocolError("reply is not ASCII") from None
    payload, crc_text = text[:-4], text[-4:]
    if not _HEX.match(crc_text):
        raise AuroraProtocolError(f"reply CRC is not hex: {crc_text!r}")
    if crc16(payload.encode("ascii")) != int(crc_text, 16):
        raise AuroraProtocolError("reply CRC mismatch")
    if not _is_payload(payload):
        raise AuroraProtocolError("reply payload has control characters")
    if payload == "OKAY":
        return OkayReply()
    if payload == "RESET":
        return ResetReply()
    match = _ERROR.match(payload)
    if match:
        return ErrorReply(int(match.group(1), 16))
    return DataReply(payload)


# --- PHSR ---------------------------------------------------------------------------


class PortStatus(IntFlag):
    """Port status bits (PHSR 3-hex field; BX/TX 32-bit field). API Guide / ndicapi.h."""

    OCCUPIED = 0x0001
    SWITCH_1 = 0x0002
    SWITCH_2 = 0x0004
    SWITCH_3 = 0x0008
    INITIALISED = 0x0010
    ENABLED = 0x0020
    OUT_OF_VOLUME = 0x0040
    PARTIALLY_IN_VOLUME = 0x0080
    BROKEN_COIL = 0x0100  # Aurora sensor coil broken (bit 8)


class PhsrMode(IntEnum):
    """PHSR reply option: which port handles to list."""

    ALL = 0x00
    TO_BE_FREED = 0x01
    NOT_INITIALISED = 0x02
    NOT_ENABLED = 0x03  # initialised but not yet enabled
    ENABLED = 0x04


@dataclass(frozen=True)
class PortHandleEntry:
    """One PHSR entry: port ``handle`` (0x01..0xFF) and its 12-bit status."""

    handle: int
    status: int

    def __post_init__(self) -> None:
        if not 0 <= self.handle <= 0xFF or not 0 <= self.status <= 0xFFF:
            raise AuroraProtocolError(f"PHSR entry out of range: {self}")


@dataclass(frozen=True)
class PortHandleList:
    """A PHSR reply: ``NN`` (count, 2 hex) then per handle ``HH`` + ``SSS`` (hex)."""

    entries: tuple[PortHandleEntry, ...] = ()

    def __post_init__(self) -> None:
        if len(self.entries) > 0xFF:
            raise AuroraProtocolError("too many port handles for one PHSR reply")

    @property
    def handles(self) -> tuple[int, ...]:
        return tuple(entry.handle for entry in self.entries)

    def to_text(self) -> str:
        return f"{len(self.entries):02X}" + "".join(f"{e.handle:02X}{e.status:03X}" for e in self.entries)

    @classmethod
    def from_text(cls, text: str) -> PortHandleList:
        if len(text) < 2 or not _HEX.match(text):
            raise AuroraProtocolError(f"PHSR reply is not hex: {text!r}")
        count = int(text[:2], 16)
        if len(text) != 2 + 5 * count:
            raise AuroraProtocolError(f"PHSR reply announces {count} handles but has {len(text)} chars")
        entries = tuple(
            PortHandleEntry(int(text[i : i + 2], 16), int(text[i + 2 : i + 5], 16))
            for i in range(2, len(text), 5)
        )
        return cls(entries)
