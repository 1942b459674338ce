"""Host-to-device commands of the NDI Combined API.

Two wire forms (NDI Aurora API Guide; ndicapi's ndiCommandVA):

* ``NAME:params<CRC16 as 4 upper-case hex><CR>``, the CRC covering ``NAME:params``;
* ``NAME params<CR>`` (or bare ``NAME<CR>``) with no CRC.

The host always sends the first form; the emulator accepts both.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass

from drivers.aurora.crc import crc16
from drivers.aurora.errors import AuroraProtocolError

CR = b"\r"

# Device error codes for malformed commands (API Guide, ERROR codes).
_INVALID_COMMAND = 0x01
_BAD_CRC = 0x04

_NAME = re.compile(r"[A-Z][A-Z0-9]*\Z")
_HEX4 = re.compile(r"[0-9A-Fa-f]{4}\Z")


def _is_printable(text: str) -> bool:
    """Only ' ' to '~' (ASCII's printable characters)."""
    return text.isascii() and text.isprintable()


@dataclass(frozen=True)
class Command:
    """One command: ``name`` (upper-case letters and digits, e.g. ``"BX"``) and its
    parameter string (e.g. ``"0801"``; empty for none)."""

    name: str
    params: str = ""

    def __post_init__(self) -> None:
        if not _NAME.match(self.name):
            raise AuroraProtocolError(f"bad command name {self.name!r}", _INVALID_COMMAND)
        if not _is_printable(self.params):
            raise AuroraProtocolError(f"command parameters must be printable ASCII: {self.params!r}")

    @property
    def text(self) -> str:
        """``NAME:params``, the part the CRC covers."""
        return f"{self.name}:{self.params}"

    @functools.cached_property
    def wire(self) -> bytes:
        """``encode()``, made once: a tracker is polled with one same command 40 times a
        second (1000 times a wall second on a 25x simulated rig)."""
        return self.encode()

    def encode(self, with_crc: bool = True) -> bytes:
        """Wire bytes: ``NAME:params<CRC><CR>``, or ``NAME params<CR>`` without CRC."""
        if with_crc:
            body = self.text.encode("ascii")
            return body + f"{crc16(body):04X}".encode("ascii") + CR
        spaced = f"{self.name} {self.params}" if self.params else self.name
        return spaced.encode("ascii") + CR


def parse_command(line: bytes) -> Command:
    """Parse one command line (with or without its trailing CR).

    Raises AuroraProtocolError with ``device_error_code`` 0x04 for a CRC mismatch and
    0x01 for anything that is not a command.
    """
    if line.endswith(CR):
        line = line[:-1]
    try:
        text = line.decode("ascii")
    except UnicodeDecodeError:
        raise AuroraProtocolError("command is not ASCII", _INVALID_COMMAND) from None
    if not text or not _is_printable(text):
        raise AuroraProtocolError(f"not a command: {text!r}", _INVALID_COMMAND)
    colon, space = text.find(":"), text.find(" ")
    if colon >= 0 and (space < 0 or colon < space):
        name, rest = text[:colon], text[colon + 1 :]
        if not _NAME.match(name):
            raise AuroraProtocolError(f"bad command name {name!r}", _INVALID_COMMAND)
        if len(rest) < 4 or not _HEX4.match(rest[-4:]):
            raise AuroraProtocolError(f"{name}: command with ':' lacks its CRC", _BAD_CRC)
        params, crc_text = rest[:-4], rest[-4:]
        if crc16(f"{name}:{params}".encode("ascii")) != int(crc_text, 16):
            raise AuroraProtocolError(f"{name}: command CRC mismatch", _BAD_CRC)
        return Command(name, params)
    if space >= 0:
        name, params = text[:space], text[space + 1 :]
    else:
        name, params = text, ""
    if not _NAME.match(name):
        raise AuroraProtocolError(f"bad command name {name!r}", _INVALID_COMMAND)
    return Command(name, params)
