"""ValveController over every backend: emulator on a sim link and on a pty, plus a
scripted mock for the exact bytes."""

from __future__ import annotations

import asyncio

import pytest

from valve_backends import emulator_backend, every_backend
from drivers.testing import ScriptedTransport
from drivers.transport import TransportClosed
from drivers.transport.handler import EmulatorHandler
from drivers.transport.sim import register_device, unregister_device
from drivers.valve import (
    JetCalibration,
    NakCode,
    ValveController,
    ValveFaultError,
    ValveNakError,
    ValveTimeoutError,
)
from drivers.valve.protocol import (
    Ack,
    AllOff,
    Arm,
    Command,
    FaultFlags,
    FrameDecoder,
    GetStatus,
    Nak,
    Ping,
    PingAck,
    SetAll,
    SetDuty,
    StatusReport,
    encode_message,
)

CALS = (
    JetCalibration.from_points([(0.0, 0), (0.1, 1000)]),
    JetCalibration.from_points([(0.0, 0), (0.01, 200), (0.2, 1000)]),
    JetCalibration.from_points([(0.0, 100), (0.05, 600)]),
)


# ------------------------------------------------------------------ every emulator backend


@every_backend
def test_open_arms_and_commands_reach_the_plant(run_async, backend: str) -> None:
    async def main() -> None:
        async with emulator_backend(backend) as bench:
            async with ValveController(bench.url, calibrations=CALS) as valves:
                assert bench.emulator.armed
                await valves.set_duties((100, 200, 300))
                assert bench.plant.valve_duties_permille == (100, 200, 300)
                await valves.set_duty(2, 1000)
                assert bench.plant.valve_duties_permille == (100, 200, 1000)
                sent = await valves.set_forces_n((0.05, 0.105, 1.0))
                assert sent == (500, 600, 600)
                assert bench.plant.valve_duties_permille == (500, 600, 600)
                status = await valves.status()
                assert status.armed and status.duties_permille == (500, 600, 600)
                assert status.firmware_version == (1, 0) and status.watchdog_ms == 500
                await valves.all_off()
                assert bench.plant.valve_duties_permille == (0, 0, 0)
                await valves.set_duties((1, 1, 1))
            assert bench.plant.valve_duties_permille == (0, 0, 0)  # ALL_OFF on exit
            assert valves.all_off_failure is None  # ...and acknowledged
            assert bench.emulator.watchdog_trips == 0

    run_async(main)


@every_backend
def test_heartbeat_keeps_the_watchdog_fed(run_async, backend: str) -> None:
    async def main() -> None:
        async with emulator_backend(backend, watchdog_s=0.15) as bench:
            async with ValveController(bench.url, heartbeat_interval_s=0.03) as valves:
                await valves.set_duties((300, 0, 0))
                await asyncio.sleep(0.6)  # four watchdog periods of host silence
                assert bench.emulator.watchdog_trips == 0
                assert bench.plant.valve_duties_permille == (300, 0, 0)
                assert (await valves.ping()).faults == FaultFlags(0)

    run_async(main)


@every_backend
def test_watchdog_fault_raises_typed_error_until_rearmed(run_async, backend: str) -> None:
    async def main() -> None:
        async with emulator_backend(backend, watchdog_s=0.1) as bench:
            async with ValveController(bench.url, heartbeat_interval_s=None) as valves:
                await valves.set_duties((400, 400, 400))
                await asyncio.sleep(0.3)  # no heartbeat: the firmware gives up on us
                assert bench.plant.valve_duties_permille == (0, 0, 0)
                with pytest.raises(ValveFaultError) as info:
                    await valves.set_duties((400, 400, 400))
                assert info.value.code is NakCode.WATCHDOG
                assert valves.faults == FaultFlags.WATCHDOG
                status = await valves.status()
                assert status.faults == FaultFlags.WATCHDOG and not status.armed
                await valves.arm()
                await valves.set_duties((10, 20, 30))
                assert bench.plant.valve_duties_permille == (10, 20, 30)

    run_async(main)


@every_backend
def test_exception_inside_the_block_still_closes_valves(run_async, backend: str) -> None:
    async def main() -> None:
        async with emulator_backend(backend) as bench:
            with pytest.raises(ZeroDivisionError):
                async with ValveController(bench.url) as valves:
                    await valves.set_duties((900, 900, 900))
                    assert bench.plant.valve_duties_permille == (900, 900, 900)
                    1 / 0  # noqa: B018
            assert bench.plant.valve_duties_permille == (0, 0, 0)
            assert bench.emulator.watchdog_trips == 0

    run_async(main)


@every_backend
def test_cancellation_inside_the_block_still_closes_valves(run_async, backend: str) -> None:
    async def main() -> None:
        async with emulator_backend(backend) as bench:
            opened = asyncio.Event()

            async def user() -> None:
                async with ValveController(bench.url) as valves:
                    await valves.set_duties((700, 700, 700))
                    opened.set()
                    await asyncio.sleep(30)

            task = asyncio.create_task(user())
            await asyncio.wait_for(opened.wait(), 5)
            assert bench.plant.valve_duties_permille == (700, 700, 700)
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
            assert bench.plant.valve_duties_permille == (0, 0, 0)

    run_async(main)


@every_backend
def test_timeout_cancellation_via_asyncio_timeout_closes_valves(run_async, backend: str) -> None:
    async def main() -> None:
        async with emulator_backend(backend) as bench:
            with pytest.raises(TimeoutError):
                async with asyncio.timeout(0.3):
                    async with ValveController(bench.url) as valves:
                        await valves.set_duties((1, 2, 3))
                        await asyncio.sleep(30)
            assert bench.plant.valve_duties_permille == (0, 0, 0)

    run_async(main)


@every_backend
def test_reopening_after_close_works(run_async, backend: str) -> None:
    async def main() -> None:
        async with emulator_backend(backend) as bench:
            for duty in (100, 200, 300):
                async with ValveController(bench.url) as valves:
                    await valves.set_duty(0, duty)
                    assert bench.plant.valve_duties_permille == (duty, 0, 0)
            assert [d for _, d in bench.plant.valve_history][-1] == (0, 0, 0)

    run_async(main)


@every_backend
def test_bad_arguments_raise_value_error_without_touching_the_device(run_async, backend: str) -> None:
    async def main() -> None:
        async with emulator_backend(backend) as bench:
            async with ValveController(bench.url) as valves:
                handled = bench.emulator.frames_handled
                with pytest.raises(ValueError, match="duties_permille"):
                    await valves.set_duties((0, 0, 1001))
                with pytest.raises(ValueError, match="3 duties"):
                    await valves.set_duties((0, 0))
                with pytest.raises(ValueError, match="valve"):
                    await valves.set_duty(3, 0)
                with pytest.raises(ValueError, match="calibrations"):
                    await valves.set_forces_n((0.0, 0.0, 0.0))
                assert bench.emulator.frames_handled - handled <= 1  # at most a heartbeat

    run_async(main)


# ------------------------------------------------------------------ unresponsive devices


class Silent(EmulatorHandler):
    def receive(self, data: bytes) -> bytes:
        return b""


class AlwaysNak(EmulatorHandler):
    def __init__(self, code: NakCode) -> None:
        self.code = code
        self.frames = 0

    def receive(self, data: bytes) -> bytes:
        out = b""
        for frame in FrameDecoder().feed(data):
            self.frames += 1
            out += encode_message(frame.seq, Nak(frame.command, self.code))
        return out


def test_silent_device_gives_timeout_error_not_a_hang(run_async) -> None:
    async def main() -> None:
        register_device("valve-silent", Silent())
        try:
            valves = ValveController("sim://valve-silent", retries=2, reply_timeout_s=0.02)
            with pytest.raises(ValveTimeoutError, match="no reply to ARM on sim://valve-silent after 3 attempts"):
                await valves.open()
            assert valves.timeouts >= 3  # ARM, then the ALL_OFF attempted on the way out
        finally:
            unregister_device("valve-silent")

    run_async(main)


def test_nak_is_retried_with_fresh_seq_then_raised(run_async) -> None:
    async def main() -> None:
        device = AlwaysNak(NakCode.BAD_VALUE)
        register_device("valve-nak", device)
        try:
            valves = ValveController("sim://valve-nak", retries=2, reply_timeout_s=0.05)
            with pytest.raises(ValveNakError) as info:
                await valves.open()
            assert info.value.code is NakCode.BAD_VALUE and info.value.command == Command.ARM
            assert device.frames == 3 + 3  # ARM x3, then ALL_OFF x3 on the way out
        finally:
            unregister_device("valve-nak")

    run_async(main)


def test_not_armed_nak_is_not_retried(run_async) -> None:
    async def main() -> None:
        device = AlwaysNak(NakCode.NOT_ARMED)
        register_device("valve-unarmed", device)
        try:
            valves = ValveController("sim://valve-unarmed", retries=5)
            with pytest.raises(ValveNakError) as info:
                await valves.open()
            assert info.value.code is NakCode.NOT_ARMED
            assert not isinstance(info.value, ValveFaultError)
            assert device.frames == 2  # one ARM, one ALL_OFF
        finally:
            unregister_device("valve-unarmed")

    run_async(main)


def test_device_vanishing_raises_transport_closed(run_async) -> None:
    async def main() -> None:
        async with emulator_backend("pty") as bench:
            valves = ValveController(bench.url, heartbeat_interval_s=0.02)
            await valves.open()
        # The pty server is gone: the heartbeat/reader see the hang-up.
        with pytest.raises(TransportClosed):
            async with asyncio.timeout(3):
                while True:
                    await valves.set_duties((0, 0, 0))
                    await asyncio.sleep(0.01)
        await valves.close()  # nothing to send to: closes quietly
        await valves.close()

    run_async(main)


def test_constructor_validates() -> None:
    with pytest.raises(ValueError, match="exactly one"):
        ValveController()
    with pytest.raises(ValueError, match="retries"):
        ValveController("sim://x", retries=-1)
    with pytest.raises(ValueError, match="reply_timeout_s"):
        ValveController("sim://x", reply_timeout_s=0)
    with pytest.raises(ValueError, match="heartbeat_interval_s"):
        ValveController("sim://x", heartbeat_interval_s=0)
    with pytest.raises(ValueError, match="calibrations"):
        ValveController("sim://x", calibrations=CALS[:2])
    with pytest.raises(ValueError, match="scheme"):
        ValveController("tcp://x")


# ------------------------------------------------------------------ scripted bytes (mock)


def test_mock_exact_bytes_of_a_session(run_async) -> None:
    script = [
        (encode_message(0, Arm()), encode_message(0, Ack(Command.ARM))),
        (encode_message(1, SetAll((0, 500, 1000))), encode_message(1, Ack(Command.SET_ALL))),
        (encode_message(2, SetDuty(1, 7)), encode_message(2, Ack(Command.SET_DUTY))),
        (
            encode_message(3, GetStatus()),
            encode_message(3, StatusReport(True, FaultFlags(0), (0, 7, 1000), (1, 0), 500, 0)),
        ),
        (encode_message(4, AllOff()), encode_message(4, Ack(Command.ALL_OFF))),
    ]
    mock = ScriptedTransport(script)

    async def main() -> None:
        async with ValveController(transport=mock, heartbeat_interval_s=None, initial_seq=0) as valves:
            await valves.set_duties((0, 500, 1000))
            await valves.set_duty(1, 7)
            assert (await valves.status()).duties_permille == (0, 7, 1000)
        mock.assert_done()

    run_async(main)


def test_mock_lost_reply_is_retried_with_the_same_seq(run_async) -> None:
    """A timeout re-sends the identical frame so the device can answer it from cache."""
    arm = encode_message(250, Arm())
    mock = ScriptedTransport(
        [
            (arm, b""),  # reply lost
            (arm, b"\x00\xa5\x99" + encode_message(250, Ack(Command.ARM))),  # after line noise
            (encode_message(251, AllOff()), encode_message(251, Ack(Command.ALL_OFF))),
        ]
    )

    async def main() -> None:
        valves = ValveController(
            transport=mock, heartbeat_interval_s=None, initial_seq=250, reply_timeout_s=0.05
        )
        await valves.open()
        await valves.close()
        assert valves.timeouts == 1
        mock.assert_done()

    run_async(main)


def test_mock_stale_and_mismatched_replies_are_ignored(run_async) -> None:
    mock = ScriptedTransport(
        [
            (
                encode_message(7, Arm()),
                encode_message(6, Ack(Command.ARM))  # wrong seq: an old reply
                + encode_message(7, Ack(Command.ALL_OFF))  # right seq, wrong command
                + encode_message(7, Ack(Command.ARM)),
            ),
            (encode_message(8, Ping()), encode_message(8, Nak(Command.PING, NakCode.BAD_LENGTH))),
            (encode_message(9, Ping()), encode_message(9, PingAck(True, FaultFlags(0)))),
            (encode_message(10, AllOff()), encode_message(10, Ack(Command.ALL_OFF))),
        ]
    )

    async def main() -> None:
        async with ValveController(transport=mock, heartbeat_interval_s=None, initial_seq=7) as valves:
            reply = await valves.ping()
            assert reply.armed
            assert valves.ignored_frames == 2
        mock.assert_done()

    run_async(main)


def test_mock_close_without_all_off_reply_raises_after_releasing(run_async) -> None:
    mock = ScriptedTransport(
        [
            (encode_message(0, Arm()), encode_message(0, Ack(Command.ARM))),
            *[(encode_message(1, AllOff()), b"")] * 2,
        ]
    )

    async def main() -> None:
        valves = ValveController(
            transport=mock, heartbeat_interval_s=None, initial_seq=0, retries=1, reply_timeout_s=0.02
        )
        await valves.open()
        with pytest.raises(ValveTimeoutError, match="ALL_OFF"):
            await valves.close()
        mock.assert_done()
        assert "ALL_OFF" in valves.all_off_failure  # said, for the session's log
        await valves.close()  # idempotent once closed

    run_async(main)
