"""Aurora codec: CRC check values, commands, text replies, PHSR, BX and TX frames, and
the incremental reply reader. Property tests: round trips; arbitrary bytes raise only
AuroraProtocolError."""

from __future__ import annotations

import contextlib
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.aurora.commands import Command, parse_command
from drivers.aurora.crc import crc16
from drivers.aurora.errors import AuroraProtocolError
from drivers.aurora.frames import (
    HandleStatus,
    ToolRecord,
    TrackingFrame,
    Transform,
    bx_total_length,
    decode_bx,
    decode_tx_text,
    encode_bx,
    encode_tx_text,
    parse_reply_option,
)
from drivers.aurora.replies import (
    DataReply,
    ErrorReply,
    OkayReply,
    PortHandleEntry,
    PortHandleList,
    ResetReply,
    decode_reply,
    encode_payload,
    encode_reply,
)
from drivers.aurora.stream import CommandSplitter, ReplyReader

PROPERTY = settings(max_examples=200, deadline=None)


# --- CRC --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "crc"),
    [(b"INIT:", 0xE3A5), (b"OKAY", 0xA896), (b"RESET", 0xBE6F), (b"VER:0", 0x65EE),
     # ndicapi's probe sends this one verbatim with CRC 0492
     (b"GETINFO:Features.Firmware.Version", 0x0492)],
)
def test_crc_check_values(text: bytes, crc: int) -> None:
    assert crc16(text) == crc


@given(st.binary(max_size=64), st.binary(max_size=64))
@PROPERTY
def test_crc_is_incremental_and_appending_it_gives_zero(a: bytes, b: bytes) -> None:
    assert crc16(b, crc16(a)) == crc16(a + b)
    # Appended little-endian, the CRC zeroes the register: BX relies on this.
    assert crc16(a + struct.pack("<H", crc16(a))) == 0


# --- commands -------------------------------------------------------------------


def test_command_encoding_matches_known_bytes() -> None:
    assert Command("INIT").encode() == b"INIT:E3A5\r"
    assert Command("VER", "0").encode() == b"VER:065EE\r"
    assert Command("BX", "0801").encode(with_crc=False) == b"BX 0801\r"
    assert Command("TSTART").encode(with_crc=False) == b"TSTART\r"


def test_parse_command_forms() -> None:
    assert parse_command(b"INIT:E3A5\r") == Command("INIT")
    assert parse_command(b"BX 0801\r") == Command("BX", "0801")
    assert parse_command(b"TSTOP") == Command("TSTOP")
    assert parse_command(b"PHRQ:*********1****" + f"{crc16(b'PHRQ:*********1****'):04X}".encode()) == Command(
        "PHRQ", "*********1****"
    )


@pytest.mark.parametrize(
    ("line", "code"),
    [(b"INIT:E3A6\r", 0x04), (b"INIT:\r", 0x04), (b"INIT:zzzz\r", 0x04), (b"\r", 0x01),
     (b"init:E3A5\r", 0x01), (b"\xffINIT\r", 0x01), (b"1NIT\r", 0x01)],
)
def test_parse_command_errors_carry_device_codes(line: bytes, code: int) -> None:
    with pytest.raises(AuroraProtocolError) as info:
        parse_command(line)
    assert info.value.device_error_code == code


names = st.from_regex(r"[A-Z][A-Z0-9]{0,7}", fullmatch=True)
params = st.text(alphabet=st.characters(min_codepoint=0x20, max_codepoint=0x7E), max_size=24)


@given(names, params, st.booleans())
@PROPERTY
def test_command_round_trip(name: str, parameters: str, with_crc: bool) -> None:
    command = Command(name, parameters)
    assert parse_command(command.encode(with_crc=with_crc)) == command


@given(st.binary(max_size=64))
@PROPERTY
def test_arbitrary_bytes_as_command_raise_only_protocol_error(data: bytes) -> None:
    with contextlib.suppress(AuroraProtocolError):
        parse_command(data)


# --- text replies -----------------------------------------------------------------


def test_reply_known_bytes() -> None:
    assert encode_reply(OkayReply()) == b"OKAYA896\r"
    assert encode_reply(ResetReply()) == b"RESETBE6F\r"
    assert decode_reply(b"OKAYA896\r") == OkayReply()
    assert decode_reply(b"RESETBE6F\r") == ResetReply()
    assert decode_reply(encode_payload("ERROR0C")) == ErrorReply(0x0C)
    with pytest.raises(AuroraProtocolError):
        decode_reply(b"OKAYA897\r")


payload_text = st.text(alphabet=st.characters(min_codepoint=0x20, max_codepoint=0x7E) | st.just("\n"), max_size=80)


@given(st.one_of(
    st.just(OkayReply()), st.just(ResetReply()), st.integers(0, 255).map(ErrorReply),
    payload_text.filter(lambda t: t not in ("OKAY", "RESET") and not (t.startswith("ERROR") and len(t) == 7))
    .map(DataReply),
))
@PROPERTY
def test_reply_round_trip(reply) -> None:
    assert decode_reply(encode_reply(reply)) == reply


@given(st.binary(max_size=64))
@PROPERTY
def test_arbitrary_bytes_as_reply_raise_only_protocol_error(data: bytes) -> None:
    with contextlib.suppress(AuroraProtocolError):
        decode_reply(data)


def test_data_reply_rejects_reserved_payloads() -> None:
    for text in ("OKAY", "RESET", "ERROR01", "a\rb"):
        with pytest.raises(AuroraProtocolError):
            DataReply(text)


# --- PHSR -----------------------------------------------------------------------


def test_phsr_known_text() -> None:
    listing = PortHandleList.from_text("020A0310B031")
    assert listing.entries == (PortHandleEntry(0x0A, 0x031), PortHandleEntry(0x0B, 0x031))
    assert listing.handles == (0x0A, 0x0B)
    assert PortHandleList.from_text("00") == PortHandleList()
    for bad in ("", "0", "010A03", "01ZZ031", "020A031"):
        with pytest.raises(AuroraProtocolError):
            PortHandleList.from_text(bad)


@given(st.lists(st.builds(PortHandleEntry, st.integers(0, 255), st.integers(0, 0xFFF)), max_size=10))
@PROPERTY
def test_phsr_round_trip(entries) -> None:
    listing = PortHandleList(tuple(entries))
    assert PortHandleList.from_text(listing.to_text()) == listing


@given(st.text(max_size=40))
@PROPERTY
def test_arbitrary_phsr_text_raises_only_protocol_error(text: str) -> None:
    with contextlib.suppress(AuroraProtocolError):
        PortHandleList.from_text(text)


# --- BX / TX frames ---------------------------------------------------------------

f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
u32 = st.integers(0, 0xFFFFFFFF)


@st.composite
def records(draw, transform_values) -> ToolRecord:
    handle = draw(st.integers(0, 255))
    status = draw(st.sampled_from(HandleStatus))
    if status is HandleStatus.DISABLED:
        return ToolRecord(handle, status)
    transform = draw(transform_values) if status is HandleStatus.VALID else None
    return ToolRecord(handle, status, transform, draw(u32), draw(u32))


bx_transforms = st.builds(Transform, st.tuples(f32, f32, f32, f32), st.tuples(f32, f32, f32), f32)


def _counts(digits: int, scale: float):
    return st.integers(-(10**digits - 1), 10**digits - 1).map(lambda n: n / scale)


tx_transforms = st.builds(
    Transform,
    st.tuples(*[_counts(5, 1e4)] * 4),
    st.tuples(*[_counts(6, 1e2)] * 3),
    _counts(5, 1e4),
)


@given(st.lists(records(bx_transforms), max_size=6), st.integers(0, 0xFFFF))
@PROPERTY
def test_bx_round_trip(tools, system_status: int) -> None:
    frame = TrackingFrame(tuple(tools), system_status)
    data = encode_bx(frame)
    assert bx_total_length(data[:6]) == len(data)
    assert decode_bx(data) == frame


@given(st.lists(records(tx_transforms), max_size=6), st.integers(0, 0xFFFF))
@PROPERTY
def test_tx_round_trip(tools, system_status: int) -> None:
    frame = TrackingFrame(tuple(tools), system_status)
    text = encode_tx_text(frame)
    assert decode_tx_text(text) == frame
    assert decode_reply(encode_payload(text)) == DataReply(text)


def _example_frame() -> TrackingFrame:
    return TrackingFrame(
        (
            ToolRecord(0x0A, HandleStatus.VALID, Transform((0.5, 0.5, -0.5, 0.5), (12.25, -3.5, -250.0), 0.375), 0x31, 7),
            ToolRecord(0x0B, HandleStatus.MISSING, None, 0x71, 7),
            ToolRecord(0x0C, HandleStatus.DISABLED),
        ),
        0x0010,
    )


def test_bx_layout_matches_the_api_guide() -> None:
    data = encode_bx(_example_frame())
    assert data[:2] == b"\xc4\xa5"
    (length, header_crc) = struct.unpack_from("<HH", data, 2)
    assert header_crc == crc16(data[:4])
    body = data[6:-2]
    assert len(body) == length == 1 + (2 + 32 + 8) + (2 + 8) + 2 + 2
    assert body[0] == 3 and body[1:3] == b"\x0a\x01"
    assert struct.unpack_from("<8f", body, 3) == (0.5, 0.5, -0.5, 0.5, 12.25, -3.5, -250.0, 0.375)
    assert struct.unpack_from("<II", body, 35) == (0x31, 7)
    assert body[43:45] == b"\x0b\x02" and body[53:55] == b"\x0c\x04"
    assert struct.unpack_from("<H", body, 55) == (0x0010,)
    assert struct.unpack_from("<H", data, len(data) - 2) == (crc16(body),)


def test_tx_layout_matches_the_api_guide() -> None:
    text = encode_tx_text(_example_frame())
    assert text == (
        "03"
        "0A+05000+05000-05000+05000+001225-000350-025000+03750" "00000031" "00000007\n"
        "0BMISSING" "00000071" "00000007\n"
        "0CDISABLED\n"
        "0010"
    )


def test_tx_rejects_unrepresentable_values() -> None:
    too_far = TrackingFrame((ToolRecord(1, HandleStatus.VALID, Transform((1, 0, 0, 0), (10000.0, 0, 0), 0), 0, 0),))
    with pytest.raises(AuroraProtocolError):
        encode_tx_text(too_far)


def test_bx_detects_corruption() -> None:
    data = bytearray(encode_bx(_example_frame()))
    for index in (2, 7, 20, len(data) - 1):
        corrupted = bytearray(data)
        corrupted[index] ^= 0x40
        with pytest.raises(AuroraProtocolError):
            decode_bx(bytes(corrupted))


@given(st.binary(max_size=120))
@PROPERTY
def test_arbitrary_bytes_as_bx_raise_only_protocol_error(data: bytes) -> None:
    with contextlib.suppress(AuroraProtocolError):
        decode_bx(data)


@given(st.binary(max_size=200).map(lambda b: b"\xc4\xa5" + b))
@PROPERTY
def test_arbitrary_bx_bodies_with_valid_crcs_raise_only_protocol_error(tail: bytes) -> None:
    body = tail[2:]
    header = b"\xc4\xa5" + struct.pack("<H", len(body))
    data = header + struct.pack("<H", crc16(header)) + body + struct.pack("<H", crc16(body))
    with contextlib.suppress(AuroraProtocolError):
        decode_bx(data)


@given(st.text(alphabet="0123456789ABCDEF+-MISNGDABLE\n", max_size=120) | st.text(max_size=60))
@PROPERTY
def test_arbitrary_tx_text_raises_only_protocol_error(text: str) -> None:
    with contextlib.suppress(AuroraProtocolError):
        decode_tx_text(text)


def test_reply_option() -> None:
    assert parse_reply_option("") == 0x0001
    assert parse_reply_option("0801") == 0x0801
    with pytest.raises(AuroraProtocolError):
        parse_reply_option("80")


# --- stream framing -------------------------------------------------------------


def test_reader_splits_text_replies_fed_byte_by_byte() -> None:
    reader = ReplyReader()
    stream = encode_reply(OkayReply()) + encode_payload("020A031")
    out = []
    for byte in stream:
        reader.feed(bytes([byte]))
        line = reader.next_text()
        if line is not None:
            out.append(decode_reply(line))
    assert out == [OkayReply(), DataReply("020A031")]


def test_reader_resyncs_binary_after_garbage() -> None:
    frame = encode_bx(_example_frame())
    error = encode_reply(ErrorReply(0x0C))
    reader = ReplyReader()
    reader.feed(b"\x00\xc4junk E" + frame[:10])
    assert reader.next_binary() is None
    reader.feed(frame[10:] + b"zz" + error)
    assert decode_bx(reader.next_binary()) == _example_frame()
    assert decode_reply(reader.next_binary()) == ErrorReply(0x0C)
    assert reader.next_binary() is None


def test_reader_rejects_bad_bx_header_then_recovers() -> None:
    frame = encode_bx(_example_frame())
    bad = bytearray(frame)
    bad[4] ^= 0xFF  # header CRC
    reader = ReplyReader()
    reader.feed(bytes(bad) + frame)
    with pytest.raises(AuroraProtocolError):
        reader.next_binary()
    assert decode_bx(reader.next_binary()) == _example_frame()


@given(st.lists(st.binary(max_size=40), max_size=8), st.booleans())
@PROPERTY
def test_reader_on_arbitrary_bytes_raises_only_protocol_error(chunks, binary: bool) -> None:
    reader = ReplyReader()
    for chunk in chunks:
        reader.feed(chunk)
        for _ in range(4):
            try:
                raw = reader.next_binary() if binary else reader.next_text()
            except AuroraProtocolError:
                continue
            if raw is None:
                break
            with contextlib.suppress(AuroraProtocolError):
                decode_bx(raw) if raw.startswith(b"\xc4\xa5") else decode_reply(raw)


def test_command_splitter() -> None:
    splitter = CommandSplitter(max_line=16)
    assert splitter.feed(b"INIT:E3") == []
    assert splitter.feed(b"A5\rBX 0801\rTS") == [b"INIT:E3A5", b"BX 0801"]
    assert splitter.feed(b"X" * 40) == []  # runaway line dropped
    assert splitter.feed(b"TSTART\r") == [b"TSTART"]
