"""Wire protocol of the HydroJet solenoid valve controller (firmware 1.0): a pure codec.

The controller drives three solenoid valves (one per water jet) with PWM duty in per mille
(0 = closed, 1000 = fully open). Host and device exchange the same frame format over a
UART at 115200 8N1 (the Arduino sketch in ``drivers/valve/firmware/`` and the Python
emulator implement the device side byte for byte).

Frame
-----
::

    +------+-----+-----+-----+-------------------+-----------+
    | SOF  | LEN | SEQ | CMD | PAYLOAD (LEN B)   | CRC16 (BE)|
    | 0xA5 | u8  | u8  | u8  | 0..16 bytes       | 2 bytes   |
    +------+-----+-----+-----+-------------------+-----------+

* CRC: CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, not reflected, no final xor;
  check value of ASCII "123456789" is 0x29B1) over LEN, SEQ, CMD and PAYLOAD; sent
  most significant byte first. All multi-byte integers are big-endian.
* No byte stuffing. The receiver resyncs by length + CRC: it hunts for SOF, rejects a
  header whose LEN exceeds 16, and on a CRC mismatch discards only that SOF byte and
  hunts again from the next byte, so garbage or a corrupted frame costs at most the
  frames it overlaps.
* A frame that fails framing or CRC is not a frame: no reply, but the device counts it
  (``rx_errors`` in STATUS) and it does not feed the watchdog.

Commands (host -> device) and replies
-------------------------------------
Every valid frame gets exactly one reply carrying the request's SEQ: ACK (0x80, payload
= acked CMD + data) or NAK (0x81, payload = CMD + code).

====  ========  ===================================  ==================================
CMD   name      payload                              ACK data
====  ========  ===================================  ==================================
0x01  PING      -                                    state u8, faults u8
0x02  ARM       -                                    -
0x03  SET_DUTY  valve u8 (0..2), duty u16 (0..1000)  -
0x04  SET_ALL   3 x duty u16 (0..1000)               -
0x05  ALL_OFF   -                                    -
0x06  STATUS    -                                    state u8, faults u8, 3 x duty u16,
                                                     fw major u8, fw minor u8,
                                                     watchdog_ms u16, rx_errors u16
====  ========  ===================================  ==================================

state bit 0 = ARMED. faults bit 0 = WATCHDOG (latched).

NAK codes: 0x01 BAD_LENGTH (payload length wrong for CMD), 0x02 UNKNOWN_COMMAND,
0x03 BAD_VALUE (valve index or duty out of range; nothing is applied), 0x04 NOT_ARMED
(SET before the first ARM), 0x05 WATCHDOG (SET while the watchdog fault is latched).

Device behaviour (the firmware state machine)
---------------------------------------------
* Boot: disarmed, all valves closed, no fault.
* ARM: arms, clears a latched WATCHDOG fault; valves stay as they are (closed after a
  trip). SET_DUTY / SET_ALL are refused (NAK NOT_ARMED or WATCHDOG) unless armed.
  ALL_OFF, PING, STATUS and ARM are always accepted.
* Watchdog: while armed, if no valid frame arrived for ``watchdog_ms`` (default 500),
  the device closes all valves, disarms and latches WATCHDOG. Any valid frame (even one
  that is NAKed) feeds it, so a host idling between commands sends PING well inside the
  period.
* Duplicates: a host that got no reply re-sends the same frame with the same SEQ. The
  device remembers the last frame (SEQ, CMD, PAYLOAD) and its reply; an identical frame
  is answered with the remembered reply and not executed again. A watchdog trip forgets
  the remembered frame, so a retry that arrives after a trip is executed afresh (and
  refused) instead of being ACKed for duties that the trip has already closed. All
  commands are absolute (idempotent) anyway, so re-execution would never compound.
* The host starts SEQ anywhere and increments it (mod 256) for every new frame.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from enum import IntEnum, IntFlag

SOF = 0xA5
MAX_PAYLOAD = 16
HEADER_LEN = 4  # SOF, LEN, SEQ, CMD
CRC_LEN = 2
VALVE_COUNT = 3
DUTY_MAX_PERMILLE = 1000
FIRMWARE_VERSION = (1, 0)
DEFAULT_WATCHDOG_MS = 500


class ValveProtocolError(ValueError):
    """Bytes or values that are not valid in the valve protocol.

    nak_code: the NAK the device answers for this problem when it is a request that
    framed correctly (None for framing/CRC errors, which get no reply).
    """

    def __init__(self, message: str, nak_code: NakCode | None = None) -> None:
        super().__init__(message)
        self.nak_code = nak_code


class Command(IntEnum):
    PING = 0x01
    ARM = 0x02
    SET_DUTY = 0x03
    SET_ALL = 0x04
    ALL_OFF = 0x05
    STATUS = 0x06
    ACK = 0x80
    NAK = 0x81


class NakCode(IntEnum):
    BAD_LENGTH = 0x01
    UNKNOWN_COMMAND = 0x02
    BAD_VALUE = 0x03
    NOT_ARMED = 0x04
    WATCHDOG = 0x05


class StateFlags(IntFlag):
    ARMED = 0x01


class FaultFlags(IntFlag):
    WATCHDOG = 0x01


_STATE_MASK = int(StateFlags.ARMED)
_FAULT_MASK = int(FaultFlags.WATCHDOG)


def crc16_ccitt_false(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, MSB first, no final xor."""
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


# ---------------------------------------------------------------------------- frames


@dataclass(frozen=True)
class Frame:
    """One frame: seq 0..255, command 0..255, payload of at most 16 bytes."""

    seq: int
    command: int
    payload: bytes = b""

    def __post_init__(self) -> None:
        if not 0 <= self.seq <= 0xFF:
            raise ValveProtocolError(f"seq must be 0..255, got {self.seq}")
        if not 0 <= self.command <= 0xFF:
            raise ValveProtocolError(f"command must be 0..255, got {self.command}")
        if len(self.payload) > MAX_PAYLOAD:
            raise ValveProtocolError(f"payload is {len(self.payload)} bytes, max {MAX_PAYLOAD}")


def encode_frame(frame: Frame) -> bytes:
    body = bytes((len(frame.payload), frame.seq, frame.command)) + bytes(frame.payload)
    return bytes((SOF,)) + body + crc16_ccitt_false(body).to_bytes(2, "big")


def decode_frame(data: bytes) -> Frame:
    """Decode exactly one complete frame; raises ValveProtocolError otherwise."""
    data = bytes(data)
    if len(data) < HEADER_LEN + CRC_LEN:
        raise ValveProtocolError(f"frame too short: {len(data)} bytes")
    if data[0] != SOF:
        raise ValveProtocolError(f"frame starts with 0x{data[0]:02X}, not SOF 0x{SOF:02X}")
    length = data[1]
    if length > MAX_PAYLOAD:
        raise ValveProtocolError(f"LEN {length} exceeds {MAX_PAYLOAD}")
    if len(data) != HEADER_LEN + length + CRC_LEN:
        raise ValveProtocolError(
            f"frame is {len(data)} bytes, LEN {length} needs {HEADER_LEN + length + CRC_LEN}"
        )
    body, crc = data[1:-CRC_LEN], int.from_bytes(data[-CRC_LEN:], "big")
    if crc16_ccitt_false(body) != crc:
        raise ValveProtocolError(f"CRC mismatch: got 0x{crc:04X}, want 0x{crc16_ccitt_false(body):04X}")
    return Frame(seq=data[2], command=data[3], payload=bytes(data[HEADER_LEN:-CRC_LEN]))


class FrameDecoder:
    """Incremental decoder: feed any byte chunks, get whole valid frames out.

    Never raises on input: garbage and corrupted frames are skipped (length + CRC
    resync, see the module docstring) and counted in ``dropped_bytes`` / ``bad_frames``.
    """

    def __init__(self) -> None:
        self._buffer = bytearray()
        self.dropped_bytes = 0
        self.bad_frames = 0

    def feed(self, data: bytes) -> list[Frame]:
        """Add bytes; return every frame they complete, in order."""
        return list(self.iter_feed(data))

    def iter_feed(self, data: bytes) -> Iterator[Frame]:
        """Like `feed`, but yields each frame as soon as it is found, so counters
        (``bad_frames``) seen at each yield cover only the bytes before that frame, as
        on a device that handles each frame before reading on. Consume it fully."""
        self._buffer += data
        buf = self._buffer
        while buf:
            start = buf.find(SOF)
            if start < 0:
                self.dropped_bytes += len(buf)
                buf.clear()
                break
            if start:
                self.dropped_bytes += start
                del buf[:start]
            if len(buf) < 2:
                break
            length = buf[1]
            if length > MAX_PAYLOAD:
                self._skip_sof()
                continue
            total = HEADER_LEN + length + CRC_LEN
            if len(buf) < total:
                break
            body = bytes(buf[1 : total - CRC_LEN])
            crc = int.from_bytes(buf[total - CRC_LEN : total], "big")
            if crc16_ccitt_false(body) != crc:
                self._skip_sof()
                continue
            del buf[:total]
            yield Frame(seq=body[1], command=body[2], payload=body[3:])

    def _skip_sof(self) -> None:
        # Drop only the SOF we trusted: a real frame may start inside the bytes after it.
        self.bad_frames += 1
        self.dropped_bytes += 1
        del self._buffer[:1]

    @property
    def pending(self) -> int:
        """Bytes held waiting for the rest of a possible frame."""
        return len(self._buffer)

    def reset(self) -> None:
        self._buffer.clear()


# -------------------------------------------------------------------------- messages


def _check_duty(duty: int, what: str) -> None:
    if isinstance(duty, bool) or not isinstance(duty, int) or not 0 <= duty <= DUTY_MAX_PERMILLE:
        raise ValveProtocolError(
            f"{what} must be an int in 0..{DUTY_MAX_PERMILLE} per mille, got {duty!r}",
            NakCode.BAD_VALUE,
        )


def _check_duties(duties: tuple[int, ...], what: str) -> None:
    if len(duties) != VALVE_COUNT:
        raise ValveProtocolError(f"{what} needs {VALVE_COUNT} duties, got {len(duties)}", NakCode.BAD_VALUE)
    for i, d in enumerate(duties):
        _check_duty(d, f"{what}[{i}]")


@dataclass(frozen=True)
class Ping:
    pass


@dataclass(frozen=True)
class Arm:
    pass


@dataclass(frozen=True)
class SetDuty:
    """valve: 0..2 (jet index); duty_permille: 0..1000."""

    valve: int
    duty_permille: int

    def __post_init__(self) -> None:
        if isinstance(self.valve, bool) or not isinstance(self.valve, int) or not 0 <= self.valve < VALVE_COUNT:
            raise ValveProtocolError(f"valve must be 0..{VALVE_COUNT - 1}, got {self.valve!r}", NakCode.BAD_VALUE)
        _check_duty(self.duty_permille, "duty_permille")


@dataclass(frozen=True)
class SetAll:
    """duties_permille: one duty 0..1000 per valve, in valve order."""

    duties_permille: tuple[int, int, int]

    def __post_init__(self) -> None:
        object.__setattr__(self, "duties_permille", tuple(self.duties_permille))
        _check_duties(self.duties_permille, "duties_permille")


@dataclass(frozen=True)
class AllOff:
    pass


@dataclass(frozen=True)
class GetStatus:
    pass


Request = Ping | Arm | SetDuty | SetAll | AllOff | GetStatus


@dataclass(frozen=True)
class Ack:
    """Plain ACK of ARM, SET_DUTY, SET_ALL or ALL_OFF."""

    command: Command

    def __post_init__(self) -> None:
        if self.command not in _PLAIN_ACK_COMMANDS:
            raise ValveProtocolError(f"a plain ACK cannot acknowledge {self.command!r}")


@dataclass(frozen=True)
class PingAck:
    """ACK of PING: armed state and latched faults."""

    armed: bool
    faults: FaultFlags


@dataclass(frozen=True)
class StatusReport:
    """ACK of STATUS. watchdog_ms: watchdog period in ms; rx_errors: frames dropped for
    framing/CRC since boot (saturates at 65535)."""

    armed: bool
    faults: FaultFlags
    duties_permille: tuple[int, int, int]
    firmware_version: tuple[int, int]
    watchdog_ms: int
    rx_errors: int

    def __post_init__(self) -> None:
        object.__setattr__(self, "duties_permille", tuple(self.duties_permille))
        object.__setattr__(self, "firmware_version", tuple(self.firmware_version))
        _check_duties(self.duties_permille, "duties_permille")
        for name in ("watchdog_ms", "rx_errors"):
            v = getattr(self, name)
            if not 0 <= v <= 0xFFFF:
                raise ValveProtocolError(f"{name} must be 0..65535, got {v}")
        if len(self.firmware_version) != 2 or not all(0 <= v <= 0xFF for v in self.firmware_version):
            raise ValveProtocolError(f"firmware_version must be two bytes, got {self.firmware_version}")


@dataclass(frozen=True)
class Nak:
    """command: the refused CMD byte as received (may be unknown); code: why."""

    command: int
    code: NakCode

    def __post_init__(self) -> None:
        if not 0 <= self.command <= 0xFF:
            raise ValveProtocolError(f"command must be 0..255, got {self.command}")


Reply = Ack | PingAck | StatusReport | Nak
Message = Request | Reply

_PLAIN_ACK_COMMANDS = frozenset({Command.ARM, Command.SET_DUTY, Command.SET_ALL, Command.ALL_OFF})
_EMPTY_REQUESTS: dict[Command, type] = {
    Command.PING: Ping,
    Command.ARM: Arm,
    Command.ALL_OFF: AllOff,
    Command.STATUS: GetStatus,
}
_STATUS_FORMAT = struct.Struct(">BBHHHBBHH")


def _flags_byte(armed: bool) -> int:
    return int(StateFlags.ARMED) if armed else 0


def encode_message(seq: int, message: Message) -> bytes:
    """Message -> complete frame bytes with the given SEQ."""
    return encode_frame(message_to_frame(seq, message))


def message_to_frame(seq: int, message: Message) -> Frame:
    match message:
        case Ping():
            return Frame(seq, Command.PING)
        case Arm():
            return Frame(seq, Command.ARM)
        case AllOff():
            return Frame(seq, Command.ALL_OFF)
        case GetStatus():
            return Frame(seq, Command.STATUS)
        case SetDuty(valve, duty):
            return Frame(seq, Command.SET_DUTY, struct.pack(">BH", valve, duty))
        case SetAll(duties):
            return Frame(seq, Command.SET_ALL, struct.pack(">HHH", *duties))
        case Ack(command):
            return Frame(seq, Command.ACK, bytes((command,)))
        case PingAck(armed, faults):
            return Frame(seq, Command.ACK, bytes((Command.PING, _flags_byte(armed), int(faults))))
        case StatusReport(armed, faults, duties, (major, minor), watchdog_ms, rx_errors):
            data = _STATUS_FORMAT.pack(
                _flags_byte(armed), int(faults), *duties, major, minor, watchdog_ms, rx_errors
            )
            return Frame(seq, Command.ACK, bytes((Command.STATUS,)) + data)
        case Nak(command, code):
            return Frame(seq, Command.NAK, bytes((command, code)))
    raise TypeError(f"not a valve protocol message: {message!r}")


def _expect_len(payload: bytes, n: int, what: str) -> None:
    if len(payload) != n:
        raise ValveProtocolError(f"{what} needs {n} payload bytes, got {len(payload)}", NakCode.BAD_LENGTH)


def _state(byte: int) -> bool:
    if byte & ~_STATE_MASK:
        raise ValveProtocolError(f"unknown state bits 0x{byte:02X}")
    return bool(byte & StateFlags.ARMED)


def _faults(byte: int) -> FaultFlags:
    if byte & ~_FAULT_MASK:
        raise ValveProtocolError(f"unknown fault bits 0x{byte:02X}")
    return FaultFlags(byte)


def decode_message(frame: Frame) -> Message:
    """Frame -> typed message. Raises ValveProtocolError (with the NAK code a device
    would answer, for requests) if the frame is not a valid message."""
    payload = frame.payload
    try:
        command = Command(frame.command)
    except ValueError:
        raise ValveProtocolError(f"unknown command 0x{frame.command:02X}", NakCode.UNKNOWN_COMMAND) from None
    if command in _EMPTY_REQUESTS:
        _expect_len(payload, 0, command.name)
        return _EMPTY_REQUESTS[command]()
    if command is Command.SET_DUTY:
        _expect_len(payload, 3, "SET_DUTY")
        valve, duty = struct.unpack(">BH", payload)
        return SetDuty(valve, duty)
    if command is Command.SET_ALL:
        _expect_len(payload, 6, "SET_ALL")
        return SetAll(struct.unpack(">HHH", payload))
    if command is Command.NAK:
        _expect_len(payload, 2, "NAK")
        try:
            code = NakCode(payload[1])
        except ValueError:
            raise ValveProtocolError(f"unknown NAK code 0x{payload[1]:02X}") from None
        return Nak(payload[0], code)
    # ACK: first byte is the acknowledged command.
    if not payload:
        raise ValveProtocolError("ACK without the acknowledged command", NakCode.BAD_LENGTH)
    try:
        acked = Command(payload[0])
    except ValueError:
        raise ValveProtocolError(f"ACK of unknown command 0x{payload[0]:02X}") from None
    data = payload[1:]
    if acked is Command.PING:
        _expect_len(data, 2, "ACK(PING) data")
        return PingAck(_state(data[0]), _faults(data[1]))
    if acked is Command.STATUS:
        _expect_len(data, _STATUS_FORMAT.size, "ACK(STATUS) data")
        state, faults, d0, d1, d2, major, minor, watchdog_ms, rx_errors = _STATUS_FORMAT.unpack(data)
        return StatusReport(_state(state), _faults(faults), (d0, d1, d2), (major, minor), watchdog_ms, rx_errors)
    if acked in _PLAIN_ACK_COMMANDS:
        _expect_len(data, 0, f"ACK({acked.name}) data")
        return Ack(acked)
    raise ValveProtocolError(f"ACK cannot acknowledge {acked.name}")
