"""Async NDI Aurora client over any transport URL (serial, pty, sim).

Start-up (`open`), after ndicapi's sequence (see hardware-facts.md):
INIT at 9600 baud (if it fails: break -> RESET -> INIT), VER:0, COMM to the working rate
(OKAY comes at the old rate; wait ~100 ms, then switch the port), PHSR 01 -> PHF,
PHSR 02 -> PINIT (repeated until nothing is left), PHSR 03 -> PENA (dynamic),
PHSR 04 -> the enabled handles, TSTART. Then `read_frame` / `frames` poll BX:0801
(or TX:0801). `close` (also on errors and cancellation, via ``async with``) sends
TSTOP and closes the port.

Every exchange has a timeout. A reply with a bad CRC, an ERROR04 (the device saw our
command corrupted) or no reply is retried a bounded number of times after draining the
line; then a typed error is raised: AuroraProtocolError (replies stayed corrupt),
AuroraTimeoutError (no reply), AuroraCommandError (the device refused),
AuroraConnectionError (the port went away).
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator, Callable, Mapping, Sequence
from types import TracebackType

from drivers.aurora.commands import Command
from drivers.aurora.errors import (
    AuroraCommandError,
    AuroraConnectionError,
    AuroraError,
    AuroraProtocolError,
    AuroraTimeoutError,
    ErrorCode,
)
from drivers.aurora.frames import ReplyOption, TrackingFrame, decode_bx, decode_tx_text
from drivers.aurora.poses import TrackedFrame, TrackedPose
from drivers.aurora.replies import (
    DataReply,
    ErrorReply,
    OkayReply,
    PhsrMode,
    PortHandleList,
    ResetReply,
    TextReply,
    decode_reply,
)
from drivers.aurora.pacing import FramePacer
from drivers.aurora.stream import ReplyReader
from drivers.transport import Transport, TransportError, open_transport

POWER_UP_BAUD = 9600
FRAME_PERIOD_S = 1.0 / 40.0  # Aurora measurement rate
COMM_SETTLE_S = 0.1  # host waits this long after COMM's OKAY before switching (ndicapi)
_COMM_DIGIT = {9600: "0", 14400: "1", 19200: "2", 38400: "3", 57600: "4", 115200: "5",
               921600: "6", 1228739: "7", 230400: "A"}
_MAX_PINIT_ROUNDS = 4  # PHSR 02 lists newly found handles; real systems settle in 1-2


class AuroraSetupError(AuroraError):
    """The tools found do not match the names the caller asked for."""


ToolNames = Sequence[str] | Mapping[str, int] | None


class AuroraTracker:
    """An Aurora system control unit seen through a transport.

    target: a transport URL (``serial:///dev/ttyUSB0``, ``/dev/pts/7``, ``sim://aurora``)
        or an unopened `Transport` (e.g. wrapped in a `drivers.testing.FaultyTransport`).
    tool_names: None -> ``tool_0A``-style names; a sequence -> names given to the enabled
        handles in ascending handle order (the port order of a wired Aurora); a mapping
        name -> handle -> exactly those handles (an error if one is absent).
    baud: working line rate set with COMM (115200); 9600 skips COMM.
    use_tx: poll TX (text) instead of BX (binary) frames.
    reply_option: BX/TX reply option; 0x0801 = transforms + out-of-volume tools.
    command_timeout_s / retries: per-attempt timeout and extra attempts per command.
    reset_timeout_s: how long to wait for RESET after a break.
    clock: host clock for ``host_time_s`` stamps.
    """

    def __init__(
        self,
        target: str | Transport,
        tool_names: ToolNames = None,
        *,
        baud: int = 115200,
        use_tx: bool = False,
        reply_option: int = int(ReplyOption.TRANSFORMS | ReplyOption.OUT_OF_VOLUME),
        command_timeout_s: float = 1.0,
        retries: int = 3,
        reset_timeout_s: float = 3.0,
        drain_quiet_s: float = 0.05,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if baud not in _COMM_DIGIT:
            raise ValueError(f"baud {baud} is not a rate COMM can set; choose from {sorted(_COMM_DIGIT)}")
        if isinstance(tool_names, str):
            raise ValueError(f"tool_names must be a sequence or mapping of names, not the string {tool_names!r}")
        if retries < 0 or command_timeout_s <= 0:
            raise ValueError("retries must be >= 0 and command_timeout_s > 0")
        self._transport = open_transport(target) if isinstance(target, str) else target
        self.url = self._transport.url
        self._tool_names = tool_names
        self.baud = baud
        self.use_tx = use_tx
        self.reply_option = reply_option
        self.command_timeout_s = command_timeout_s
        self.retries = retries
        self.reset_timeout_s = reset_timeout_s
        self.drain_quiet_s = drain_quiet_s
        self.clock = clock
        self._reader = ReplyReader()
        self._dirty = False  # a failed exchange may have left bytes on the line
        self._opened = False
        self._tracking = False
        self._lock = asyncio.Lock()
        # The polling command, made once, and again if use_tx or reply_option change.
        self._frame_command: tuple[tuple[bool, int] | None, Command | None] = (None, None)
        self.version_text = ""
        self.handles: dict[str, int] = {}  # tool name -> port handle
        self.stats = {"retries": 0, "resets": 0}

    # --- lifecycle ------------------------------------------------------------------

    async def __aenter__(self) -> AuroraTracker:
        await self.open()
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.close()

    async def open(self) -> None:
        """Connect, set up every port handle and start tracking."""
        if self._opened:
            raise AuroraError(f"{self.url}: already open")
        try:
            await self._transport.open()
        except TransportError as exc:
            raise AuroraConnectionError(f"{self.url}: cannot open: {exc}") from exc
        self._opened = True
        try:
            await self._start_up()
        except TransportError as exc:  # set_baudrate / send_break on a vanished port
            await self.close()
            raise AuroraConnectionError(f"{self.url}: link lost during start-up: {exc}") from exc
        except BaseException:
            await self.close()
            raise

    async def close(self) -> None:
        """Stop tracking (best effort, bounded) and close the port. Idempotent."""
        if not self._opened:
            return
        self._opened = False
        try:
            if self._tracking:
                self._tracking = False
                with contextlib.suppress(AuroraError, TransportError):
                    await self._exchange(Command("TSTOP"), retries=1, ok_on_retry=(ErrorCode.INVALID_MODE,))
        finally:
            await self._transport.close()

    async def _start_up(self) -> None:
        await self._transport.set_baudrate(POWER_UP_BAUD)
        await self._initialise()
        reply = await self._exchange(Command("VER", "0"))
        self.version_text = reply.text if isinstance(reply, DataReply) else ""
        if self.baud != POWER_UP_BAUD:
            await self._change_baud(self.baud)
        for handle in (await self._phsr(PhsrMode.TO_BE_FREED)).handles:
            await self._exchange(Command("PHF", f"{handle:02X}"))
        for _ in range(_MAX_PINIT_ROUNDS):
            pending = (await self._phsr(PhsrMode.NOT_INITIALISED)).handles
            if not pending:
                break
            for handle in pending:
                await self._exchange(Command("PINIT", f"{handle:02X}"))
        for handle in (await self._phsr(PhsrMode.NOT_ENABLED)).handles:
            await self._exchange(Command("PENA", f"{handle:02X}D"))
        enabled = (await self._phsr(PhsrMode.ENABLED)).handles
        self.handles = self._assign_names(sorted(enabled))
        self._tracking = True  # from here on, close() must send TSTOP
        await self._exchange(Command("TSTART"), ok_on_retry=(ErrorCode.INVALID_MODE,))

    async def _initialise(self) -> None:
        """INIT; if the device does not answer sensibly (wrong baud rate, left in a
        strange state), break -> RESET -> INIT, as ndicapi's probe does."""
        try:
            await self._exchange(Command("INIT"), retries=0)
            return
        except (AuroraTimeoutError, AuroraProtocolError):
            pass
        self.stats["resets"] += 1
        self._reader.clear()
        await self._transport.set_baudrate(POWER_UP_BAUD)
        await self._transport.send_break()
        # A pty or sim link may carry no break; then no RESET arrives and INIT decides.
        with contextlib.suppress(AuroraTimeoutError, AuroraProtocolError):
            raw = await self._read_reply(binary=False, timeout_s=self.reset_timeout_s)
            if not isinstance(decode_reply(raw), ResetReply):
                raise AuroraProtocolError("expected RESET after break")
        await asyncio.sleep(COMM_SETTLE_S)
        self._dirty = True
        await self._exchange(Command("INIT"))

    async def _change_baud(self, baud: int) -> None:
        """COMM: the OKAY comes at the old rate, then both ends switch. If the reply is
        lost or garbled the device may or may not have switched: probe with INIT at the
        new rate, and fall back to the old one before trying again."""
        command = Command("COMM", f"{_COMM_DIGIT[baud]}0000")
        old = POWER_UP_BAUD
        last: Exception | None = None
        for _ in range(self.retries + 1):
            try:
                reply = await self._exchange(command, retries=0)  # ERRORxx raises AuroraCommandError
            except (AuroraTimeoutError, AuroraProtocolError) as exc:
                last = exc
                reply = None
            await asyncio.sleep(COMM_SETTLE_S)
            await self._transport.set_baudrate(baud)
            if isinstance(reply, OkayReply):
                return
            self.stats["retries"] += 1
            try:
                await self._exchange(Command("INIT"), retries=0)
                return
            except (AuroraTimeoutError, AuroraProtocolError) as exc:
                last = exc
            await self._transport.set_baudrate(old)
            self._dirty = True
        raise AuroraTimeoutError(f"{self.url}: could not switch to {baud} baud: {last}")

    async def _phsr(self, mode: PhsrMode) -> PortHandleList:
        reply = await self._exchange(Command("PHSR", f"{int(mode):02X}"))
        if not isinstance(reply, DataReply):
            raise AuroraProtocolError(f"PHSR {int(mode):02X}: unexpected reply {reply!r}")
        return PortHandleList.from_text(reply.text)

    def _assign_names(self, handles: list[int]) -> dict[str, int]:
        names = self._tool_names
        if names is None:
            return {f"tool_{h:02X}": h for h in handles}
        if isinstance(names, Mapping):
            absent = {n: h for n, h in names.items() if h not in handles}
            if absent:
                raise AuroraSetupError(
                    f"{self.url}: tools {', '.join(f'{n}=0x{h:02X}' for n, h in absent.items())} not found; "
                    f"enabled handles: {[hex(h) for h in handles]}"
                )
            return dict(names)
        names = list(names)
        if len(names) > len(handles):
            raise AuroraSetupError(
                f"{self.url}: {len(names)} tools named {names} but only {len(handles)} found "
                f"(handles {[hex(h) for h in handles]})"
            )
        assigned = dict(zip(names, handles))
        assigned.update({f"tool_{h:02X}": h for h in handles[len(names):]})
        return assigned

    # --- tracking -------------------------------------------------------------------

    async def read_frame(self) -> TrackedFrame:
        """Poll one frame now (BX or TX) and name its tools."""
        if not self._tracking:
            raise AuroraError(f"{self.url}: not tracking (open the tracker first)")
        key = (self.use_tx, self.reply_option)
        if self._frame_command[0] != key:
            self._frame_command = (key, Command("TX" if self.use_tx else "BX", f"{self.reply_option:04X}"))
        command = self._frame_command[1]
        name = command.name
        reply = await self._exchange(command, binary=not self.use_tx)
        host_time = self.clock()
        if isinstance(reply, TrackingFrame):
            frame = reply
        elif isinstance(reply, DataReply):
            frame = decode_tx_text(reply.text)
        else:
            raise AuroraProtocolError(f"{name}: unexpected reply {reply!r}")
        by_handle = {h: n for n, h in self.handles.items()}
        poses = tuple(
            TrackedPose.from_record(by_handle[r.handle], r, host_time)
            for r in frame.tools
            if r.handle in by_handle
        )
        numbers = [r.frame_number for r in frame.tools if r.frame_number is not None]
        return TrackedFrame(poses, numbers[0] if numbers else None, frame.system_status, host_time)

    async def frames(self, poll_period_s: float = FRAME_PERIOD_S) -> AsyncIterator[TrackedFrame]:
        """Each new frame once, reading one every ``poll_period_s`` (s; default: every
        frame), polls locked to the device's frame count (`FramePacer`), forever (break
        out, or use ``contextlib.aclosing``)."""
        loop = asyncio.get_running_loop()
        pacer = FramePacer(FRAME_PERIOD_S, poll_period_s)
        while True:
            await asyncio.sleep(max(0.0, pacer.next_poll_s(loop.time()) - loop.time()))
            sent_s = loop.time()
            frame = await self.read_frame()
            if pacer.observe(sent_s, loop.time(), frame.frame_number):
                yield frame

    # --- command exchange -----------------------------------------------------------

    async def command(self, name: str, params: str = "") -> TextReply:
        """Send any text command (with retries) and return its decoded reply; raises
        AuroraCommandError on ERRORxx. For diagnostics (e.g. ``BEEP``)."""
        reply = await self._exchange(Command(name, params))
        assert not isinstance(reply, TrackingFrame)
        return reply

    async def _exchange(
        self,
        command: Command,
        *,
        binary: bool = False,
        retries: int | None = None,
        ok_on_retry: tuple[ErrorCode, ...] = (),
    ) -> TextReply | TrackingFrame:
        """Send ``command``, return its reply (a TrackingFrame for BX), retrying bounded."""
        attempts = 1 + (self.retries if retries is None else retries)
        last: AuroraError | None = None
        async with self._lock:
            for attempt in range(attempts):
                if attempt:
                    self.stats["retries"] += 1
                try:
                    if self._dirty:
                        await self._drain()
                    # Until a whole reply is in, the line is in an unknown state (this
                    # also covers a cancellation mid-exchange).
                    self._dirty = True
                    await self._transport.write(command.wire)
                    raw = await self._read_reply(binary, self.command_timeout_s)
                    self._dirty = False
                    reply: TextReply | TrackingFrame = (
                        decode_bx(raw) if binary and not raw.startswith(b"ERROR") else decode_reply(raw)
                    )
                except AuroraTimeoutError as exc:
                    last = exc
                    continue
                except AuroraProtocolError as exc:
                    last = AuroraProtocolError(f"{self.url}: {command.text}: {exc}")
                    self._dirty = True
                    continue
                except TransportError as exc:
                    raise AuroraConnectionError(f"{self.url}: link lost during {command.text}: {exc}") from exc
                if isinstance(reply, ErrorReply):
                    if reply.code == ErrorCode.BAD_CRC:
                        last = AuroraProtocolError(f"{self.url}: {command.text}: device saw a bad CRC")
                        self._dirty = True
                        continue
                    if attempt and reply.code in ok_on_retry:
                        # An earlier attempt took effect; only its reply was lost.
                        return OkayReply()
                    raise AuroraCommandError(command.text, reply.code)
                return reply
        assert last is not None
        raise last

    async def _read_reply(self, binary: bool, timeout_s: float) -> bytes:
        """Raw bytes of the next reply; AuroraTimeoutError if none in ``timeout_s``."""
        try:
            async with asyncio.timeout(timeout_s):
                while True:
                    raw = self._reader.next_binary() if binary else self._reader.next_text()
                    if raw is not None:
                        return raw
                    self._reader.feed(await self._transport.read())
        except TimeoutError:
            raise AuroraTimeoutError(f"{self.url}: no reply within {timeout_s} s") from None

    async def _drain(self) -> None:
        """Discard whatever a failed exchange left on the line: read until it has been
        quiet for ``drain_quiet_s`` (at most 10 such periods)."""
        self._reader.clear()
        for _ in range(10):
            try:
                async with asyncio.timeout(self.drain_quiet_s):
                    await self._transport.read()
            except TimeoutError:
                break
        self._dirty = False
