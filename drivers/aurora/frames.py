"""Tracking frames: the BX (binary) and TX (text) replies, reply option 0x0001.

Both carry, per port handle, a status and for a valid tool a transform (unit quaternion
q0 qx qy qz = (w, x, y, z) rotating tool-frame vectors into the tracker frame,
translation of the tool origin in the tracker frame in mm, RMS fit error in mm), then
the 32-bit port status and frame number; finally the 16-bit system status.

BX layout (little-endian; NDI Aurora API Guide, ndicapi ndiBXHelper/ndiSerialRead):
``C4 A5`` | uint16 body length | uint16 CRC of the first 4 header bytes |
body: uint8 handle count, per handle uint8 handle, uint8 status (1 valid, 2 missing,
4 disabled), [valid: 8 x float32], [not disabled: uint32 port status, uint32 frame],
..., uint16 system status | uint16 CRC of the body.

TX layout (ndicapi ndiTXHelper): ``NN`` handle count (hex), per handle ``HH`` then either
a 51-char transform (4 x 6 chars quaternion, sign + 5 digits, x 1e-4; 3 x 7 chars
position, sign + 6 digits, x 0.01 mm; 6 chars error, sign + 5 digits, x 1e-4 mm) or
``MISSING`` or ``DISABLED``; a valid or missing handle then has 8 hex port status and
8 hex frame number; each handle ends with LF; then 4 hex system status.
"""

from __future__ import annotations

import math
import re
import struct
from dataclasses import dataclass
from enum import IntEnum, IntFlag

from drivers.aurora.crc import crc16
from drivers.aurora.errors import AuroraProtocolError

BX_START = b"\xc4\xa5"  # 0xA5C4 little-endian
BX_HEADER_LEN = 6


class ReplyOption(IntFlag):
    """BX/TX reply option bits this driver understands."""

    TRANSFORMS = 0x0001
    OUT_OF_VOLUME = 0x0800  # also report tools outside the characterised volume


class HandleStatus(IntEnum):
    """Per-handle status byte of a BX frame (TX spells MISSING / DISABLED)."""

    VALID = 0x01
    MISSING = 0x02
    DISABLED = 0x04


class SystemStatus(IntFlag):
    """System status bits of BX/TX frames (ndicapi.h NDI_* system status)."""

    COMM_SYNC_ERROR = 0x0001
    COMM_CRC_ERROR = 0x0004
    RECOVERABLE_EXCEPTION = 0x0008
    HARDWARE_FAILURE = 0x0010  # the emulator raises this when the field generator drops
    HARDWARE_CHANGE = 0x0020
    PORT_OCCUPIED = 0x0040
    PORT_UNOCCUPIED = 0x0080


@dataclass(frozen=True)
class Transform:
    """A tool pose: ``quaternion`` (w, x, y, z), tool -> tracker frame;
    ``translation_mm`` tool origin in the tracker frame (mm); ``rms_error_mm``."""

    quaternion: tuple[float, float, float, float]
    translation_mm: tuple[float, float, float]
    rms_error_mm: float

    def __post_init__(self) -> None:
        if len(self.quaternion) != 4 or len(self.translation_mm) != 3:
            raise AuroraProtocolError("transform needs 4 quaternion and 3 translation values")


@dataclass(frozen=True)
class ToolRecord:
    """One handle of a frame. ``transform`` is present iff VALID; ``port_status`` and
    ``frame_number`` are present iff not DISABLED (the device sends none for disabled)."""

    handle: int
    status: HandleStatus
    transform: Transform | None = None
    port_status: int | None = None
    frame_number: int | None = None

    def __post_init__(self) -> None:
        if not 0 <= self.handle <= 0xFF:
            raise AuroraProtocolError(f"port handle out of range: {self.handle}")
        if (self.transform is not None) != (self.status is HandleStatus.VALID):
            raise AuroraProtocolError(f"handle {self.handle:02X}: transform iff VALID")
        has_counters = self.port_status is not None and self.frame_number is not None
        if has_counters != (self.status is not HandleStatus.DISABLED):
            raise AuroraProtocolError(f"handle {self.handle:02X}: port status and frame iff not DISABLED")
        if has_counters and not (0 <= self.port_status <= 0xFFFFFFFF and 0 <= self.frame_number <= 0xFFFFFFFF):  # type: ignore[operator]
            raise AuroraProtocolError(f"handle {self.handle:02X}: counters out of range")


@dataclass(frozen=True)
class TrackingFrame:
    """A whole BX or TX reply: one record per handle and the 16-bit system status."""

    tools: tuple[ToolRecord, ...]
    system_status: int = 0

    def __post_init__(self) -> None:
        if len(self.tools) > 0xFF or not 0 <= self.system_status <= 0xFFFF:
            raise AuroraProtocolError("frame has too many handles or a bad system status")

    def tool(self, handle: int) -> ToolRecord | None:
        for record in self.tools:
            if record.handle == handle:
                return record
        return None


def parse_reply_option(params: str) -> int:
    """Reply option of a BX/TX command's parameter string (4 hex; empty = 0x0001)."""
    if params == "":
        return int(ReplyOption.TRANSFORMS)
    if not re.fullmatch(r"[0-9A-Fa-f]{4}", params):
        raise AuroraProtocolError(f"reply option must be 4 hex digits: {params!r}", 0x07)
    return int(params, 16)


# --- BX -----------------------------------------------------------------------------

_F32X8 = struct.Struct("<8f")
_U32X2 = struct.Struct("<II")


def encode_bx(frame: TrackingFrame) -> bytes:
    """Wire bytes of a BX reply (option 0x0001 layout)."""
    body = bytearray([len(frame.tools)])
    for record in frame.tools:
        body += bytes([record.handle, int(record.status)])
        if record.transform is not None:
            t = record.transform
            try:
                body += _F32X8.pack(*t.quaternion, *t.translation_mm, t.rms_error_mm)
            except OverflowError:
                raise AuroraProtocolError("transform value does not fit a float32") from None
        if record.status is not HandleStatus.DISABLED:
            body += _U32X2.pack(record.port_status, record.frame_number)
    body += struct.pack("<H", frame.system_status)
    if len(body) > 0xFFFF:
        raise AuroraProtocolError("BX body too long")
    header = BX_START + struct.pack("<H", len(body))
    return header + struct.pack("<H", crc16(header)) + bytes(body) + struct.pack("<H", crc16(body))


def bx_total_length(header: bytes) -> int:
    """Total reply length (header + body + CRC) announced by a 6-byte BX header;
    checks the start sequence and the header CRC."""
    if len(header) < BX_HEADER_LEN or header[:2] != BX_START:
        raise AuroraProtocolError("not a BX header")
    (length, header_crc) = struct.unpack_from("<HH", header, 2)
    if crc16(header[:4]) != header_crc:
        raise AuroraProtocolError("BX header CRC mismatch")
    return BX_HEADER_LEN + length + 2


def decode_bx(data: bytes) -> TrackingFrame:
    """Parse one complete BX reply (option 0x0001 layout), checking both CRCs."""
    total = bx_total_length(data)
    if len(data) != total:
        raise AuroraProtocolError(f"BX reply is {len(data)} bytes, header says {total}")
    body = data[BX_HEADER_LEN:-2]
    (body_crc,) = struct.unpack_from("<H", data, total - 2)
    if crc16(body) != body_crc:
        raise AuroraProtocolError("BX body CRC mismatch")
    try:
        return _decode_bx_body(body)
    except struct.error:
        raise AuroraProtocolError("BX body truncated") from None


# A dict lookup: calling the enum costs several times more, at 1000 frames a wall second.
_HANDLE_STATUS = {int(status): status for status in HandleStatus}


def _decode_bx_body(body: bytes) -> TrackingFrame:
    if not body:
        raise AuroraProtocolError("BX body is empty")
    count = body[0]
    pos = 1
    tools = []
    for _ in range(count):
        handle, status_byte = struct.unpack_from("<BB", body, pos)
        pos += 2
        status = _HANDLE_STATUS.get(status_byte)
        if status is None:
            raise AuroraProtocolError(f"handle {handle:02X}: unknown status {status_byte:#x}")
        transform = None
        port_status = frame_number = None
        if status is HandleStatus.VALID:
            values = _F32X8.unpack_from(body, pos)
            pos += _F32X8.size
            transform = Transform(tuple(values[0:4]), tuple(values[4:7]), values[7])  # type: ignore[arg-type]
        if status is not HandleStatus.DISABLED:
            port_status, frame_number = _U32X2.unpack_from(body, pos)
            pos += _U32X2.size
        tools.append(ToolRecord(handle, status, transform, port_status, frame_number))
    (system_status,) = struct.unpack_from("<H", body, pos)
    pos += 2
    if pos != len(body):
        raise AuroraProtocolError(f"BX body has {len(body) - pos} trailing bytes")
    return TrackingFrame(tuple(tools), system_status)


# --- TX -----------------------------------------------------------------------------

QUATERNION_SCALE = 1e4  # TX quaternion components are integers x 1e-4
POSITION_SCALE = 1e2  # TX positions are integers x 0.01 mm
ERROR_SCALE = 1e4  # TX RMS error is an integer x 1e-4 mm


def _signed(value: float, scale: float, digits: int) -> str:
    if not math.isfinite(value):
        raise AuroraProtocolError(f"TX cannot encode {value}")
    count = round(value * scale)
    if abs(count) >= 10**digits:
        raise AuroraProtocolError(f"TX value {value} does not fit {digits} digits")
    return f"{'-' if count < 0 else '+'}{abs(count):0{digits}d}"


def _parse_signed(text: str, scale: float) -> float:
    if not re.fullmatch(r"[+-][0-9]+", text):
        raise AuroraProtocolError(f"TX number malformed: {text!r}")
    return int(text) / scale


def encode_tx_text(frame: TrackingFrame) -> str:
    """Payload of a TX reply (option 0x0001 layout); wrap with replies.encode_payload."""
    parts = [f"{len(frame.tools):02X}"]
    for record in frame.tools:
        parts.append(f"{record.handle:02X}")
        if record.status is HandleStatus.DISABLED:
            parts.append("DISABLED\n")
            continue
        if record.transform is None:
            parts.append("MISSING")
        else:
            t = record.transform
            parts.extend(_signed(v, QUATERNION_SCALE, 5) for v in t.quaternion)
            parts.extend(_signed(v, POSITION_SCALE, 6) for v in t.translation_mm)
            parts.append(_signed(t.rms_error_mm, ERROR_SCALE, 5))
        parts.append(f"{record.port_status:08X}{record.frame_number:08X}\n")
    parts.append(f"{frame.system_status:04X}")
    return "".join(parts)


_HEX_FIELD = re.compile(r"[0-9A-Fa-f]+\Z")


def _hex(text: str, width: int, what: str) -> int:
    if len(text) != width or not _HEX_FIELD.match(text):
        raise AuroraProtocolError(f"TX {what} malformed: {text!r}")
    return int(text, 16)


def decode_tx_text(text: str) -> TrackingFrame:
    """Parse the payload of a TX reply (option 0x0001 layout)."""
    count = _hex(text[:2], 2, "handle count")
    pos = 2
    tools = []
    for _ in range(count):
        end = text.find("\n", pos)
        if end < 0:
            raise AuroraProtocolError("TX handle record lacks its LF")
        record_text, pos = text[pos:end], end + 1
        tools.append(_decode_tx_record(record_text))
    system_status = _hex(text[pos:], 4, "system status")
    return TrackingFrame(tuple(tools), system_status)


def _decode_tx_record(text: str) -> ToolRecord:
    handle = _hex(text[:2], 2, "handle")
    rest = text[2:]
    if rest == "DISABLED":
        return ToolRecord(handle, HandleStatus.DISABLED)
    if rest.startswith("MISSING"):
        status, transform, counters = HandleStatus.MISSING, None, rest[7:]
    else:
        if len(rest) < 51:
            raise AuroraProtocolError(f"TX transform of handle {handle:02X} too short")
        fields = [rest[i : i + 6] for i in range(0, 24, 6)]
        fields += [rest[i : i + 7] for i in range(24, 45, 7)]
        fields.append(rest[45:51])
        quaternion = tuple(_parse_signed(f, QUATERNION_SCALE) for f in fields[0:4])
        translation = tuple(_parse_signed(f, POSITION_SCALE) for f in fields[4:7])
        error = _parse_signed(fields[7], ERROR_SCALE)
        transform = Transform(quaternion, translation, error)  # type: ignore[arg-type]
        status, counters = HandleStatus.VALID, rest[51:]
    port_status = _hex(counters[:8], 8, "port status")
    frame_number = _hex(counters[8:], 8, "frame number")
    return ToolRecord(handle, status, transform, port_status, frame_number)
