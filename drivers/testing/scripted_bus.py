"""A scripted I2C bus for driver unit tests (the MOCK, not the IMU emulator).

`ScriptedBus` stands in for `smbus2.SMBus` (the subset in `drivers.imu.driver.SmbusLike`).
It knows nothing about any chip: it checks that the driver issues exactly the scripted
transactions in order and hands back the scripted replies, or raises the scripted
OSError. A departure fails at once with `ScriptMismatch`.

A script is a list of ``(call, reply)`` steps; `W`, `R`, `B`, `RW` and `F` build them::

    bus = ScriptedBus([W(0x68, 0x7F, 0x00), R(0x68, 0x00, 0xEA), F(R(0x68, 0x00, 0), nack())])
"""

from __future__ import annotations

import ctypes
import errno
import os
from collections.abc import Iterable
from typing import Any

from drivers.testing.scripted_transport import ScriptMismatch

# ("method name", *arguments): one bus transaction as the driver called it.
Call = tuple[Any, ...]
Step = tuple[Call, Any]
# linux/i2c.h: the flag of a read message
I2C_M_RD = 0x0001


def nack() -> OSError:
    """The error Linux raises when the addressed device does not acknowledge."""
    return OSError(errno.EREMOTEIO, os.strerror(errno.EREMOTEIO))


def eio() -> OSError:
    """A generic bus I/O error (a glitch, an unplugged cable)."""
    return OSError(errno.EIO, os.strerror(errno.EIO))


def W(address: int, register: int, value: int) -> Step:
    """``write_byte_data(address, register, value)``."""
    return ("write_byte_data", address, register, value), None


def R(address: int, register: int, reply: int | BaseException) -> Step:
    """``read_byte_data(address, register)`` answering ``reply``."""
    return ("read_byte_data", address, register), reply


def B(address: int, register: int, length: int, reply: bytes | BaseException) -> Step:
    """``read_i2c_block_data(address, register, length)`` answering ``reply``."""
    return ("read_i2c_block_data", address, register, length), reply


def RW(address: int, register: int, length: int, reply: bytes | BaseException) -> Step:
    """``i2c_rdwr``: write the register address, then read ``length`` bytes answering ``reply``."""
    return ("i2c_rdwr", ((address, 0, 1), (address, I2C_M_RD, length))), reply


def F(step: Step, error: BaseException) -> Step:
    """The same call, answered with an exception."""
    return step[0], error


class ScriptedBus:
    """An SMBus stand-in that checks the exact sequence of transactions.

    ``i2c_rdwr`` is matched as ``("i2c_rdwr", ((addr, flags, length), ...))``; a bytes
    reply fills its read message (`RW`), otherwise they stay as allocated (zeros)."""

    def __init__(self, script: Iterable[Step]) -> None:
        self.script = list(script)
        self.position = 0
        self.calls: list[Call] = []

    def _next(self, call: Call) -> Any:
        self.calls.append(call)
        if self.position >= len(self.script):
            raise ScriptMismatch(f"unscripted transaction after the script ended: {call}")
        expected, reply = self.script[self.position]
        if call != expected:
            raise ScriptMismatch(f"transaction {self.position}: expected {expected}, got {call}")
        self.position += 1
        if isinstance(reply, BaseException):
            raise reply
        return reply

    def read_byte_data(self, i2c_addr: int, register: int) -> int:
        return self._next(("read_byte_data", i2c_addr, register))

    def write_byte_data(self, i2c_addr: int, register: int, value: int) -> None:
        self._next(("write_byte_data", i2c_addr, register, value))

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> list[int]:
        return list(self._next(("read_i2c_block_data", i2c_addr, register, length)))

    def i2c_rdwr(self, *messages: Any) -> None:
        reply = self._next(("i2c_rdwr", tuple((m.addr, m.flags, len(m)) for m in messages)))
        if isinstance(reply, (bytes, bytearray)):
            read = next(m for m in messages if m.flags & I2C_M_RD)
            ctypes.memmove(read.buf, bytes(reply), len(read))

    def assert_done(self) -> None:
        """Fail unless every scripted transaction happened."""
        if self.position != len(self.script):
            raise ScriptMismatch(
                f"script not finished: {len(self.script) - self.position} transaction(s) left, "
                f"next {self.script[self.position][0]}"
            )
