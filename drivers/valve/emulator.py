"""Byte-level emulator of the valve controller firmware (see `drivers.valve.protocol`).

`ValveEmulator` is the same state machine as ``firmware/valve_controller.ino``: it
takes host bytes through ``receive`` (any split, any garbage), answers exactly one
ACK/NAK per valid frame, enforces the ARM latch, answers duplicate frames from its
one-frame cache, and runs the watchdog from ``poll`` (called by the pty or sim server)
and before handling each frame (so a late frame cannot beat an overdue trip). Every
change of duties, including the watchdog closing the valves, is reported to
``plant.apply_valve_duties`` with the emulator's clock time.

Thread-safe: the pty server calls it from its own thread while tests inspect it.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from drivers.plant import Plant
from drivers.transport.handler import EmulatorHandler
from drivers.valve.protocol import (
    DEFAULT_WATCHDOG_MS,
    FIRMWARE_VERSION,
    VALVE_COUNT,
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
    Reply,
    SetAll,
    SetDuty,
    StatusReport,
    ValveProtocolError,
    decode_message,
    encode_message,
)

_RX_ERRORS_MAX = 0xFFFF


class ValveEmulator(EmulatorHandler):
    """plant: receives duty changes. clock: seconds, monotonic (virtual time welcome).
    watchdog_s: silence (s) after which an armed device closes all valves and latches
    the WATCHDOG fault; the firmware holds it in whole milliseconds (1..65535)."""

    def __init__(
        self,
        plant: Plant,
        clock: Callable[[], float] = time.monotonic,
        watchdog_s: float = DEFAULT_WATCHDOG_MS / 1000,
    ) -> None:
        if not 0.001 <= watchdog_s <= 65.535:  # whole milliseconds, 1..65535 (and no NaN, no inf)
            raise ValueError(f"watchdog_s must be 0.001..65.535 s, got {watchdog_s}")
        watchdog_ms = round(watchdog_s * 1000)
        self.plant = plant
        self.clock = clock
        self.watchdog_ms = watchdog_ms
        self._lock = threading.RLock()
        self._decoder = FrameDecoder()
        self._duties: tuple[int, ...] = (0,) * VALVE_COUNT
        self._armed = False
        self._faults = FaultFlags(0)
        self._last_valid_s = clock()
        self._last_frame: Frame | None = None
        self._last_reply: bytes = b""
        self.frames_handled = 0
        self.duplicates = 0
        self.watchdog_trips = 0

    # ---------------------------------------------------------------- inspection
    @property
    def duties_permille(self) -> tuple[int, ...]:
        with self._lock:
            return self._duties

    @property
    def armed(self) -> bool:
        with self._lock:
            return self._armed

    @property
    def faults(self) -> FaultFlags:
        with self._lock:
            return self._faults

    @property
    def rx_errors(self) -> int:
        with self._lock:
            return min(self._decoder.bad_frames, _RX_ERRORS_MAX)

    # ---------------------------------------------------------------- server hooks
    def receive(self, data: bytes) -> bytes:
        """Host bytes in; the replies to every complete valid frame out."""
        with self._lock:
            now = self.clock()
            # Time passed before these bytes arrived: an overdue watchdog trips first.
            self._check_watchdog(now)
            out = bytearray()
            for frame in self._decoder.iter_feed(data):
                self._last_valid_s = now
                out += self._handle(frame)
            return bytes(out)

    def poll(self) -> bytes:
        """Run the watchdog; the device never speaks unasked, so always b""."""
        with self._lock:
            self._check_watchdog(self.clock())
        return b""

    def shutdown(self) -> None:
        """Power-off: close all valves (reported to the plant) and disarm."""
        with self._lock:
            self._armed = False
            self._set_duties((0,) * VALVE_COUNT)

    # ---------------------------------------------------------------- state machine
    def _check_watchdog(self, now: float) -> None:
        if self._armed and (now - self._last_valid_s) * 1000 >= self.watchdog_ms:
            self._armed = False
            self._faults |= FaultFlags.WATCHDOG
            self._last_frame = None  # a retry after the trip must be judged afresh
            self.watchdog_trips += 1
            self._set_duties((0,) * VALVE_COUNT)

    def _set_duties(self, duties: tuple[int, ...]) -> None:
        if duties != self._duties:
            self._duties = duties
            self.plant.apply_valve_duties(duties, self.clock())

    def _handle(self, frame: Frame) -> bytes:
        if frame == self._last_frame:
            self.duplicates += 1
            return self._last_reply
        self.frames_handled += 1
        reply = encode_message(frame.seq, self._execute(frame))
        self._last_frame, self._last_reply = frame, reply
        return reply

    def _execute(self, frame: Frame) -> Reply:
        if frame.command in (Command.ACK, Command.NAK):
            # Replies are not requests: a device receiving one NAKs it as unknown.
            return Nak(frame.command, NakCode.UNKNOWN_COMMAND)
        try:
            request = decode_message(frame)
        except ValveProtocolError as exc:
            return Nak(frame.command, exc.nak_code or NakCode.BAD_VALUE)
        match request:
            case Ping():
                return PingAck(self._armed, self._faults)
            case Arm():
                self._armed = True
                self._faults &= ~FaultFlags.WATCHDOG
                return Ack(Command.ARM)
            case AllOff():
                self._set_duties((0,) * VALVE_COUNT)
                return Ack(Command.ALL_OFF)
            case GetStatus():
                return StatusReport(
                    armed=self._armed,
                    faults=self._faults,
                    duties_permille=self._duties,  # type: ignore[arg-type]
                    firmware_version=FIRMWARE_VERSION,
                    watchdog_ms=self.watchdog_ms,
                    rx_errors=min(self._decoder.bad_frames, _RX_ERRORS_MAX),
                )
            case SetDuty(valve, duty):
                refusal = self._refuse_set(frame.command)
                if refusal is not None:
                    return refusal
                duties = list(self._duties)
                duties[valve] = duty
                self._set_duties(tuple(duties))
                return Ack(Command.SET_DUTY)
            case SetAll(duties):
                refusal = self._refuse_set(frame.command)
                if refusal is not None:
                    return refusal
                self._set_duties(tuple(duties))
                return Ack(Command.SET_ALL)
        raise AssertionError(f"unhandled request {request!r}")  # pragma: no cover

    def _refuse_set(self, command: int) -> Nak | None:
        if self._faults & FaultFlags.WATCHDOG:
            return Nak(command, NakCode.WATCHDOG)
        if not self._armed:
            return Nak(command, NakCode.NOT_ARMED)
        return None
