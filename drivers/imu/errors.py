"""Typed errors of the IMU driver. Every one names the I2C address it is about, so a bench
with two chips on one bus says which one failed."""

from __future__ import annotations


class ImuError(Exception):
    """Base of every error this package raises on purpose."""


class ImuProtocolError(ImuError):
    """Bytes that cannot be a register burst of the configured layout (the codec's only
    error type)."""


class ImuBusError(ImuError):
    """An I2C transaction kept failing after the bounded retries.

    address: 7-bit I2C address; operation: what was being done; errno: the last OSError's
    errno (None if it had none)."""

    def __init__(self, address: int, operation: str, errno: int | None, detail: str = "") -> None:
        self.address = address
        self.operation = operation
        self.errno = errno
        text = f"I2C 0x{address:02X}: {operation} failed (errno {errno})"
        super().__init__(f"{text}: {detail}" if detail else text)


class ImuNotFoundError(ImuBusError):
    """Nothing acknowledged the address when the driver first spoke to it."""

    def __init__(self, address: int, errno: int | None) -> None:
        super().__init__(
            address,
            "probe",
            errno,
            "no device acknowledged this address (check wiring, AD0 level, bus number)",
        )


class ImuIdentityError(ImuError):
    """A device answered but its identity register holds the wrong value.

    part: "ICM-20948" or "AK09916"; register: the identity register's name."""

    def __init__(self, address: int, part: str, register: str, expected: int, got: int) -> None:
        self.address = address
        self.part = part
        self.expected = expected
        self.got = got
        super().__init__(
            f"I2C 0x{address:02X}: {part} {register} reads 0x{got:02X}, expected 0x{expected:02X}"
        )


class ImuAuxBusError(ImuError):
    """The chip's auxiliary I2C master could not reach its AK09916 (NACK or no completion)."""

    def __init__(self, address: int, detail: str) -> None:
        self.address = address
        super().__init__(f"I2C 0x{address:02X}: auxiliary bus to the AK09916: {detail}")


class ImuConfigError(ImuError):
    """A configuration register did not read back what was written, or a reset did not
    complete."""

    def __init__(self, address: int, detail: str) -> None:
        self.address = address
        super().__init__(f"I2C 0x{address:02X}: {detail}")


class ImuMotionError(ImuError):
    """Gyro bias estimation saw motion: the spread of the samples exceeded the limit."""

    def __init__(self, address: int | None, detail: str) -> None:
        self.address = address
        where = f"I2C 0x{address:02X}: " if address is not None else ""
        super().__init__(f"{where}gyro bias estimation rejected: {detail}")


class ImuTimeoutError(ImuError):
    """An async wrapper call did not finish within its timeout."""
