"""The rig's devices, opened per the profile's ``[transports]`` and closed safely.

`open_rig` is the one place that wires the valve controller, the EM tracker and the IMU
pair: emulated on the digital twin (``"sim"``/``"pty"``, `bench.simulated_rig`) or real
(a serial URL, an I2C bus number), in any mix. Its guarantee on every exit path (normal
end, exception, cancellation): the valve controller is entered last, so it exits first
and sends ALL_OFF before anything else is torn down.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass

from drivers.aurora import AuroraTimeoutError
from drivers.aurora.client import AuroraTracker
from drivers.imu import AsyncIcm20948, Icm20948, ImuPairFusion, sample_rate_divider_for
from drivers.valve.client import ValveController, ValveTimeoutError
from drivers.transport import TransportOpenError

from ..config import SIM, RigConfig
from ..errors import UserError
from ..profile import RigProfile
from .clock import Clock
from .simulated_rig import SimulatedDevices, simulated_devices

# (level, source, message), as `Session.event` takes them.
EventSink = Callable[[str, str, str], None]


@dataclass(frozen=True)
class ImuPair:
    """The base and tip ICM-20948s (gyro bias estimated when the profile asks, then
    queueing every sample in their FIFOs) and the fusion of their samples."""

    base: AsyncIcm20948
    tip: AsyncIcm20948
    fusion: ImuPairFusion


@dataclass(frozen=True)
class Rig:
    """Open devices. imus: None when the profile has no IMU bus; simulated: the twin and
    emulators behind the emulated devices, None on an all-real rig."""

    valves: ValveController
    tracker: AuroraTracker
    imus: ImuPair | None
    simulated: SimulatedDevices | None


async def _nothing() -> None:
    return None


def _ignore(level: str, source: str, message: str) -> None:
    return None


@contextlib.asynccontextmanager
async def open_rig(profile: RigProfile, settings: RigConfig, clock: Clock, *, seed: int | None = None,
                   before_arming: Callable[[], Awaitable[None]] = _nothing,
                   on_event: EventSink = _ignore) -> AsyncIterator[Rig]:
    """Open tracker and IMUs, await ``before_arming`` (anything slow that must not run
    with the valves armed), then arm the valves and yield the `Rig`. seed: the digital
    twin's noise seed (default: the profile's); on_event: one line per device opened."""
    transports = settings.transports
    async with contextlib.AsyncExitStack() as stack:
        simulated = None
        valves_url, tracker_url, imu_bus = transports.valves, transports.tracker, None
        if transports.simulated:
            simulated = await stack.enter_async_context(simulated_devices(profile, settings, clock, seed))
            valves_url = simulated.valves_url or valves_url
            tracker_url = simulated.tracker_url or tracker_url
            imu_bus = simulated.imu_bus
            on_event("info", "rig", f"simulated rig: {simulated.twin!r}")
        if imu_bus is None and transports.imu_bus != SIM:
            import smbus2  # only a real rig needs it

            try:
                imu_bus = stack.enter_context(smbus2.SMBus(transports.imu_bus))
            except OSError as error:
                raise UserError(f"{profile.source}: transports.imu_bus = {transports.imu_bus}: cannot open "
                                f"/dev/i2c-{transports.imu_bus}: {error.strerror or error} (is this the rig's "
                                'PC? imu_bus = "sim" emulates the IMUs)') from None
        tracker = AuroraTracker(tracker_url, list(settings.tracker.tools), use_tx=settings.tracker.use_tx,
                                clock=clock.now)
        await _open_port(stack, tracker, profile, "tracker", tracker_url)
        on_event("info", "tracker", f"tracking {', '.join(tracker.handles)} ({tracker.version_text.strip()[:40]})")
        imus = None if imu_bus is None else await _open_imus(imu_bus, settings, clock)
        if imus is not None:
            on_event("info", "imu", f"ICM-20948 at {settings.imu.base_address:#04x} and "
                     f"{settings.imu.tip_address:#04x} ready")
        await before_arming()
        valve_settings = settings.valves
        valves = ValveController(valves_url, calibrations=settings.valve_calibrations(),
                                 retries=valve_settings.retries,
                                 reply_timeout_s=valve_settings.reply_timeout_ms / 1000.0,
                                 heartbeat_interval_s=valve_settings.heartbeat_ms / 1000.0)
        # Entered last, so it exits first: ALL_OFF before anything else is torn down.
        await _open_port(stack, valves, profile, "valves", valves_url)
        on_event("info", "valves", "armed")
        yield Rig(valves, tracker, imus, simulated)


async def _open_port(stack: contextlib.AsyncExitStack, device, profile: RigProfile, key: str, url: str) -> None:
    """Enter ``device``; a port that cannot be opened at all (no such device, no
    permission) is the profile's ``transports.<key>`` to fix: said as one line naming
    them, like the IMU bus."""
    try:
        await stack.enter_async_context(device)
    except (AuroraTimeoutError, ValveTimeoutError) as error:
        # The port opened and nothing answers: another device's port, or one switched off.
        raise UserError(f"{profile.source}: transports.{key} = {url!r}: the port opened but {error} (is the "
                        "device on this port, and powered?)") from None
    except Exception as error:
        cause: BaseException | None = error
        while cause is not None and not isinstance(cause, TransportOpenError):
            cause = cause.__cause__
        if cause is None:
            raise
        raise UserError(f"{profile.source}: transports.{key} = {url!r}: {cause} (is this the rig's PC, and the "
                        f'device plugged in? {key} = "sim" emulates it)') from None


async def _open_imus(bus, settings: RigConfig, clock: Clock) -> ImuPair:
    imu = settings.imu
    # Both chips share one bus: one transfer at a time.
    lock = threading.Lock()
    chips = []
    for address, calibration in ((imu.base_address, imu.base.calibration()),
                                 (imu.tip_address, imu.tip.calibration())):
        driver = Icm20948(bus, address, clock=clock.now, calibration=calibration,
                          sample_rate_divider=sample_rate_divider_for(imu.rate_hz),
                          sleep=lambda seconds: time.sleep(seconds / clock.time_scale))
        chip = AsyncIcm20948(driver, bus_lock=lock)
        await chip.initialize()
        if imu.gyro_bias_samples:
            await chip.estimate_gyro_bias(imu.gyro_bias_samples)  # applied to the driver's calibration
        chips.append(chip)
    for chip in chips:  # together, so both queues start at the same sample
        await chip.enable_fifo()
    rate_hz = chips[0].driver.sample_rate_hz
    return ImuPair(chips[0], chips[1], ImuPairFusion(rate_hz, fusion=imu.fusion, gain=imu.madgwick_gain,
                                                     use_magnetometer=imu.use_magnetometer))
