"""The valve codec: golden bytes, round trips, garbage and corruption resync."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.valve.protocol import (
    CRC_LEN,
    HEADER_LEN,
    MAX_PAYLOAD,
    SOF,
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
    ValveProtocolError,
    crc16_ccitt_false,
    decode_frame,
    decode_message,
    encode_frame,
    encode_message,
    message_to_frame,
)

SETTINGS = settings(max_examples=200, deadline=None)
# One longest frame's worth of zero bytes: enough to disprove any false LEN.
IDLE = bytes(HEADER_LEN + MAX_PAYLOAD + CRC_LEN)

duty = st.integers(0, 1000)
duties = st.tuples(duty, duty, duty)
faults = st.sampled_from([FaultFlags(0), FaultFlags.WATCHDOG])
messages = st.one_of(
    st.builds(Ping),
    st.builds(Arm),
    st.builds(AllOff),
    st.builds(GetStatus),
    st.builds(SetDuty, st.integers(0, 2), duty),
    st.builds(SetAll, duties),
    st.builds(Ack, st.sampled_from([Command.ARM, Command.SET_DUTY, Command.SET_ALL, Command.ALL_OFF])),
    st.builds(PingAck, st.booleans(), faults),
    st.builds(
        StatusReport,
        st.booleans(),
        faults,
        duties,
        st.tuples(st.integers(0, 255), st.integers(0, 255)),
        st.integers(0, 0xFFFF),
        st.integers(0, 0xFFFF),
    ),
    st.builds(Nak, st.integers(0, 255), st.sampled_from(list(NakCode))),
)
frames = st.builds(
    Frame, st.integers(0, 255), st.integers(0, 255), st.binary(max_size=MAX_PAYLOAD)
)


def test_crc_is_ccitt_false() -> None:
    assert crc16_ccitt_false(b"123456789") == 0x29B1
    assert crc16_ccitt_false(b"") == 0xFFFF


@pytest.mark.parametrize(
    ("seq", "message", "wire"),
    [
        (0x00, Arm(), "a5 00 00 02"),
        (0x07, SetAll((1, 2, 1000)), "a5 06 07 04 00 01 00 02 03 e8"),
        (0x10, SetDuty(2, 500), "a5 03 10 03 02 01 f4"),
        (0xFF, Nak(0x04, NakCode.NOT_ARMED), "a5 02 ff 81 04 04"),
        (0x01, PingAck(True, FaultFlags.WATCHDOG), "a5 03 01 80 01 01 01"),
    ],
)
def test_golden_frames(seq: int, message, wire: str) -> None:
    body = bytes.fromhex(wire)
    expected = body + crc16_ccitt_false(body[1:]).to_bytes(2, "big")
    assert encode_message(seq, message) == expected
    assert decode_message(decode_frame(expected)) == message


@SETTINGS
@given(st.integers(0, 255), messages)
def test_message_round_trip(seq: int, message) -> None:
    wire = encode_message(seq, message)
    frame = decode_frame(wire)
    assert frame.seq == seq
    assert decode_message(frame) == message


@SETTINGS
@given(frames)
def test_frame_round_trip(frame: Frame) -> None:
    assert decode_frame(encode_frame(frame)) == frame
    assert FrameDecoder().feed(encode_frame(frame)) == [frame]


@SETTINGS
@given(st.binary(max_size=64))
def test_arbitrary_bytes_raise_only_protocol_error(data: bytes) -> None:
    with contextlib.suppress(ValveProtocolError):
        decode_message(decode_frame(data))


@SETTINGS
@given(frames)
def test_arbitrary_frames_decode_or_raise_protocol_error(frame: Frame) -> None:
    try:
        message = decode_message(frame)
    except ValveProtocolError:
        return
    assert message_to_frame(frame.seq, message) == frame


@SETTINGS
@given(st.binary(max_size=256))
def test_stream_decoder_never_raises(data: bytes) -> None:
    decoder = FrameDecoder()
    for frame in decoder.feed(data):
        assert decode_frame(encode_frame(frame)) == frame
    assert decoder.pending <= 4 + MAX_PAYLOAD + 2


def _is_subsequence(wanted: list[Frame], got: list[Frame]) -> bool:
    it = iter(got)
    return all(any(g == w for g in it) for w in wanted)


@SETTINGS
@given(
    st.lists(st.tuples(st.binary(max_size=24), frames), min_size=1, max_size=6),
    st.binary(max_size=24),
    st.integers(1, 7),
)
def test_decoder_resyncs_after_garbage(chunks, tail: bytes, piece: int) -> None:
    # Garbage can hold a false SOF whose LEN swallows the next frame until later bytes
    # fail its CRC; IDLE supplies them.
    stream = b"".join(garbage + encode_frame(f) for garbage, f in chunks) + tail + IDLE
    decoder = FrameDecoder()
    got: list[Frame] = []
    for i in range(0, len(stream), piece):  # fed in small pieces, as a UART delivers
        got += decoder.feed(stream[i : i + piece])
    assert _is_subsequence([f for _, f in chunks], got)


@SETTINGS
@given(st.lists(frames, min_size=2, max_size=6), st.data())
def test_decoder_recovers_every_other_frame_after_a_corrupted_one(frame_list, data) -> None:
    encoded = [bytearray(encode_frame(f)) for f in frame_list]
    victim = data.draw(st.integers(0, len(encoded) - 1))
    pos = data.draw(st.integers(0, len(encoded[victim]) - 1))
    encoded[victim][pos] ^= data.draw(st.integers(1, 255))
    # A corrupted LEN makes the decoder wait for bytes that would disprove it; on a live
    # line later traffic (the heartbeat) supplies them, as IDLE does here.
    got = FrameDecoder().feed(b"".join(bytes(e) for e in encoded) + IDLE)
    others = [f for i, f in enumerate(frame_list) if i != victim]
    assert _is_subsequence(others, got)


def test_decoder_counts_bad_frames_and_resyncs_on_false_sof() -> None:
    good = encode_message(1, Ping())
    corrupted = bytearray(encode_message(2, SetAll((1, 2, 3))))
    corrupted[-1] ^= 0xFF
    decoder = FrameDecoder()
    # A false SOF with a huge LEN, a corrupted frame, then a good one split in two.
    frames_out = decoder.feed(bytes([SOF, 200, 0x11]) + bytes(corrupted) + good[:3])
    frames_out += decoder.feed(good[3:])
    assert frames_out == [Frame(1, Command.PING)]
    assert decoder.bad_frames == 2
    assert decoder.pending == 0


@pytest.mark.parametrize(
    ("frame", "code"),
    [
        (Frame(0, 0x42), NakCode.UNKNOWN_COMMAND),
        (Frame(0, Command.PING, b"\x00"), NakCode.BAD_LENGTH),
        (Frame(0, Command.SET_ALL, b"\x00" * 5), NakCode.BAD_LENGTH),
        (Frame(0, Command.SET_DUTY, bytes([3, 0, 1])), NakCode.BAD_VALUE),
        (Frame(0, Command.SET_DUTY, bytes([0, 0x03, 0xE9])), NakCode.BAD_VALUE),
        (Frame(0, Command.SET_ALL, bytes([0, 0, 0, 0, 0x03, 0xE9])), NakCode.BAD_VALUE),
    ],
)
def test_bad_requests_carry_the_nak_code(frame: Frame, code: NakCode) -> None:
    with pytest.raises(ValveProtocolError) as info:
        decode_message(frame)
    assert info.value.nak_code is code


def test_constructors_validate() -> None:
    with pytest.raises(ValueError, match="duties_permille"):
        SetAll((0, 0, 1001))
    with pytest.raises(ValueError, match="valve"):
        SetDuty(3, 0)
    with pytest.raises(ValueError, match="payload"):
        Frame(0, 1, bytes(17))
