"""The simulated rig: the digital twin behind the byte-level emulators.

One `DigitalTwin` (from the profile's ``[twin]`` table) is the truth for all three
emulators, seen through `SessionPlant` at *session* time. The valve emulator keeps its
watchdog on the wall clock (it is the firmware's own safety, see `bench.clock`); the
Aurora's 40 Hz frame counter and the IMUs' sample instants follow session time.

Per the profile's ``[transports]``: ``"sim"`` registers the emulator as an in-process
``sim://`` device (no thread; the drivers' full codec path still runs); ``"pty"`` serves it
on a pseudo-terminal from a thread, so the serial transport runs too. The IMU pair is an
SMBus-compatible object either way.
"""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.aurora.emulator import AuroraEmulator
from drivers.imu.emulator import Icm20948BusEmulator
from drivers.plant import SensorTruth
from drivers.transport.pty import PtyServer
from drivers.transport.sim import serve_sim
from drivers.valve.emulator import ValveEmulator

from ..config import PTY, SIM, RigConfig
from ..profile import RigProfile
from ..twin import DigitalTwin, TwinConfig
from .clock import Clock

_instances = itertools.count()


class SessionPlant:
    """`drivers.plant.Plant` over a twin at session time. The tracker and IMU emulators run
    on the session clock, so their instants pass through (an IMU FIFO asks for instants
    a little in the past); the valve emulator runs on the wall clock (its watchdog), so
    its commands are stamped with session time here."""

    def __init__(self, twin: DigitalTwin, clock: Clock) -> None:
        self.twin = twin
        self.clock = clock
        self.gravity_in_tracker_m_s2 = twin.gravity_in_tracker_m_s2
        self.magnetic_field_in_tracker_ut = twin.magnetic_field_in_tracker_ut

    def sensor_truth(self, sensor: str, t_s: float) -> SensorTruth:
        return self.twin.sensor_truth(sensor, t_s)

    def sensor_truths(self, sensor: str, t_s: np.ndarray) -> SensorTruth:
        return self.twin.sensor_truths(sensor, t_s)

    def apply_valve_duties(self, duties_permille: Sequence[int], t_s: float) -> None:
        self.twin.apply_valve_duties(duties_permille, self.clock.now())


@dataclass
class SimulatedDevices:
    """Where the session's drivers find the emulated devices."""

    twin: DigitalTwin
    valves_url: str | None
    tracker_url: str | None
    imu_bus: Any | None
    valve_emulator: ValveEmulator | None
    aurora_emulator: AuroraEmulator | None


@contextlib.asynccontextmanager
async def simulated_devices(profile: RigProfile, settings: RigConfig, clock: Clock,
                            seed: int | None = None) -> AsyncIterator[SimulatedDevices]:
    """Build the twin and serve an emulator for every device the profile marks "sim" or
    "pty"; the others keep their URLs (a session may mix real and emulated devices)."""
    config = TwinConfig.from_profile(profile) if seed is None else TwinConfig.from_profile(profile, seed=seed)
    twin = DigitalTwin(config)
    plant = SessionPlant(twin, clock)
    transports = settings.transports
    suffix = next(_instances)
    async with contextlib.AsyncExitStack() as stack:
        valve_emulator = aurora_emulator = None
        valves_url = tracker_url = None
        if transports.valves in (SIM, PTY):
            # Not shut down on exit: like the real board it keeps whatever the host left it
            # with, so a test can see that the host closed the valves itself.
            valve_emulator = ValveEmulator(plant, watchdog_s=settings.valves.watchdog_ms / 1000.0)
            valves_url = await _serve(stack, transports.valves, f"valves-{suffix}", valve_emulator)
        if transports.tracker in (SIM, PTY):
            tools = {0x0A + index: name for index, name in enumerate(settings.tracker.tools)}
            # The twin's [twin.noise] is the tracker's: the emulator adds it to the truth.
            aurora_emulator = AuroraEmulator(plant, clock.now, tools, seed=config.seed,
                                             position_noise_mm=config.noise.em_position_rms_m * 1000.0,
                                             orientation_noise_deg=config.noise.em_orientation_rms_deg)
            tracker_url = await _serve(stack, transports.tracker, f"aurora-{suffix}", aurora_emulator)
        imu_bus = None
        if transports.imu_bus == SIM:
            # No task samples the chips between reads: each FIFO read makes the records of
            # the instants since the last in one batch (0.1-0.2 ms for 5 samples of both
            # chips on a slow host). Sampling every two periods beside the session cost
            # a fifth of the IMU rate it could keep at 25x.
            imu_bus = Icm20948BusEmulator(plant, clock.now, sensors={settings.imu.base_address: "base",
                                                                     settings.imu.tip_address: "tip"},
                                          seed=config.seed)
        yield SimulatedDevices(twin, valves_url, tracker_url, imu_bus, valve_emulator, aurora_emulator)


async def _serve(stack: contextlib.AsyncExitStack, mode: str, name: str, emulator: Any) -> str:
    if mode == SIM:
        return await stack.enter_async_context(serve_sim(name, emulator))
    server = PtyServer(emulator, poll_interval_s=0.005, name=name).start()
    stack.callback(server.stop)
    return f"pty://{server.path}"

