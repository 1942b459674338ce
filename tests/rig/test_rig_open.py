"""`open_rig` on the simulated rig: every device opened per the profile, the slow
preparation done before the valves are armed, and the valves closed on every exit."""

from __future__ import annotations

import contextlib

import msgspec
import pytest

from hydrojet_bench.bench.clock import ScaledClock
from hydrojet_bench.bench.rig import open_rig
from hydrojet_bench.profile import load_profile


class Unplugged(Exception):
    """Stands for whatever goes wrong while the rig is open."""


@pytest.mark.parametrize("failure", [None, Unplugged])
def test_open_rig_arms_the_valves_last_and_closes_them_on_exit(run_async, failure):
    profile = load_profile("sim")
    settings = profile.config
    # The valves are under test, not the watchdog: a loaded machine may stall the loop
    # past the firmware's 0.5 s, which would close the jet for the wrong reason.
    settings = msgspec.structs.replace(settings, valves=msgspec.structs.replace(settings.valves, watchdog_ms=60_000.0))
    sources: list[str] = []

    async def before_arming() -> None:
        sources.append("before_arming")

    async def check():
        opened = None
        with contextlib.suppress(Unplugged):
            async with open_rig(profile, settings, ScaledClock(settings.session.time_scale), seed=3, before_arming=before_arming,
                                on_event=lambda level, source, message: sources.append(source)) as rig:
                opened = rig
                assert rig.imus is not None and rig.simulated is not None
                frame = await rig.tracker.read_frame()
                assert frame["base"].has_pose and frame["tip"].has_pose
                await rig.valves.set_forces_n((0.05, 0.0, 0.0))
                assert rig.simulated.valve_emulator.duties_permille[0] > 0
                if failure is not None:
                    raise failure("tracker cable pulled")
        return opened

    rig = run_async(check, timeout_s=60.0)
    assert sources == ["rig", "tracker", "imu", "before_arming", "valves"]
    assert rig.simulated.valve_emulator.duties_permille == (0, 0, 0)
    assert not rig.simulated.twin.jet_forces_n.any()


# The tracker takes the same path (an AuroraTimeoutError after its resets: 9 s of retries).
@pytest.mark.parametrize("key", ["valves"])
def test_a_port_where_nothing_answers_is_named_by_its_profile_key(run_async, key):
    import os

    from hydrojet_bench.errors import UserError

    # A terminal nobody listens on: the port opens, no device replies (a wrong port, or
    # the device switched off).
    listener, silent = os.openpty()
    try:
        profile = load_profile("sim")
        url = f"pty://{os.ttyname(silent)}"
        # A real device runs on wall time; no gyro-bias wait at that pace before the valves.
        settings = msgspec.structs.replace(
            profile.config, transports=msgspec.structs.replace(profile.config.transports, **{key: url}),
            session=msgspec.structs.replace(profile.config.session, time_scale=1.0),
            imu=msgspec.structs.replace(profile.config.imu, gyro_bias_samples=0))

        async def check():
            async with open_rig(profile, settings, ScaledClock(1.0)):
                pass

        with pytest.raises(UserError) as info:
            run_async(check, timeout_s=60.0)
    finally:
        os.close(listener)
        os.close(silent)
    message = str(info.value)
    assert message.startswith(f"{profile.source}: transports.{key} = {url!r}: the port opened but "), message
    assert message.endswith("(is the device on this port, and powered?)") and "\n" not in message
