"""Async client of the valve controller: arming, retries, heartbeat, safe state.

    async with ValveController("pty:///dev/pts/7", calibrations=cals) as valves:
        await valves.set_forces_n((0.05, 0.0, 0.02))

On entry the controller opens the transport and ARMs the device; a heartbeat task then
PINGs whenever the link has been idle for ``heartbeat_interval_s`` (default 0.1 s, a
fifth of the firmware's 0.5 s watchdog). On exit - normal, exception or cancellation -
it stops the heartbeat, sends ALL_OFF and closes the transport; if that ALL_OFF cannot
get through, the firmware watchdog closes the valves within its period anyway.

Requests are one at a time (the firmware is half duplex in effect). Each waits
``reply_timeout_s`` for its reply; a timeout re-sends the same frame with the same SEQ
(the device answers duplicates from its cache, so a lost ACK never applies a command
twice), and a NAK for a bad frame is retried with a fresh SEQ, up to ``retries`` extra
attempts. NAKs that report device state are not retried: WATCHDOG raises
`ValveFaultError` (call `arm` to recover), NOT_ARMED raises `ValveNakError`.
Transport failures propagate as `drivers.transport.TransportError`/`TransportClosed`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
from collections.abc import Sequence
from types import TracebackType

from drivers.transport import Transport, TransportClosed, TransportError, open_transport
from drivers.valve.calibration import JetCalibration
from drivers.valve.protocol import (
    DUTY_MAX_PERMILLE,
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
    Request,
    SetAll,
    SetDuty,
    StatusReport,
    ValveProtocolError,
    decode_message,
    encode_frame,
    message_to_frame,
)

log = logging.getLogger(__name__)


class ValveError(Exception):
    """Base of the valve client's errors."""


class ValveNakError(ValveError):
    """The device refused a request. code: the NakCode; command: the refused CMD."""

    def __init__(self, code: NakCode, command: int, message: str | None = None) -> None:
        self.code = code
        self.command = command
        super().__init__(message or f"device refused command 0x{command:02X}: NAK {code.name}")


class ValveFaultError(ValveNakError):
    """The device has latched a fault (the watchdog tripped) and refuses to open valves
    until re-armed (`ValveController.arm`)."""


class ValveTimeoutError(ValveError):
    """No valid reply after every attempt."""


_STATE_NAKS = {NakCode.NOT_ARMED, NakCode.WATCHDOG}


def _reply_answers(reply: Reply, command: int) -> bool:
    match reply:
        case Nak(refused, _):
            return refused == command
        case Ack(acked):
            return acked == command
        case PingAck():
            return command == Command.PING
        case StatusReport():
            return command == Command.STATUS
    return False


class ValveController:
    """Client of one valve controller.

    url: transport URL (``serial://``, ``pty://``, ``sim://``), or pass ``transport``.
    calibrations: one `JetCalibration` per jet, needed by `set_forces_n`.
    retries: extra attempts after a timeout or retryable NAK (>= 0).
    reply_timeout_s: wait for each reply (s). heartbeat_interval_s: idle time (s) after
    which a PING is sent; None disables the heartbeat (scripted tests only: the device
    watchdog will then trip). initial_seq: first SEQ (random if None).
    """

    def __init__(
        self,
        url: str | None = None,
        *,
        transport: Transport | None = None,
        calibrations: Sequence[JetCalibration] | None = None,
        retries: int = 3,
        reply_timeout_s: float = 0.1,
        heartbeat_interval_s: float | None = 0.1,
        initial_seq: int | None = None,
    ) -> None:
        if (url is None) == (transport is None):
            raise ValueError("give exactly one of url or transport")
        if retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        if reply_timeout_s <= 0:
            raise ValueError(f"reply_timeout_s must be > 0, got {reply_timeout_s}")
        if heartbeat_interval_s is not None and heartbeat_interval_s <= 0:
            raise ValueError(f"heartbeat_interval_s must be > 0 or None, got {heartbeat_interval_s}")
        if calibrations is not None:
            calibrations = tuple(calibrations)
            if len(calibrations) != VALVE_COUNT or not all(
                isinstance(c, JetCalibration) for c in calibrations
            ):
                raise ValueError(f"calibrations must be {VALVE_COUNT} JetCalibration objects")
        self.transport: Transport = transport if transport is not None else open_transport(url)  # type: ignore[arg-type]
        self.calibrations = calibrations
        self.retries = retries
        self.reply_timeout_s = reply_timeout_s
        self.heartbeat_interval_s = heartbeat_interval_s
        self._seq = random.randrange(256) if initial_seq is None else initial_seq % 256
        self._decoder = FrameDecoder()
        self._lock = asyncio.Lock()
        self._pending: tuple[int, int, asyncio.Future[Reply]] | None = None
        self._reader: asyncio.Task[None] | None = None
        self._heartbeat: asyncio.Task[None] | None = None
        self._link_error: BaseException | None = None
        self._last_tx_s = 0.0
        self._open = False
        self.faults = FaultFlags(0)  # as last reported by the device
        self.armed = False
        self.timeouts = 0  # reply timeouts (each retried or raised)
        self.heartbeat_failures = 0
        self.ignored_frames = 0  # valid frames that answered nothing we asked
        # After close: None if ALL_OFF was acknowledged, else why not (the firmware's
        # watchdog then closes the valves once the host falls silent).
        self.all_off_failure: str | None = None

    # ------------------------------------------------------------------ lifecycle
    async def open(self) -> None:
        """Open the transport, start reading, ARM, start the heartbeat."""
        if self._open:
            raise RuntimeError("ValveController is already open")
        await self.transport.open()
        self._open = True
        self._reader = asyncio.create_task(self._read_loop(), name=f"valve-reader:{self.transport.url}")
        try:
            await self.arm()
            if self.heartbeat_interval_s is not None:
                self._heartbeat = asyncio.create_task(
                    self._heartbeat_loop(), name=f"valve-heartbeat:{self.transport.url}"
                )
        except BaseException:
            await self._shutdown(send_all_off=True, raise_errors=False)
            raise

    async def close(self) -> None:
        """Stop the heartbeat, send ALL_OFF, close the transport. Idempotent. Raises the
        ALL_OFF failure (after releasing everything) if it could not be delivered."""
        await self._shutdown(send_all_off=True, raise_errors=True)

    async def __aenter__(self) -> ValveController:
        await self.open()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        # With an exception (or cancellation) already propagating, a failed ALL_OFF is
        # logged rather than raised so it does not hide the original error.
        await self._shutdown(send_all_off=True, raise_errors=exc is None)

    async def _shutdown(self, send_all_off: bool, raise_errors: bool) -> None:
        if not self._open:
            return
        self._open = False
        error: BaseException | None = None
        try:
            await _stop_task(self._heartbeat)
            self._heartbeat = None
            if send_all_off and self._link_error is not None:
                self.all_off_failure = f"the link had failed ({self._link_error})"
            elif send_all_off:
                try:
                    await self._request(AllOff(), allow_closed=True)
                except (ValveError, TransportError) as exc:
                    error = exc
                    self.all_off_failure = str(exc) or type(exc).__name__
                    log.warning("ALL_OFF on close failed (%s); firmware watchdog will close the valves", exc)
        finally:
            await _stop_task(self._reader)
            self._reader = None
            await self.transport.close()
        if error is not None and raise_errors:
            raise error

    # ------------------------------------------------------------------ commands
    async def arm(self) -> None:
        """ARM the device (also clears a latched watchdog fault)."""
        await self._request(Arm())
        self.armed = True
        self.faults = FaultFlags(0)

    async def ping(self) -> PingAck:
        reply = await self._request(Ping())
        assert isinstance(reply, PingAck)
        self._note_state(reply.armed, reply.faults)
        return reply

    async def status(self) -> StatusReport:
        reply = await self._request(GetStatus())
        assert isinstance(reply, StatusReport)
        self._note_state(reply.armed, reply.faults)
        return reply

    async def set_duties(self, duties_permille: Sequence[int]) -> None:
        """Set all three valve duties (per mille, 0..1000) at once."""
        duties = tuple(duties_permille)
        if len(duties) != VALVE_COUNT:
            raise ValueError(f"need {VALVE_COUNT} duties, got {len(duties)}")
        for i, d in enumerate(duties):
            if isinstance(d, bool) or not isinstance(d, int) or not 0 <= d <= DUTY_MAX_PERMILLE:
                raise ValueError(f"duties_permille[{i}] must be an int in 0..{DUTY_MAX_PERMILLE}, got {d!r}")
        await self._request(SetAll(duties))  # type: ignore[arg-type]

    async def set_duty(self, valve: int, duty_permille: int) -> None:
        """Set one valve (0..2) to a duty (per mille, 0..1000)."""
        try:
            message = SetDuty(valve, duty_permille)
        except ValveProtocolError as exc:
            raise ValueError(str(exc)) from None
        await self._request(message)

    async def set_forces_n(self, forces_n: Sequence[float]) -> tuple[int, ...]:
        """Command each jet's force (N) through its calibration; returns the duties sent."""
        if self.calibrations is None:
            raise ValueError("set_forces_n needs calibrations (one JetCalibration per jet)")
        forces = tuple(forces_n)
        if len(forces) != VALVE_COUNT:
            raise ValueError(f"need {VALVE_COUNT} forces, got {len(forces)}")
        duties = tuple(cal.duty_for_force(float(f)) for cal, f in zip(self.calibrations, forces))
        await self.set_duties(duties)
        return duties

    async def all_off(self) -> None:
        """Close every valve (accepted even when disarmed or faulted)."""
        await self._request(AllOff())

    # ------------------------------------------------------------------ plumbing
    def _note_state(self, armed: bool, faults: FaultFlags) -> None:
        self.armed = armed
        self.faults = faults

    def _next_seq(self) -> int:
        seq = self._seq
        self._seq = (self._seq + 1) % 256
        return seq

    async def _request(self, message: Request, allow_closed: bool = False) -> Reply:
        if not self._open and not allow_closed:
            raise RuntimeError("ValveController is not open")
        async with self._lock:
            frame = message_to_frame(self._next_seq(), message)
            last_nak: Nak | None = None
            loop = asyncio.get_running_loop()
            for attempt in range(self.retries + 1):
                if self._link_error is not None:
                    raise TransportClosed(f"valve link lost: {self._link_error}") from self._link_error
                if last_nak is not None:
                    # The device caches its last reply per frame: a NAK retried with the
                    # same SEQ would just be NAKed again from the cache.
                    frame = message_to_frame(self._next_seq(), message)
                future: asyncio.Future[Reply] = loop.create_future()
                self._pending = (frame.seq, frame.command, future)
                try:
                    await self.transport.write(encode_frame(frame))
                    self._last_tx_s = loop.time()
                    reply = await asyncio.wait_for(future, self.reply_timeout_s)
                except TimeoutError:
                    self.timeouts += 1
                    last_nak = None
                    continue
                finally:
                    self._pending = None
                if isinstance(reply, Nak):
                    if reply.code in _STATE_NAKS:
                        if reply.code is NakCode.WATCHDOG:
                            self._note_state(False, self.faults | FaultFlags.WATCHDOG)
                            raise ValveFaultError(
                                reply.code, reply.command,
                                "watchdog fault latched: the device closed all valves; arm() to resume",
                            )
                        self.armed = False
                        raise ValveNakError(reply.code, reply.command)
                    last_nak = reply
                    continue
                return reply
            if last_nak is not None:
                raise ValveNakError(last_nak.code, last_nak.command)
            raise ValveTimeoutError(
                f"no reply to {Command(frame.command).name} on {self.transport.url} after "
                f"{self.retries + 1} attempts of {self.reply_timeout_s} s"
            )

    async def _read_loop(self) -> None:
        try:
            while True:
                data = await self.transport.read()
                for frame in self._decoder.feed(data):
                    self._dispatch(frame)
        except TransportError as exc:
            self._link_error = exc
            if self._pending is not None and not self._pending[2].done():
                self._pending[2].set_exception(exc)

    def _dispatch(self, frame: Frame) -> None:
        pending = self._pending
        try:
            reply = decode_message(frame)
        except ValveProtocolError:
            self.ignored_frames += 1
            return
        if (
            pending is None
            or pending[2].done()
            or frame.seq != pending[0]
            or not isinstance(reply, (Ack, PingAck, StatusReport, Nak))
            or not _reply_answers(reply, pending[1])
        ):
            # Late replies to an attempt we gave up on, or a previous session's.
            self.ignored_frames += 1
            return
        pending[2].set_result(reply)

    async def _heartbeat_loop(self) -> None:
        assert self.heartbeat_interval_s is not None
        loop = asyncio.get_running_loop()
        # Checked each turn as well as cancelled on close: Python 3.11's wait_for can
        # swallow the cancellation, and a PING after close would raise "not open".
        while self._open:
            idle_s = loop.time() - self._last_tx_s
            if idle_s < self.heartbeat_interval_s:
                await asyncio.sleep(self.heartbeat_interval_s - idle_s)
                continue
            try:
                await self.ping()
            except ValveError as exc:
                self.heartbeat_failures += 1
                log.warning("valve heartbeat failed: %s", exc)
            except TransportError:
                return  # the reader recorded the link error; every request raises it


async def _stop_task(task: asyncio.Task[None] | None) -> None:
    """Cancel a helper task and wait for it, without swallowing our own cancellation."""
    if task is None or task.done():
        if task is not None and not task.cancelled():
            with contextlib.suppress(BaseException):
                task.result()
        return
    task.cancel()
    await asyncio.wait([task])
