"""The emulated firmware, byte for byte, on a fake clock."""

from __future__ import annotations

import pytest

from drivers.plant import StaticPlant
from drivers.valve.emulator import ValveEmulator
from drivers.valve.protocol import (
    Ack,
    AllOff,
    Arm,
    Command,
    FaultFlags,
    Frame,
    FrameDecoder,
    GetStatus,
    Nak,
    NakCode,
    Ping,
    PingAck,
    SetAll,
    SetDuty,
    StatusReport,
    decode_message,
    encode_frame,
    encode_message,
)


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def rig():
    clock = FakeClock()
    plant = StaticPlant()
    emulator = ValveEmulator(plant, clock=clock, watchdog_s=0.5)
    return emulator, plant, clock


def exchange(emulator: ValveEmulator, seq: int, message) -> list:
    replies = FrameDecoder().feed(emulator.receive(encode_message(seq, message)))
    assert all(r.seq == seq for r in replies)
    return [decode_message(r) for r in replies]


def test_boots_disarmed_and_refuses_set_until_armed(rig) -> None:
    emulator, plant, _ = rig
    assert exchange(emulator, 1, SetAll((1, 2, 3))) == [Nak(Command.SET_ALL, NakCode.NOT_ARMED)]
    assert exchange(emulator, 2, SetDuty(0, 5)) == [Nak(Command.SET_DUTY, NakCode.NOT_ARMED)]
    assert plant.valve_history == []
    assert exchange(emulator, 3, Arm()) == [Ack(Command.ARM)]
    assert exchange(emulator, 4, SetAll((1, 2, 3))) == [Ack(Command.SET_ALL)]
    assert exchange(emulator, 5, SetDuty(1, 999)) == [Ack(Command.SET_DUTY)]
    assert plant.valve_history == [(100.0, (1, 2, 3)), (100.0, (1, 999, 3))]


def test_status_and_ping_report_state(rig) -> None:
    emulator, _, _ = rig
    exchange(emulator, 1, Arm())
    exchange(emulator, 2, SetAll((10, 20, 30)))
    [status] = exchange(emulator, 3, GetStatus())
    assert status == StatusReport(True, FaultFlags(0), (10, 20, 30), (1, 0), 500, 0)
    assert exchange(emulator, 4, Ping()) == [PingAck(True, FaultFlags(0))]


def test_watchdog_closes_valves_latches_and_requires_arm(rig) -> None:
    emulator, plant, clock = rig
    exchange(emulator, 1, Arm())
    exchange(emulator, 2, SetAll((500, 600, 700)))
    clock.t += 0.499
    assert emulator.poll() == b""
    assert emulator.duties_permille == (500, 600, 700)
    clock.t += 0.001
    emulator.poll()
    assert emulator.duties_permille == (0, 0, 0)
    assert plant.valve_history[-1] == (100.5, (0, 0, 0))
    assert emulator.faults == FaultFlags.WATCHDOG and not emulator.armed
    assert exchange(emulator, 3, Ping()) == [PingAck(False, FaultFlags.WATCHDOG)]
    assert exchange(emulator, 4, SetAll((1, 1, 1))) == [Nak(Command.SET_ALL, NakCode.WATCHDOG)]
    assert exchange(emulator, 5, AllOff()) == [Ack(Command.ALL_OFF)]  # always accepted
    assert exchange(emulator, 6, Arm()) == [Ack(Command.ARM)]
    assert emulator.faults == FaultFlags(0)
    assert emulator.duties_permille == (0, 0, 0)  # re-arming does not reopen anything
    assert exchange(emulator, 7, SetAll((1, 1, 1))) == [Ack(Command.SET_ALL)]
    assert emulator.watchdog_trips == 1


def test_overdue_watchdog_trips_before_a_late_frame_is_handled(rig) -> None:
    """Without any poll, a frame arriving after the period meets a tripped device."""
    emulator, plant, clock = rig
    exchange(emulator, 1, Arm())
    exchange(emulator, 2, SetAll((500, 0, 0)))
    clock.t += 2.0
    assert exchange(emulator, 3, SetAll((600, 0, 0))) == [Nak(Command.SET_ALL, NakCode.WATCHDOG)]
    assert plant.valve_history[-1] == (102.0, (0, 0, 0))


def test_valid_frames_feed_the_watchdog_and_garbage_does_not(rig) -> None:
    emulator, _, clock = rig
    exchange(emulator, 1, Arm())
    for seq in range(2, 12):
        clock.t += 0.4
        exchange(emulator, seq, Ping())
        emulator.poll()
    assert emulator.armed
    clock.t += 0.4
    emulator.receive(b"\x00\xa5\x03garbage" + bytes(20))
    clock.t += 0.2
    emulator.poll()
    assert not emulator.armed and emulator.faults == FaultFlags.WATCHDOG


def test_nakked_frames_still_feed_the_watchdog(rig) -> None:
    emulator, _, clock = rig
    exchange(emulator, 1, Arm())
    clock.t += 0.4
    replies = FrameDecoder().feed(emulator.receive(encode_frame(Frame(2, 0x42))))
    assert [decode_message(r) for r in replies] == [Nak(0x42, NakCode.UNKNOWN_COMMAND)]
    clock.t += 0.4
    emulator.poll()
    assert emulator.armed


def test_watchdog_idle_while_disarmed(rig) -> None:
    emulator, plant, clock = rig
    clock.t += 10
    emulator.poll()
    assert emulator.faults == FaultFlags(0) and plant.valve_history == []


def test_duplicate_frame_is_reacked_not_reexecuted(rig) -> None:
    emulator, plant, _ = rig
    exchange(emulator, 1, Arm())
    frame = encode_message(2, SetDuty(0, 400))
    reply = emulator.receive(frame)
    assert reply == encode_message(2, Ack(Command.SET_DUTY))
    handled, history = emulator.frames_handled, list(plant.valve_history)
    for _ in range(3):  # the host missed the ACK and retries the same frame
        assert emulator.receive(frame) == reply
    assert emulator.frames_handled == handled and emulator.duplicates == 3
    assert plant.valve_history == history


def test_only_the_last_frame_is_cached(rig) -> None:
    """A host retries only its current frame, so one cached frame is enough; an older
    frame sent again is a new command (and, being absolute, does not compound)."""
    emulator, _, _ = rig
    exchange(emulator, 1, Arm())
    exchange(emulator, 2, SetDuty(0, 400))
    exchange(emulator, 3, AllOff())
    exchange(emulator, 2, SetDuty(0, 400))
    assert emulator.duties_permille == (400, 0, 0) and emulator.duplicates == 0


def test_same_seq_different_content_is_a_new_frame(rig) -> None:
    emulator, _, _ = rig
    exchange(emulator, 1, Arm())
    exchange(emulator, 9, SetDuty(0, 100))
    exchange(emulator, 9, SetDuty(0, 200))
    assert emulator.duties_permille == (200, 0, 0)


def test_retry_after_watchdog_trip_is_refused_not_reacked(rig) -> None:
    emulator, _, clock = rig
    exchange(emulator, 1, Arm())
    exchange(emulator, 2, SetAll((500, 500, 500)))
    clock.t += 1.0
    emulator.poll()
    assert exchange(emulator, 2, SetAll((500, 500, 500))) == [Nak(Command.SET_ALL, NakCode.WATCHDOG)]
    assert emulator.duties_permille == (0, 0, 0)


@pytest.mark.parametrize(
    ("frame", "code"),
    [
        (Frame(1, 0x42), NakCode.UNKNOWN_COMMAND),
        (Frame(1, Command.ACK, bytes([Command.PING])), NakCode.UNKNOWN_COMMAND),
        (Frame(1, Command.ARM, b"\x01"), NakCode.BAD_LENGTH),
        (Frame(1, Command.SET_DUTY, bytes([7, 0, 1])), NakCode.BAD_VALUE),
        (Frame(1, Command.SET_ALL, bytes([0, 1, 0, 1, 0x27, 0x10])), NakCode.BAD_VALUE),
    ],
)
def test_bad_requests_are_nakked_with_their_code(rig, frame: Frame, code: NakCode) -> None:
    emulator, plant, _ = rig
    exchange(emulator, 0, Arm())
    replies = FrameDecoder().feed(emulator.receive(encode_frame(frame)))
    assert [decode_message(r) for r in replies] == [Nak(frame.command, code)]
    assert plant.valve_history == []


def test_exactly_one_reply_per_valid_frame_in_a_noisy_split_stream(rig) -> None:
    emulator, _, _ = rig
    bad = bytearray(encode_message(50, Ping()))
    bad[4] ^= 0x10
    stream = (
        b"\xff\xa5" + encode_message(1, Arm()) + bytes(bad) + encode_message(2, SetAll((5, 6, 7)))
        + b"\xa5\x30" + encode_message(3, GetStatus())
    )
    out = b"".join(emulator.receive(stream[i : i + 3]) for i in range(0, len(stream), 3))
    replies = FrameDecoder().feed(out)
    assert [r.seq for r in replies] == [1, 2, 3]
    status = decode_message(replies[-1])
    assert isinstance(status, StatusReport)
    assert status.duties_permille == (5, 6, 7)
    assert status.rx_errors == emulator.rx_errors >= 2


def test_plant_hears_only_changes_and_shutdown(rig) -> None:
    emulator, plant, _ = rig
    exchange(emulator, 1, Arm())
    exchange(emulator, 2, SetAll((5, 5, 5)))
    exchange(emulator, 3, SetAll((5, 5, 5)))
    exchange(emulator, 4, SetDuty(0, 5))
    exchange(emulator, 5, AllOff())
    exchange(emulator, 6, AllOff())
    assert [d for _, d in plant.valve_history] == [(5, 5, 5), (0, 0, 0)]
    exchange(emulator, 7, SetAll((1, 0, 0)))
    emulator.shutdown()
    assert plant.valve_duties_permille == (0, 0, 0) and not emulator.armed


def test_watchdog_period_is_validated() -> None:
    with pytest.raises(ValueError, match="watchdog_s"):
        ValveEmulator(StaticPlant(), watchdog_s=0.0)
    with pytest.raises(ValueError, match="watchdog_s"):
        ValveEmulator(StaticPlant(), watchdog_s=100.0)
