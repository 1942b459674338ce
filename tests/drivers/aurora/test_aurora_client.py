"""AuroraTracker against a scripted mock (exact bytes), and against the emulator over
sim:// and a pty (one suite parametrised over the backends), including fault cases."""

from __future__ import annotations

import asyncio
import contextlib
import time

import numpy as np
import pytest
from aurora_testkit import HANDLES, POSES, SIM_BACKENDS, served, truth_mm

from drivers.aurora import (
    AuroraCommandError,
    AuroraConnectionError,
    AuroraEmulator,
    AuroraError,
    AuroraProtocolError,
    AuroraSetupError,
    AuroraTimeoutError,
    AuroraTracker,
    ToolStatus,
)
from drivers.aurora.commands import Command
from drivers.aurora.frames import HandleStatus, ToolRecord, TrackingFrame, Transform, encode_bx
from drivers.aurora.replies import ErrorReply, OkayReply, encode_payload, encode_reply
from drivers.plant import StaticPlant
from drivers.testing import FaultyTransport, ScriptedTransport
from drivers.transport import open_transport
from drivers.transport.sim import unregister_device
from hydrojet_bench.geometry import rotation_angle_deg

OKAY = b"OKAYA896\r"
# Short timeouts keep the timeout tests quick. In-process links (mock, sim) answer
# synchronously, so they can use them everywhere; a pty's emulator thread may be
# starved on a loaded machine, so pty runs get a generous one.
FAST = {"command_timeout_s": 0.3, "reset_timeout_s": 0.2}


def timeouts(backend: str) -> dict[str, float]:
    return {**FAST, "command_timeout_s": 2.0} if backend == "pty" else FAST


def cmd(text: str) -> bytes:
    name, _, params = text.partition(":")
    return Command(name, params).encode()


def data(text: str) -> bytes:
    return encode_payload(text)


def truth_frame(frame_number: int = 42) -> TrackingFrame:
    records = []
    for handle, sensor in HANDLES.items():
        q, p = POSES[sensor]
        transform = Transform(tuple(float(v) for v in q), tuple(float(v) * 1000 for v in p), 0.25)
        records.append(ToolRecord(handle, HandleStatus.VALID, transform, 0x31, frame_number))
    return TrackingFrame(tuple(records), 0)


def start_up_script() -> list[tuple[bytes, bytes]]:
    return [
        (b"INIT:E3A5\r", OKAY),
        (b"VER:065EE\r", data("Freeze Tag: scripted")),
        (cmd("COMM:50000"), OKAY),
        (cmd("PHSR:01"), data("00")),
        (cmd("PHSR:02"), data("020A0010B001")),
        (cmd("PINIT:0A"), OKAY),
        (cmd("PINIT:0B"), OKAY),
        (cmd("PHSR:02"), data("00")),
        (cmd("PHSR:03"), data("020A0110B011")),
        (cmd("PENA:0AD"), OKAY),
        (cmd("PENA:0BD"), OKAY),
        (cmd("PHSR:04"), data("020A0310B031")),
        (cmd("TSTART"), OKAY),
    ]


def check_poses_near_truth(frame, plant: StaticPlant, position_tol_mm: float, angle_tol_deg: float) -> None:
    assert frame.names == ("base", "tip")
    for name in ("base", "tip"):
        pose = frame[name]
        assert pose.status is ToolStatus.VALID
        q, p_mm = truth_mm(plant, name)
        assert np.linalg.norm(np.array(pose.position_mm) - p_mm) < position_tol_mm
        assert rotation_angle_deg(pose.orientation, q) < angle_tol_deg
        assert pose.rms_error_mm is not None and pose.rms_error_mm >= 0


@contextlib.asynccontextmanager
async def tracker_on(backend: str, emulator: AuroraEmulator, **kwargs):
    async with served(emulator, backend) as url:
        async with AuroraTracker(url, ["base", "tip"], **{**timeouts(backend), **kwargs}) as tracker:
            yield tracker


# --- one suite over every backend ------------------------------------------------


@pytest.mark.parametrize("backend", ["mock", *SIM_BACKENDS])
def test_start_up_and_read_a_frame(run_async, plant, backend: str) -> None:
    async def main() -> None:
        if backend == "mock":
            script = [*start_up_script(), (cmd("BX:0801"), encode_bx(truth_frame())), (cmd("TSTOP"), OKAY)]
            transport = ScriptedTransport(script)
            async with AuroraTracker(transport, ["base", "tip"]) as tracker:
                frame = await tracker.read_frame()
            transport.assert_done()
            tolerance = (1e-3, 1e-3)
        else:
            emulator = AuroraEmulator(plant, tools=HANDLES)
            async with tracker_on(backend, emulator) as tracker:
                frame = await tracker.read_frame()
                assert "Freeze Tag:" in tracker.version_text
            assert emulator.mode == "setup"  # TSTOP went out on close
            assert list(emulator.command_log)[-1] == "TSTOP:"
            tolerance = (0.48 * 5, 0.70 * 5)  # five sigma of the emulated noise
        assert tracker.handles == {"base": 0x0A, "tip": 0x0B}
        check_poses_near_truth(frame, plant, *tolerance)

    run_async(main)


@pytest.mark.parametrize("backend", SIM_BACKENDS)
def test_frames_stream_new_frame_numbers(run_async, plant, backend: str) -> None:
    async def main() -> None:
        emulator = AuroraEmulator(plant, tools=HANDLES)
        async with tracker_on(backend, emulator) as tracker:
            numbers = []
            async with contextlib.aclosing(tracker.frames()) as stream:
                async for frame in stream:
                    numbers.append(frame.frame_number)
                    assert frame["tip"].frame_number == frame.frame_number
                    if len(numbers) == 4:
                        break
        assert numbers == sorted(set(numbers))

    run_async(main)


@pytest.mark.parametrize("backend", SIM_BACKENDS)
def test_tx_mode_matches_bx(run_async, plant, backend: str) -> None:
    async def main() -> None:
        emulator = AuroraEmulator(plant, tools=HANDLES, position_noise_mm=0, orientation_noise_deg=0)
        async with tracker_on(backend, emulator, use_tx=True) as tracker:
            frame = await tracker.read_frame()
        assert "TX:0801" in emulator.command_log
        check_poses_near_truth(frame, plant, 0.01, 0.02)  # TX resolution: 0.01 mm, 1e-4

    run_async(main)


@pytest.mark.parametrize("backend", SIM_BACKENDS)
def test_corrupt_reply_is_retried(run_async, plant, backend: str) -> None:
    async def main() -> None:
        emulator = AuroraEmulator(plant, tools=HANDLES)
        async with tracker_on(backend, emulator) as tracker:
            emulator.corrupt_next_reply()
            frame = await tracker.read_frame()
            check_poses_near_truth(frame, plant, 2.4, 3.5)
            assert tracker.stats["retries"] == 1

    run_async(main)


@pytest.mark.parametrize("backend", SIM_BACKENDS)
def test_persistently_corrupt_replies_raise_a_typed_error(run_async, plant, backend: str) -> None:
    async def main() -> None:
        emulator = AuroraEmulator(plant, tools=HANDLES)
        async with tracker_on(backend, emulator, retries=2) as tracker:
            emulator.corrupt_next_reply(3)
            with pytest.raises(AuroraProtocolError):
                await tracker.read_frame()
            assert tracker.stats["retries"] == 2
            await tracker.read_frame()  # the link is still usable afterwards
        assert emulator.mode == "setup"

    run_async(main)


@pytest.mark.parametrize("backend", SIM_BACKENDS)
def test_missing_out_of_volume_and_field_generator_faults(run_async, plant, backend: str) -> None:
    async def main() -> None:
        emulator = AuroraEmulator(plant, tools=HANDLES)
        async with tracker_on(backend, emulator) as tracker:
            emulator.set_tool_missing("tip")
            frame = await tracker.read_frame()
            assert frame["tip"].status is ToolStatus.MISSING and not frame["tip"].has_pose
            assert frame["base"].status is ToolStatus.VALID
            emulator.set_tool_missing("tip", False)

            emulator.set_out_of_volume("base")
            frame = await tracker.read_frame()  # BX:0801 still reports the pose
            assert frame["base"].status is ToolStatus.OUT_OF_VOLUME and frame["base"].has_pose
            emulator.set_out_of_volume("base", False)

            emulator.set_field_generator_connected(False)
            frame = await tracker.read_frame()
            assert frame.hardware_failure
            assert {p.status for p in frame.poses} == {ToolStatus.MISSING}
            emulator.set_field_generator_connected(True)
            frame = await tracker.read_frame()
            assert not frame.hardware_failure and frame["tip"].status is ToolStatus.VALID

    run_async(main)


@pytest.mark.parametrize("backend", SIM_BACKENDS)
def test_cancel_while_streaming_stops_tracking(run_async, plant, backend: str) -> None:
    async def main() -> None:
        emulator = AuroraEmulator(plant, tools=HANDLES)
        async with served(emulator, backend) as url:
            seen = []

            async def consume() -> None:
                async with AuroraTracker(url, ["base", "tip"], **timeouts(backend)) as tracker:
                    async with contextlib.aclosing(tracker.frames()) as stream:
                        async for frame in stream:
                            seen.append(frame)

            task = asyncio.create_task(consume(), name="aurora-consumer")
            while len(seen) < 2:
                await asyncio.sleep(0.01)
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
            assert emulator.mode == "setup"

    run_async(main)


@pytest.mark.parametrize("backend", SIM_BACKENDS)
def test_exception_inside_the_block_stops_tracking(run_async, plant, backend: str) -> None:
    async def main() -> None:
        emulator = AuroraEmulator(plant, tools=HANDLES)
        with pytest.raises(RuntimeError, match="bench fault"):
            async with tracker_on(backend, emulator) as tracker:
                await tracker.read_frame()
                raise RuntimeError("bench fault")
        assert emulator.mode == "setup"

    run_async(main)


@pytest.mark.parametrize("backend", SIM_BACKENDS)
def test_tool_names(run_async, plant, backend: str) -> None:
    async def main() -> None:
        emulator = AuroraEmulator(plant, tools=HANDLES)
        async with served(emulator, backend) as url:
            async with AuroraTracker(url, {"tip": 0x0B}, **timeouts(backend)) as tracker:
                frame = await tracker.read_frame()
                assert frame.names == ("tip",)
            async with AuroraTracker(url, None, **timeouts(backend)) as tracker:
                assert tracker.handles == {"tool_0A": 0x0A, "tool_0B": 0x0B}
            with pytest.raises(AuroraSetupError):
                await AuroraTracker(url, ["base", "tip", "elbow"], **timeouts(backend)).open()
            with pytest.raises(AuroraSetupError):
                await AuroraTracker(url, {"tip": 0x0C}, **timeouts(backend)).open()
            assert emulator.mode == "setup"

    run_async(main)


@pytest.mark.parametrize("backend", SIM_BACKENDS)
def test_field_generator_off_at_start_up(run_async, plant, backend: str) -> None:
    async def main() -> None:
        emulator = AuroraEmulator(plant, tools=HANDLES)
        emulator.set_field_generator_connected(False)
        async with served(emulator, backend) as url:
            tracker = AuroraTracker(url, ["base", "tip"], **timeouts(backend))
            with pytest.raises(AuroraCommandError) as info:
                await tracker.open()
            assert info.value.code == 0x13
            with pytest.raises(AuroraError, match="not tracking"):
                await tracker.read_frame()  # open failed and closed the port

    run_async(main)


# --- sim-only faults (baud rates, line faults, disconnects) ----------------------


def test_recovers_a_device_left_at_115200_with_a_break(run_async, plant) -> None:
    async def main() -> None:
        emulator = AuroraEmulator(plant, tools=HANDLES)
        async with served(emulator, "sim") as url:
            async with AuroraTracker(url, ["base", "tip"], **FAST) as tracker:
                await tracker.read_frame()
                assert tracker.stats["resets"] == 0
            assert emulator.baud_rate == 115200  # the device stays at the working rate
            async with AuroraTracker(url, ["base", "tip"], **FAST) as tracker:
                await tracker.read_frame()
                assert tracker.stats["resets"] == 1  # INIT at 9600 failed; break; RESET

    run_async(main)


def test_noisy_split_line(run_async, plant) -> None:
    async def main() -> None:
        emulator = AuroraEmulator(plant, tools=HANDLES)
        async with served(emulator, "sim") as url:
            link = FaultyTransport(open_transport(url), corrupt=0.003, split=True, seed=11)
            async with AuroraTracker(link, ["base", "tip"], retries=6, **FAST) as tracker:
                for _ in range(20):
                    frame = await tracker.read_frame()
                    check_poses_near_truth(frame, plant, 2.4, 3.5)
            assert link.stats["corrupted_bytes"] > 0 and link.stats["split_reads"] > 0
            assert tracker.stats["retries"] > 0

    run_async(main, timeout_s=30)


@pytest.mark.parametrize("after_bytes", [30, 150, 2000])  # during INIT/VER, during COMM..., tracking
def test_disconnect_raises_connection_error(run_async, plant, after_bytes: int) -> None:
    async def main() -> None:
        emulator = AuroraEmulator(plant, tools=HANDLES)
        async with served(emulator, "sim") as url:
            link = FaultyTransport(open_transport(url), disconnect_after=after_bytes)
            with pytest.raises(AuroraConnectionError):
                async with AuroraTracker(link, ["base", "tip"], **FAST) as tracker:
                    for _ in range(100):
                        await tracker.read_frame()
            assert link.stats["disconnects"] == 1

    run_async(main)


def test_device_vanishing_raises_connection_error(run_async, plant) -> None:
    async def main() -> None:
        emulator = AuroraEmulator(plant, tools=HANDLES)
        async with served(emulator, "sim") as url:
            async with AuroraTracker(url, ["base", "tip"], **FAST) as tracker:
                await tracker.read_frame()
                unregister_device(url.removeprefix("sim://"))
                with pytest.raises(AuroraConnectionError):
                    await tracker.read_frame()

    run_async(main)


def test_silent_device_times_out(run_async, plant) -> None:
    async def main() -> None:
        emulator = AuroraEmulator(plant, tools=HANDLES)
        async with served(emulator, "sim") as url:
            link = FaultyTransport(open_transport(url), drop=1.0, direction="rx")
            started = time.monotonic()
            with pytest.raises(AuroraTimeoutError):
                await AuroraTracker(link, ["base", "tip"], retries=1, **FAST).open()
            assert time.monotonic() - started < 5.0  # bounded, never a hang

    run_async(main)


# --- pty-only: the emulator goes away; reconnecting ------------------------------


def test_pty_reconnect_and_server_gone(run_async, plant) -> None:
    async def main() -> None:
        emulator = AuroraEmulator(plant, tools=HANDLES)
        async with served(emulator, "pty") as url:
            for _ in range(2):  # the pty stays usable across client sessions
                async with AuroraTracker(url, ["base", "tip"], **timeouts("pty")) as tracker:
                    await tracker.read_frame()
            tracker = AuroraTracker(url, ["base", "tip"], **timeouts("pty"))
            await tracker.open()
        # The server (and its pty) closed under an open tracker.
        try:
            with pytest.raises(AuroraConnectionError):
                await tracker.read_frame()
        finally:
            await tracker.close()

    run_async(main)


# --- mock-only: exact bytes of retries, errors and resets ------------------------


def test_mock_error_reply_is_a_typed_error(run_async) -> None:
    async def main() -> None:
        script = start_up_script()[:5] + [(cmd("PINIT:0A"), encode_reply(ErrorReply(0x13)))]
        transport = ScriptedTransport(script)
        with pytest.raises(AuroraCommandError) as info:
            await AuroraTracker(transport, ["base", "tip"]).open()
        assert info.value.code == 0x13 and "PINIT:0A" in str(info.value)
        transport.assert_done()

    run_async(main)


def test_mock_corrupt_then_good_reply(run_async) -> None:
    async def main() -> None:
        good = encode_bx(truth_frame())
        bad = good[:-1] + bytes([good[-1] ^ 0x01])
        script = [*start_up_script(), (cmd("BX:0801"), bad), (cmd("BX:0801"), good),
                  (cmd("BX:0801"), encode_reply(ErrorReply(0x04))), (cmd("BX:0801"), good), (cmd("TSTOP"), OKAY)]
        transport = ScriptedTransport(script)
        async with AuroraTracker(transport, ["base", "tip"], **FAST) as tracker:
            assert (await tracker.read_frame()).frame_number == 42
            assert (await tracker.read_frame()).frame_number == 42
            assert tracker.stats["retries"] == 2
        transport.assert_done()

    run_async(main)


def test_mock_no_reply_times_out_after_bounded_retries(run_async) -> None:
    async def main() -> None:
        script = [*start_up_script(), *[(cmd("BX:0801"), b"")] * 3, (cmd("TSTOP"), OKAY)]
        transport = ScriptedTransport(script)
        async with AuroraTracker(transport, ["base", "tip"], retries=2, **FAST) as tracker:
            with pytest.raises(AuroraTimeoutError):
                await tracker.read_frame()
        transport.assert_done()

    run_async(main)


def test_mock_init_unanswered_then_break_and_reset(run_async) -> None:
    async def main() -> None:
        script = [(b"INIT:E3A5\r", b""), (b"INIT:E3A5\r", OKAY), *start_up_script()[1:], (cmd("TSTOP"), OKAY)]
        transport = ScriptedTransport(script)
        async with AuroraTracker(transport, ["base", "tip"], **FAST) as tracker:
            assert tracker.stats["resets"] == 1
        transport.assert_done()

    run_async(main)


def test_mock_lost_tstart_reply_is_not_fatal(run_async) -> None:
    async def main() -> None:
        script = [*start_up_script()[:-1], (cmd("TSTART"), b"garbage\r"),
                  (cmd("TSTART"), encode_reply(ErrorReply(0x0C))), (cmd("TSTOP"), b""), (cmd("TSTOP"), OKAY)]
        transport = ScriptedTransport(script)
        async with AuroraTracker(transport, ["base", "tip"], **FAST):
            pass  # TSTART's first reply was garbled; the retry's ERROR0C means "already tracking"
        transport.assert_done()

    run_async(main)


def test_mock_garbled_comm_reply_probes_the_new_rate(run_async) -> None:
    async def main() -> None:
        script = [*start_up_script()[:2], (cmd("COMM:50000"), b"OK\x00Y\r"), (b"INIT:E3A5\r", OKAY),
                  *start_up_script()[3:], (cmd("TSTOP"), OKAY)]
        transport = ScriptedTransport(script)
        async with AuroraTracker(transport, ["base", "tip"], **FAST):
            pass
        transport.assert_done()

    run_async(main)


def test_constructor_validates() -> None:
    with pytest.raises(ValueError):
        AuroraTracker("sim://x", baud=12345)
    with pytest.raises(ValueError):
        AuroraTracker("ftp://x")
    with pytest.raises(ValueError):
        AuroraTracker("sim://x", "tip")


def test_okay_reply_constant_matches_codec() -> None:
    assert encode_reply(OkayReply()) == OKAY
