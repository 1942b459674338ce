"""Errors of the NDI Aurora driver.

`AuroraProtocolError` is the codec's only error: whatever bytes arrive, decoding raises
nothing else. The client adds typed errors for what went wrong on the link.
"""

from __future__ import annotations


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
        from drivers.aurora.replies import error_description

        super().__init__(f"Aurora rejected {command!r}: ERROR{code:02X} ({error_description(code)})")
        self.command = command
        self.code = code


class AuroraTimeoutError(AuroraError, TimeoutError):
    """The device did not answer a command in time (after the allowed retries)."""


class AuroraConnectionError(AuroraError):
    """The link to the device is gone (port closed, cable pulled, peer exited)."""
