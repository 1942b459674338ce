"""What a bench session needs from the rig profile beyond the physics: devices, timing
and the live estimator, validated on load.

Schema (all tables and keys optional; unknown keys are errors naming file and key)::

    [transports]
    valves = "sim"      # "sim": in-process emulator on the digital twin; "pty": the same
    tracker = "sim"     #   emulator served on a pseudo-terminal (the serial code path);
                        #   else a transport URL: serial:///dev/ttyUSB0?baud=115200,
                        #   pty:///dev/pts/7 or a bare device path (drivers/transport)
    imu_bus = "sim"     # "sim" (emulated ICM-20948 pair) or an I2C bus number (/dev/i2c-N)

    [tracker]
    tools = ["base", "tip"]   # names given to the tracker's sensors in port order
    use_tx = false            # poll TX (text) frames instead of BX (binary)
    rate_hz = 40.0            # polling rate (the Aurora delivers 40 frames/s)

    [imu]
    base_address = 0x68       # ICM-20948 AD0 low; the tip chip has AD0 high
    tip_address = 0x69
    rate_hz = 40.0            # fusion and logging rate
    madgwick_gain = 0.041     # beta, rad/s
    use_magnetometer = true
    gyro_bias_samples = 100   # at rest, before the first command
    [imu.base]                # per chip, optional: magnetometer correction, uT
    mag_hard_iron_ut = [0, 0, 0]
    mag_soft_iron = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]

    [valves]
    watchdog_ms = 500         # the firmware's (and emulator's) silence limit
    heartbeat_ms = 100        # host PING when idle this long
    reply_timeout_ms = 100
    retries = 3
    [valves.calibration]      # per jet: force (N) -> duty (per mille) table
    jet1 = { force_n = [0.0, 0.15], duty_permille = [0, 1000] }   # default: linear to max

    [session]
    settle_s = 5.0            # hold each command this long (the paper: 5 s)
    window_s = 1.0            # average the last window_s of each step
    time_scale = 1.0          # virtual seconds per wall second (> 1 only on the sim rig)
    flush_interval_s = 1.0    # log chunk flush period (wall time): what a crash may lose

    [estimator]
    model = "cosserat"        # or "prb"
    effects = []              # library names or file.py:Class, besides gravity
    online = true             # live online disturbance estimation after calibration
    gain = 0.4                # OnlineSettings: lambda, damping mu, iterations, tolerance
    damping = 1e-3
    iterations = 2
    tolerance_deg = 0.05
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from drivers.imu.calibration import ImuCalibration
from drivers.valve.calibration import JetCalibration
from drivers.valve.protocol import DUTY_MAX_PERMILLE

from ..errors import UserError
from ..estimation import OnlineSettings
from ..models import MODELS
from ..profile import RigProfile, TableReader

SIM = "sim"
PTY = "pty"
TABLE_KEYS: dict[str, tuple[str, ...]] = {
    "transports": ("valves", "tracker", "imu_bus"),
    "tracker": ("tools", "use_tx", "rate_hz"),
    "imu": ("base_address", "tip_address", "rate_hz", "madgwick_gain", "use_magnetometer",
            "gyro_bias_samples", "base", "tip"),
    "imu_chip": ("mag_hard_iron_ut", "mag_soft_iron"),
    "valves": ("watchdog_ms", "heartbeat_ms", "reply_timeout_ms", "retries", "calibration"),
    "valves_calibration": ("jet1", "jet2", "jet3"),
    "session": ("settle_s", "window_s", "time_scale", "flush_interval_s"),
    "estimator": ("model", "effects", "online", "gain", "damping", "iterations", "tolerance_deg"),
}


@dataclass(frozen=True)
class TransportSettings:
    """valves, tracker: "sim", "pty" or a transport URL. imu_bus: "sim" or a bus number."""

    valves: str = SIM
    tracker: str = SIM
    imu_bus: str | int = SIM

    @property
    def simulated(self) -> bool:
        """True when any device is emulated (the session then builds a digital twin)."""
        return SIM in (self.valves, self.tracker, self.imu_bus) or PTY in (self.valves, self.tracker)


@dataclass(frozen=True)
class TrackerSettings:
    tools: tuple[str, ...] = ("base", "tip")
    use_tx: bool = False
    rate_hz: float = 40.0


@dataclass(frozen=True)
class ImuSettings:
    base_address: int = 0x68
    tip_address: int = 0x69
    rate_hz: float = 40.0
    madgwick_gain: float = 0.041
    use_magnetometer: bool = True
    gyro_bias_samples: int = 100
    base_calibration: ImuCalibration = field(default_factory=ImuCalibration)
    tip_calibration: ImuCalibration = field(default_factory=ImuCalibration)


@dataclass(frozen=True)
class ValveSettings:
    watchdog_ms: float = 500.0
    heartbeat_ms: float = 100.0
    reply_timeout_ms: float = 100.0
    retries: int = 3
    calibrations: tuple[JetCalibration, ...] = ()


@dataclass(frozen=True)
class SessionTiming:
    """settle_s: hold per command (s, session time). window_s: averaging window at the
    end of each step (s). time_scale: session seconds per wall second. flush_interval_s:
    log flush period (wall s)."""

    settle_s: float = 5.0
    window_s: float = 1.0
    time_scale: float = 1.0
    flush_interval_s: float = 1.0


@dataclass(frozen=True)
class EstimatorSettings:
    model: str = "cosserat"
    effects: tuple[str, ...] = ()
    online: bool = True
    online_settings: OnlineSettings = field(default_factory=OnlineSettings)


@dataclass(frozen=True)
class BenchSettings:
    transports: TransportSettings
    tracker: TrackerSettings
    imu: ImuSettings
    valves: ValveSettings
    timing: SessionTiming
    estimator: EstimatorSettings


def bench_settings(profile: RigProfile) -> BenchSettings:
    """The profile's bench tables, validated; every error is a `UserError` naming the
    profile file and the dotted key."""
    document = {name: profile.table(name) for name in ("transports", "tracker", "imu", "valves",
                                                        "session", "estimator")}
    reader = TableReader(profile.source, document, TABLE_KEYS)
    return BenchSettings(
        transports=_transports(reader),
        tracker=_tracker(reader),
        imu=_imu(reader),
        valves=_valves(reader, profile),
        timing=_timing(reader),
        estimator=_estimator(reader),
    )


def _positive(reader: TableReader, table: str, key: str, default: float) -> float:
    value = reader.number(table, key, positive=True)
    return default if value is None else value


def _device(reader: TableReader, key: str, default: str) -> str:
    value = reader.string("transports", key)
    if value is None:
        return default
    if value in (SIM, PTY) or "://" in value or value.startswith("/"):
        return value
    raise reader.fail(f"transports.{key}", f'must be "sim", "pty" or a transport URL (serial:///dev/ttyUSB0, '
                      f"pty:///dev/pts/7, /dev/ttyUSB0), got {value!r}")


def _transports(reader: TableReader) -> TransportSettings:
    values = reader.table("transports")
    bus: str | int = SIM
    if "imu_bus" in values:
        raw = values["imu_bus"]
        if raw != SIM and (isinstance(raw, bool) or not isinstance(raw, int) or raw < 0):
            raise reader.fail("transports.imu_bus", f'must be "sim" or an I2C bus number (>= 0), got {raw!r}')
        bus = raw
    return TransportSettings(_device(reader, "valves", SIM), _device(reader, "tracker", SIM), bus)


def _tracker(reader: TableReader) -> TrackerSettings:
    tools = reader.strings("tracker", "tools") or ("base", "tip")
    missing = {"base", "tip"} - set(tools)
    if missing or len(set(tools)) != len(tools):
        raise reader.fail("tracker.tools", f'must name each of "base" and "tip" once, got {list(tools)!r}')
    return TrackerSettings(tools, bool(reader.boolean("tracker", "use_tx")),
                           _positive(reader, "tracker", "rate_hz", 40.0))


def _imu(reader: TableReader) -> ImuSettings:
    base = reader.integer("imu", "base_address", minimum=0x68, maximum=0x69)
    tip = reader.integer("imu", "tip_address", minimum=0x68, maximum=0x69)
    base = 0x68 if base is None else base
    tip = 0x69 if tip is None else tip
    if base == tip:
        raise reader.fail("imu.tip_address", f"must differ from imu.base_address (both {base:#04x})")
    samples = reader.integer("imu", "gyro_bias_samples", minimum=0)
    use_magnetometer = reader.boolean("imu", "use_magnetometer")
    return ImuSettings(
        base_address=base, tip_address=tip,
        rate_hz=_positive(reader, "imu", "rate_hz", 40.0),
        madgwick_gain=_positive(reader, "imu", "madgwick_gain", 0.041),
        use_magnetometer=True if use_magnetometer is None else use_magnetometer,
        gyro_bias_samples=100 if samples is None else samples,
        base_calibration=_imu_calibration(reader, "base"),
        tip_calibration=_imu_calibration(reader, "tip"),
    )


def _imu_calibration(reader: TableReader, chip: str) -> ImuCalibration:
    raw = reader.table("imu").get(chip, {})
    if not isinstance(raw, Mapping):
        raise reader.fail(f"imu.{chip}", "must be a table ([imu.%s])" % chip)
    sub = TableReader(reader.source, {f"imu.{chip}": raw}, {f"imu.{chip}": TABLE_KEYS["imu_chip"]})
    hard = sub.vector(f"imu.{chip}", "mag_hard_iron_ut", 3) or (0.0, 0.0, 0.0)
    soft = raw.get("mag_soft_iron", [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    try:
        return ImuCalibration(mag_hard_iron_ut=hard, mag_soft_iron=soft)
    except (TypeError, ValueError) as error:
        raise reader.fail(f"imu.{chip}", f"is not a valid magnetometer correction: {error}") from None


def _valves(reader: TableReader, profile: RigProfile) -> ValveSettings:
    retries = reader.integer("valves", "retries", minimum=0, maximum=10)
    raw = reader.table("valves").get("calibration", {})
    if not isinstance(raw, Mapping):
        raise reader.fail("valves.calibration", "must be a table ([valves.calibration])")
    unknown = sorted(set(raw) - set(TABLE_KEYS["valves_calibration"]))
    if unknown:
        raise reader.fail(f"valves.calibration.{unknown[0]}", "is not a known key; use jet1, jet2, jet3")
    calibrations = []
    for index, limit in enumerate(profile.max_jet_force_n):
        key = f"jet{index + 1}"
        table = raw.get(key)
        if table is None:
            # No measured curve: duty proportional to force up to the jet's rated maximum.
            calibrations.append(JetCalibration((0.0, limit), (0, DUTY_MAX_PERMILLE)))
            continue
        if not isinstance(table, Mapping) or set(table) != {"force_n", "duty_permille"}:
            raise reader.fail(f"valves.calibration.{key}", "must be { force_n = [...], duty_permille = [...] }")
        try:
            calibrations.append(JetCalibration(tuple(table["force_n"]), tuple(table["duty_permille"])))
        except (TypeError, ValueError) as error:
            raise reader.fail(f"valves.calibration.{key}", f"is not a valid calibration table: {error}") from None
    heartbeat = _positive(reader, "valves", "heartbeat_ms", 100.0)
    watchdog = _positive(reader, "valves", "watchdog_ms", 500.0)
    if heartbeat >= watchdog / 2:
        # A heartbeat slower than half the watchdog trips it on ordinary scheduling jitter.
        raise reader.fail("valves.heartbeat_ms", f"must be below half of valves.watchdog_ms ({watchdog:g}), "
                          f"got {heartbeat:g}")
    return ValveSettings(watchdog, heartbeat, _positive(reader, "valves", "reply_timeout_ms", 100.0),
                         3 if retries is None else retries, tuple(calibrations))


def _timing(reader: TableReader) -> SessionTiming:
    settle = _positive(reader, "session", "settle_s", 5.0)
    window = _positive(reader, "session", "window_s", 1.0)
    if window > settle:
        raise reader.fail("session.window_s", f"must not exceed session.settle_s ({settle:g} s), got {window:g}")
    return SessionTiming(settle, window, _positive(reader, "session", "time_scale", 1.0),
                         _positive(reader, "session", "flush_interval_s", 1.0))


def _estimator(reader: TableReader) -> EstimatorSettings:
    model = reader.string("estimator", "model") or "cosserat"
    if model not in MODELS:
        raise reader.fail("estimator.model", f"must be one of {', '.join(MODELS)}, got {model!r}")
    online = reader.boolean("estimator", "online")
    values: dict[str, Any] = {}
    for key in ("gain", "damping", "tolerance_deg"):
        number = reader.number("estimator", key)
        if number is not None:
            values[key] = number
    iterations = reader.integer("estimator", "iterations", minimum=1)
    if iterations is not None:
        values["iterations"] = iterations
    try:
        settings = OnlineSettings(**values)
    except ValueError as error:
        raise UserError(f"{reader.source}: {error}") from None
    return EstimatorSettings(model, reader.strings("estimator", "effects") or (),
                             True if online is None else online, settings)
