"""A byte-level NDI Aurora (Combined API) emulator driven by a `Plant`.

It speaks the protocol of `drivers.aurora.commands/replies/frames` byte for byte, so the
real host library (ndicapi / scikit-surgerynditracker) and our own client both drive it.
Serve it with `drivers.transport.pty.PtyServer` (a pty a serial client opens) or
`drivers.transport.sim.serve_sim` (in-process ``sim://NAME``); see also `drivers.aurora.serve`.

Modes, as on the device: after power-up or a break the system is not initialised and
talks at 9600 baud; INIT initialises it (and un-initialises every port handle, so a new
host session re-runs PHSR 02/PINIT/PENA); TSTART enters tracking, TSTOP leaves it.

Poses: ``plant.sensor_truth(name, t)`` at the instant ``t`` the frame began, plus noise
from each port's own seeded stream drawn at the frame's first read and kept: two reads
of one frame agree, and what a frame holds does not depend on when the host read it.
Noise levels are the Aurora's published accuracy (0.48 mm, 0.70 deg RMS), spread evenly
over the three axes. Frame numbers count at 40 Hz on ``clock``.

Baud rate: only a sim link tells the emulator the host's rate (``on_baudrate``); then a
mismatch garbles the line both ways (bytes are dropped), which exercises the client's
break/reset recovery. On a pty the rate is not modelled and a break is invisible, so
any INIT, even after garbage on the line, gets the system back.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from drivers.aurora.commands import Command, parse_command
from drivers.aurora.errors import AuroraProtocolError, ErrorCode
from drivers.aurora.frames import (
    BX_START,
    HandleStatus,
    ReplyOption,
    SystemStatus,
    ToolRecord,
    TrackingFrame,
    Transform,
    encode_bx,
    encode_tx_text,
    parse_reply_option,
)
from drivers.aurora.replies import (
    ErrorReply,
    OkayReply,
    PhsrMode,
    PortHandleEntry,
    PortHandleList,
    PortStatus,
    ResetReply,
    encode_payload,
    encode_reply,
)
from drivers.aurora.stream import CommandSplitter
from drivers.plant import Plant
from drivers.rotations import quat_from_rotvec, quat_multiply, quat_normalize
from drivers.transport.handler import EmulatorHandler

FRAME_RATE_HZ = 40.0  # Aurora measurement rate
DEFAULT_BAUD = 9600  # after power-up, a break or RESET
POSITION_NOISE_MM = 0.48  # Aurora 5DOF/6DOF RMS position accuracy (hardware-facts.md)
ORIENTATION_NOISE_DEG = 0.70  # Aurora RMS orientation accuracy

DEFAULT_VERSION_TEXT = "\n".join(
    [
        "Aurora Control Unit (HydroJet Bench emulator)",
        "Freeze Tag: HydroJet Aurora emulator 1.0",
        "Freeze Date: 2024-01-01",
        "(C) HydroJet Bench",
    ]
)

# COMM baud digit -> bit/s (API Guide COMM; ndicapi ndiCOMMHelper).
COMM_BAUD = {"0": 9600, "1": 14400, "2": 19200, "3": 38400, "4": 57600, "5": 115200,
             "6": 921600, "7": 1228739, "A": 230400}

_SUPPORTED_OPTIONS = int(ReplyOption.TRANSFORMS | ReplyOption.OUT_OF_VOLUME)
_TRANSFORMS, _OUT_OF_VOLUME_OPTION = int(ReplyOption.TRANSFORMS), int(ReplyOption.OUT_OF_VOLUME)
_OCCUPIED, _INITIALISED, _ENABLED = int(PortStatus.OCCUPIED), int(PortStatus.INITIALISED), int(PortStatus.ENABLED)
_OUT_OF_VOLUME_BIT = int(PortStatus.OUT_OF_VOLUME)
_KNOWN_COMMANDS = ("INIT", "COMM", "VER", "GETINFO", "RESET", "BEEP", "PHSR", "PHF",
                   "PINIT", "PENA", "PDIS", "TSTART", "TSTOP", "BX", "TX")


class _DeviceError(Exception):
    def __init__(self, code: ErrorCode) -> None:
        self.code = code


@dataclass
class _Port:
    handle: int
    sensor: str
    noise: np.random.Generator
    initialised: bool = False
    enabled: bool = False
    missing: bool = False  # fault: the sensor gives no solution
    out_of_volume: bool = False  # fault: outside the characterised volume
    # The last frame measured and its transform: a frame read again is the same frame.
    measured_frame: int | None = None
    measured: Transform | None = None

    @property
    def status_bits(self) -> int:
        # Plain ints: IntFlag operations cost microseconds each, at 1000 frames a wall second.
        return (_OCCUPIED | (_INITIALISED if self.initialised else 0) | (_ENABLED if self.enabled else 0))


def _parse_handle(params: str) -> int:
    if len(params) != 2:
        raise _DeviceError(ErrorCode.PARAMETER_COUNT)
    try:
        return int(params, 16)
    except ValueError:
        raise _DeviceError(ErrorCode.INVALID_PORT_HANDLE) from None


class AuroraEmulator(EmulatorHandler):
    """An Aurora system control unit with wired sensors ``tools`` (handle -> plant
    sensor name). Thread-safe: servers call it from their own thread while tests and the
    bench flip faults.

    ``position_noise_mm`` / ``orientation_noise_deg``: RMS of the 3-D position error and
    of the rotation error angle. ``seed`` fixes the noise sequence.
    """

    def __init__(
        self,
        plant: Plant,
        clock: Callable[[], float] = time.monotonic,
        tools: Mapping[int, str] | None = None,
        *,
        position_noise_mm: float = POSITION_NOISE_MM,
        orientation_noise_deg: float = ORIENTATION_NOISE_DEG,
        seed: int = 0,
        version_text: str = DEFAULT_VERSION_TEXT,
    ) -> None:
        tools = dict(tools) if tools is not None else {0x0A: "base", 0x0B: "tip"}
        for handle in tools:
            if not 0x01 <= handle <= 0xFF:
                raise ValueError(f"port handle must be 0x01..0xFF, got {handle:#x}")
        if position_noise_mm < 0 or orientation_noise_deg < 0:
            raise ValueError("noise levels must be >= 0")
        self.plant = plant
        self.clock = clock
        self.position_noise_mm = float(position_noise_mm)
        self.orientation_noise_deg = float(orientation_noise_deg)
        self.version_text = version_text
        self._lock = threading.RLock()
        self._ports = {h: _Port(h, name, np.random.default_rng([seed, h]))
                       for h, name in sorted(tools.items())}
        self._t0 = clock()
        self._splitter = CommandSplitter()
        self._initialised = False
        self._tracking = False
        self._baud = DEFAULT_BAUD
        self._host_baud: int | None = None  # known only on links that report it
        self._field_generator_connected = True
        self._corrupt_next = 0
        self.command_log: deque[str] = deque(maxlen=1000)  # "NAME:params" as received

    # --- state, for tests and the bench --------------------------------------------

    @property
    def mode(self) -> str:
        """"uninitialised", "setup" or "tracking"."""
        with self._lock:
            if self._tracking:
                return "tracking"
            return "setup" if self._initialised else "uninitialised"

    @property
    def baud_rate(self) -> int:
        with self._lock:
            return self._baud

    def frame_number(self) -> int:
        """The 40 Hz frame counter now."""
        return int((self.clock() - self._t0) * FRAME_RATE_HZ) & 0xFFFFFFFF

    # --- fault controls -------------------------------------------------------------

    def _port(self, tool: int | str) -> _Port:
        for port in self._ports.values():
            if port.handle == tool or port.sensor == tool:
                return port
        raise KeyError(f"no tool {tool!r}; have {[(hex(p.handle), p.sensor) for p in self._ports.values()]}")

    def set_tool_missing(self, tool: int | str, missing: bool = True) -> None:
        """Report the tool (handle or sensor name) MISSING, as when its coil gives no
        solution (e.g. metal distortion)."""
        with self._lock:
            self._port(tool).missing = missing

    def set_out_of_volume(self, tool: int | str, out_of_volume: bool = True) -> None:
        """Flag the tool outside the characterised volume (port status bit 6). With reply
        option 0x0800 its transform is still reported; without, it is MISSING."""
        with self._lock:
            self._port(tool).out_of_volume = out_of_volume

    def set_field_generator_connected(self, connected: bool) -> None:
        """Drop (False) or restore the field generator: while dropped, every tool is
        MISSING, the system status has HARDWARE_FAILURE and PINIT fails (ERROR13)."""
        with self._lock:
            self._field_generator_connected = connected

    def corrupt_next_reply(self, count: int = 1) -> None:
        """Send the next ``count`` replies with a wrong CRC."""
        with self._lock:
            self._corrupt_next += count

    # --- handler interface (drivers.transport.handler) ------------------------------

    def receive(self, data: bytes) -> bytes:
        """Host bytes in, device bytes out."""
        with self._lock:
            if self._host_baud is not None and self._host_baud != self._baud:
                # Rates differ: the UART sees framing errors, the host sees noise.
                self._splitter.clear()
                return b""
            out = bytearray()
            for line in self._splitter.feed(data):
                out += self._handle_line(line)
            return bytes(out)

    def on_break(self) -> bytes:
        """A serial break resets the system: 9600 baud, uninitialised, ``RESET`` reply."""
        with self._lock:
            self._reset()
            reply = encode_reply(ResetReply())
            if self._host_baud is not None and self._host_baud != self._baud:
                return b""
            return self._finish(reply)

    def on_baudrate(self, baud: int) -> None:
        with self._lock:
            self._host_baud = baud

    # --- command processing ---------------------------------------------------------

    def _reset(self) -> None:
        self._initialised = False
        self._tracking = False
        self._baud = DEFAULT_BAUD
        self._splitter.clear()
        for port in self._ports.values():
            port.initialised = port.enabled = False

    def _finish(self, reply: bytes) -> bytes:
        if self._corrupt_next > 0:
            self._corrupt_next -= 1
            return _corrupt_crc(reply)
        return reply

    def _handle_line(self, line: bytes) -> bytes:
        try:
            command = _parse_resync(line)
        except AuroraProtocolError as exc:
            code = exc.device_error_code or ErrorCode.INVALID_COMMAND
            return self._finish(encode_reply(ErrorReply(code)))
        self.command_log.append(command.text)
        after: Callable[[], None] | None = None
        try:
            handler = getattr(self, f"_cmd_{command.name.lower()}", None)
            if handler is None or command.name not in _KNOWN_COMMANDS:
                raise _DeviceError(ErrorCode.INVALID_COMMAND)
            result = handler(command.params)
            if isinstance(result, tuple):
                result, after = result
        except _DeviceError as exc:
            result = encode_reply(ErrorReply(exc.code))
        reply = self._finish(result)
        if after is not None:
            after()  # e.g. COMM: the OKAY goes out at the old rate, then the rate changes
        return reply

    def _require_setup(self) -> None:
        if not self._initialised:
            raise _DeviceError(ErrorCode.NOT_INITIALISED)
        if self._tracking:
            raise _DeviceError(ErrorCode.INVALID_MODE)

    def _known_port(self, handle: int) -> _Port:
        port = self._ports.get(handle)
        if port is None:
            raise _DeviceError(ErrorCode.INVALID_PORT_HANDLE)
        return port

    def _cmd_init(self, params: str) -> bytes:
        if params:
            raise _DeviceError(ErrorCode.PARAMETER_COUNT)
        self._initialised = True
        self._tracking = False
        for port in self._ports.values():
            port.initialised = port.enabled = False
        return encode_reply(OkayReply())

    def _cmd_comm(self, params: str) -> tuple[bytes, Callable[[], None]]:
        if len(params) != 5:
            raise _DeviceError(ErrorCode.PARAMETER_COUNT)
        digit, data_bits, parity, stop_bits, handshake = params
        if (digit not in COMM_BAUD or data_bits not in "01" or parity not in "012"
                or stop_bits not in "01" or handshake not in "01"):
            raise _DeviceError(ErrorCode.PARAMETER_RANGE)
        new_baud = COMM_BAUD[digit]

        def switch() -> None:
            self._baud = new_baud

        return encode_reply(OkayReply()), switch

    def _cmd_ver(self, params: str) -> bytes:
        if params and not (len(params) == 1 and params.isdigit()):
            raise _DeviceError(ErrorCode.PARAMETER_RANGE)
        return encode_payload(self.version_text)

    def _cmd_getinfo(self, params: str) -> bytes:
        # This firmware predates GETINFO (as older Aurora units do); hosts fall back to VER.
        raise _DeviceError(ErrorCode.INVALID_COMMAND)

    def _cmd_reset(self, params: str) -> tuple[bytes, Callable[[], None]]:
        if params not in ("", "0"):
            raise _DeviceError(ErrorCode.PARAMETER_RANGE)
        return encode_reply(ResetReply()), self._reset

    def _cmd_beep(self, params: str) -> bytes:
        if len(params) != 1 or params not in "123456789":
            raise _DeviceError(ErrorCode.PARAMETER_RANGE)
        return encode_payload("1")  # 1: the system beeped

    def _cmd_phsr(self, params: str) -> bytes:
        self._require_setup()
        if params == "":
            mode = PhsrMode.ALL
        else:
            if len(params) != 2:
                raise _DeviceError(ErrorCode.PARAMETER_COUNT)
            try:
                mode = PhsrMode(int(params, 16))
            except ValueError:
                raise _DeviceError(ErrorCode.PARAMETER_RANGE) from None
        selected = {
            PhsrMode.ALL: lambda p: True,
            PhsrMode.TO_BE_FREED: lambda p: False,
            PhsrMode.NOT_INITIALISED: lambda p: not p.initialised,
            PhsrMode.NOT_ENABLED: lambda p: p.initialised and not p.enabled,
            PhsrMode.ENABLED: lambda p: p.enabled,
        }[mode]
        entries = tuple(PortHandleEntry(p.handle, p.status_bits) for p in self._ports.values() if selected(p))
        return encode_payload(PortHandleList(entries).to_text())

    def _cmd_phf(self, params: str) -> bytes:
        self._require_setup()
        port = self._known_port(_parse_handle(params))
        port.initialised = port.enabled = False
        return encode_reply(OkayReply())

    def _cmd_pinit(self, params: str) -> bytes:
        self._require_setup()
        port = self._known_port(_parse_handle(params))
        if not self._field_generator_connected:
            raise _DeviceError(ErrorCode.CANNOT_INITIALISE_HANDLE)
        port.initialised = True  # re-PINIT of an initialised handle is harmless: OKAY
        return encode_reply(OkayReply())

    def _cmd_pena(self, params: str) -> bytes:
        self._require_setup()
        if len(params) != 3:
            raise _DeviceError(ErrorCode.PARAMETER_COUNT)
        port = self._known_port(_parse_handle(params[:2]))
        if params[2] not in "DSB":  # dynamic, static, button box
            raise _DeviceError(ErrorCode.PARAMETER_RANGE)
        if not port.initialised:
            raise _DeviceError(ErrorCode.PORT_NOT_INITIALISED)
        port.enabled = True
        return encode_reply(OkayReply())

    def _cmd_pdis(self, params: str) -> bytes:
        self._require_setup()
        port = self._known_port(_parse_handle(params))
        port.enabled = False
        return encode_reply(OkayReply())

    def _cmd_tstart(self, params: str) -> bytes:
        if params not in ("", "80"):  # 80: reset the frame counter
            raise _DeviceError(ErrorCode.PARAMETER_RANGE)
        self._require_setup()
        if params == "80":
            self._t0 = self.clock()
        self._tracking = True
        return encode_reply(OkayReply())

    def _cmd_tstop(self, params: str) -> bytes:
        if params:
            raise _DeviceError(ErrorCode.PARAMETER_COUNT)
        if not self._tracking:
            raise _DeviceError(ErrorCode.INVALID_MODE if self._initialised else ErrorCode.NOT_INITIALISED)
        self._tracking = False
        return encode_reply(OkayReply())

    def _tracking_frame(self, params: str) -> TrackingFrame:
        if not self._tracking:
            raise _DeviceError(ErrorCode.INVALID_MODE if self._initialised else ErrorCode.NOT_INITIALISED)
        try:
            option = parse_reply_option(params)
        except AuroraProtocolError:
            raise _DeviceError(ErrorCode.PARAMETER_COUNT) from None
        if option & ~_SUPPORTED_OPTIONS or not option & _TRANSFORMS:
            raise _DeviceError(ErrorCode.PARAMETER_RANGE)
        return self.frame(bool(option & _OUT_OF_VOLUME_OPTION))

    def _cmd_bx(self, params: str) -> bytes:
        return encode_bx(self._tracking_frame(params))

    def _cmd_tx(self, params: str) -> bytes:
        return encode_payload(encode_tx_text(self._tracking_frame(params)))

    # --- poses ----------------------------------------------------------------------

    def frame(self, report_out_of_volume: bool = True) -> TrackingFrame:
        """The tracking frame the device would report now (all initialised handles)."""
        with self._lock:
            elapsed_frames = int((self.clock() - self._t0) * FRAME_RATE_HZ)
            frame_number = elapsed_frames & 0xFFFFFFFF
            # The instant the frame began: its pose is the same whenever the host reads it.
            t_s = self._t0 + elapsed_frames / FRAME_RATE_HZ
            records = []
            for port in self._ports.values():
                if not port.initialised:
                    continue
                if not port.enabled:
                    records.append(ToolRecord(port.handle, HandleStatus.DISABLED))
                    continue
                status_bits = port.status_bits
                if port.out_of_volume:
                    status_bits |= _OUT_OF_VOLUME_BIT
                visible = (self._field_generator_connected and not port.missing
                           and (report_out_of_volume or not port.out_of_volume))
                if visible:
                    records.append(ToolRecord(port.handle, HandleStatus.VALID,
                                              self._measure(port, t_s, frame_number),
                                              status_bits, frame_number))
                else:
                    records.append(ToolRecord(port.handle, HandleStatus.MISSING, None,
                                              status_bits, frame_number))
            system = 0 if self._field_generator_connected else int(SystemStatus.HARDWARE_FAILURE)
            return TrackingFrame(tuple(records), system)

    def _measure(self, port: _Port, t_s: float, frame_number: int) -> Transform:
        if port.measured_frame == frame_number and port.measured is not None:
            return port.measured
        truth = self.plant.sensor_truth(port.sensor, t_s)
        position_sigma_mm = self.position_noise_mm / math.sqrt(3.0)
        rotation_sigma_rad = math.radians(self.orientation_noise_deg) / math.sqrt(3.0)
        # Plain floats: numpy's per-call cost on 3- and 4-vectors was most of a frame's
        # (22 us a tool; 40 frames a second are 1000 a wall second on a 25x rig).
        nx, ny, nz, rx, ry, rz = port.noise.normal(0.0, 1.0, 6).tolist()
        px, py, pz = np.asarray(truth.position_in_tracker_m, dtype=float).tolist()
        # Body-frame perturbation: the sensor's own orientation error.
        q = quat_normalize(quat_multiply(truth.orientation_in_tracker, quat_from_rotvec(
            (rx * rotation_sigma_rad, ry * rotation_sigma_rad, rz * rotation_sigma_rad))))
        port.measured = Transform(
            quaternion=tuple(q.tolist()),  # type: ignore[arg-type]
            translation_mm=(px * 1000.0 + nx * position_sigma_mm, py * 1000.0 + ny * position_sigma_mm,
                            pz * 1000.0 + nz * position_sigma_mm),
            rms_error_mm=self.position_noise_mm,
        )
        port.measured_frame = frame_number
        return port.measured


def _parse_resync(line: bytes) -> Command:
    """Parse a command line; if it does not parse, look for a valid command after
    leading garbage (a pty cannot carry a break, so garbage before INIT must not stop a
    host from re-initialising)."""
    try:
        return parse_command(line)
    except AuroraProtocolError as first_error:
        for start in range(1, len(line)):
            tail = line[start:]
            if not any(tail.startswith(name.encode()) for name in _KNOWN_COMMANDS):
                continue
            try:
                return parse_command(tail)
            except AuroraProtocolError:
                continue
        raise first_error


def _corrupt_crc(reply: bytes) -> bytes:
    """The same reply with a wrong CRC (framing intact, so the host sees a CRC error)."""
    if reply.startswith(BX_START):
        return reply[:-2] + bytes(b ^ 0xFF for b in reply[-2:])
    crc = int(reply[-5:-1], 16)
    return reply[:-5] + f"{crc ^ 0xFFFF:04X}".encode("ascii") + reply[-1:]
