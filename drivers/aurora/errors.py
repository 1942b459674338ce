"""Errors of the NDI Aurora driver.

`AuroraProtocolError` is the codec's only error: whatever bytes arrive, decoding raises
nothing else. The client adds typed errors for what went wrong on the link.
"""

from __future__ import annotations

from enum import IntEnum


class ErrorCode(IntEnum):
    """Device error codes used by this driver (NDI Aurora API Guide, ERROR table)."""

    INVALID_COMMAND = 0x01
    BAD_CRC = 0x04
    PARAMETER_COUNT = 0x07
    INVALID_PORT_HANDLE = 0x08
    INVALID_MODE = 0x0C  # command not valid in the current operating mode
    PORT_NOT_INITIALISED = 0x0E
    NOT_INITIALISED = 0x10
    CANNOT_INITIALISE_HANDLE = 0x13
    PARAMETER_RANGE = 0x23


_DESCRIPTIONS = {
    ErrorCode.INVALID_COMMAND: "invalid command",
    ErrorCode.BAD_CRC: "bad CRC in command",
    ErrorCode.PARAMETER_COUNT: "wrong number of parameters",
    ErrorCode.INVALID_PORT_HANDLE: "invalid port handle",
    ErrorCode.INVALID_MODE: "command not valid in the current mode",
    ErrorCode.PORT_NOT_INITIALISED: "port handle not initialised",
    ErrorCode.NOT_INITIALISED: "system not initialised",
    ErrorCode.CANNOT_INITIALISE_HANDLE: "cannot initialise port handle",
    ErrorCode.PARAMETER_RANGE: "parameter out of range",
}


def error_description(code: int) -> str:
    """Human-readable meaning of a device error code."""
    try:
        return _DESCRIPTIONS[ErrorCode(code)]
    except ValueError:
        return "unknown error"


class AuroraError(Exception):
    """Base class of every Aurora driver error."""


class AuroraProtocolError(AuroraError):
    """Bytes that are not a valid Combined API command, reply or frame.

    ``device_error_code`` is the ERROR code a real Aurora answers to such a command
    (e.g. 0x04 for a bad CRC, 0x01 for an unknown command), so the emulator can reply
    like the device; None where no device code applies (reply-side errors).
    """

    def __init__(self, message: str, device_error_code: int | None = None) -> None:
        super().__init__(message)
        self.device_error_code = device_error_code


class AuroraCommandError(AuroraError):
    """The device answered ``ERRORxx`` to a command."""

    def __init__(self, command: str, code: int) -> None:
        super().__init__(f"Aurora rejected {command!r}: ERROR{code:02X} ({error_description(code)})")
        self.command = command
        self.code = code


class AuroraTimeoutError(AuroraError, TimeoutError):
    """The device did not answer a command in time (after the allowed retries)."""


class AuroraConnectionError(AuroraError):
    """The link to the device is gone (port closed, cable pulled, peer exited)."""
