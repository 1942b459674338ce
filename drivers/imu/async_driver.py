"""Async face of `Icm20948` for the bench.

An I2C burst takes ~0.5 ms at 400 kHz and ~2.5 ms at 100 kHz; at 100 Hz for two chips
that would steal a noticeable share of the event loop from the serial devices, so each
call runs in a worker thread. Both chips share one bus and smbus2 selects the slave
address per call (an ioctl, then the transfer), so calls on one bus must not interleave:
every wrapper on a bus shares one `threading.Lock` (`bus_lock`). Every call is bounded by
a timeout; a worker that overruns it cannot be interrupted, but the caller gets
`ImuTimeoutError` instead of hanging.

A bus whose transactions never wait on hardware says so with a false ``calls_block``
attribute (the in-process `Icm20948BusEmulator`): its sample reads then run on the
caller's thread, as a thread hop would cost more than the read (two chips at 100 Hz on a
25x simulated rig are 5000 hops per wall second). `smbus2.SMBus` has no such attribute
and keeps its worker. Calls that sleep while the chip starts up (`initialize`,
`estimate_gyro_bias`) take a worker on any bus.
"""

from __future__ import annotations

import asyncio
import functools
import threading
from collections.abc import Callable
from typing import TypeVar

from drivers.imu.calibration import GyroBiasEstimate, ImuSample
from drivers.imu.codec import RawImuSample
from drivers.imu.driver import FifoRead, Icm20948
from drivers.imu.errors import ImuTimeoutError

T = TypeVar("T")


class AsyncIcm20948:
    """Wraps one `Icm20948`. bus_lock: shared by all wrappers on the same bus;
    timeout_s: bound of a single read; init_timeout_s: bound of `initialize` and
    `enable_fifo`, and of `estimate_gyro_bias` on top of its samples' duration (which
    wait for the chip)."""

    def __init__(
        self,
        driver: Icm20948,
        *,
        bus_lock: threading.Lock | None = None,
        timeout_s: float = 0.5,
        init_timeout_s: float = 5.0,
    ) -> None:
        if not timeout_s > 0 or not init_timeout_s > 0:
            raise ValueError("timeouts must be positive")
        self.driver = driver
        self.bus_lock = bus_lock or threading.Lock()
        self.timeout_s = timeout_s
        self.init_timeout_s = init_timeout_s
        self.reads_inline = not getattr(driver.bus, "calls_block", True)

    @property
    def address(self) -> int:
        return self.driver.address

    def _locked(self, function: Callable[[], T]) -> T:
        with self.bus_lock:
            return function()

    async def _run(self, what: str, function: Callable[[], T], timeout_s: float) -> T:
        try:
            return await asyncio.wait_for(asyncio.to_thread(self._locked, function), timeout_s)
        except TimeoutError:
            raise ImuTimeoutError(
                f"I2C 0x{self.address:02X}: {what} did not finish within {timeout_s} s"
            ) from None

    async def initialize(self) -> None:
        await self._run("initialize", self.driver.initialize, self.init_timeout_s)

    async def _read(self, what: str, function: Callable[[], T]) -> T:
        if self.reads_inline:
            return self._locked(function)
        return await self._run(what, function, self.timeout_s)

    async def read_raw(self) -> RawImuSample:
        return await self._read("read_raw", self.driver.read_raw)

    async def read_sample(self) -> ImuSample:
        return await self._read("read_sample", self.driver.read_sample)

    async def enable_fifo(self) -> None:
        await self._run("enable_fifo", self.driver.enable_fifo, self.init_timeout_s)

    async def read_fifo(self) -> FifoRead:
        return await self._read("read_fifo", self.driver.read_fifo)

    async def reset_fifo(self) -> None:
        await self._read("reset_fifo", self.driver.reset_fifo)

    async def estimate_gyro_bias(self, sample_count: int = 200, **kwargs: float | bool) -> GyroBiasEstimate:
        call = functools.partial(self.driver.estimate_gyro_bias, sample_count, **kwargs)  # type: ignore[arg-type]
        # One sample per output period: 100 samples at 10 Hz take 10 s on the rig.
        timeout_s = self.init_timeout_s + sample_count * self.driver.sample_period_s
        return await self._run("estimate_gyro_bias", call, timeout_s)
