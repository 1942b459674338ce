"""The rig profile format: one typed tree, one `msgspec.Struct` per TOML table.

This module is the one place the profile format is documented: each field's comment
gives its unit and meaning, its default is the value written here (or, for the rod,
capsule and jets, the HydroJet value of `hydrojet_bench.params`). Every table and key is
optional except ``[gravity] in_tracker_m_s2``; unknown tables and keys are errors.
`hydrojet_bench.config.loading` reads the TOML, resolves ``extends`` and converts.

::

    extends = "sim"        # optional: a shipped profile's name or a path relative to this
                           # file; its tables are merged under this file's, key by key
                           # (lists are replaced whole; the name is never inherited)
    name = "hydrojet-v1"   # default: the file name without .toml
    description = "..."

    [gravity] [base] [base_sensor] [tip_sensor] [rod] [capsule] [jets]   # the rig's physics
    [transports] [tracker] [imu] [valves] [session] [estimator]          # the bench session
    [twin]                                                               # the simulated rig

Frames (see `hydrojet_bench.profile`): the *tracker frame* the sensors are measured in,
the *base frame* of the clamp (z along the undeformed rod, base to tip) and the *tip
frame* at s = L. Quaternions are (w, x, y, z), scalar first, of unit norm within
`QUATERNION_NORM_TOLERANCE` (a typed-in quaternion with four digits is accepted and
renormalised).

Checks that involve a field and its table (a quaternion's norm, heartbeat against
watchdog) raise `ValueError` from ``__post_init__`` with a message that starts with the
field's name, so that the loader can report the dotted key.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from typing import Annotated

import msgspec

from drivers.aurora.client import FRAME_PERIOD_S as AURORA_FRAME_PERIOD_S
from drivers.imu.calibration import ImuCalibration
from drivers.imu.fusion import DEFAULT_FUSION, FusionName
from drivers.transport.url import open_transport
from drivers.valve.calibration import JetCalibration
from drivers.valve.protocol import DUTY_MAX_PERMILLE

from ..models import MODELS
from ..params import (JET_COUNT, MAX_PLAUSIBLE_JET_FORCE_N, MAX_PLAUSIBLE_POSITION_M, CapsuleParameters, JetLayout,
                      RodParameters, check_plausible, check_within)
from ..plans import MAX_SETTLE_S

# Device transports in [transports]: "sim" serves an in-process emulator on the digital
# twin, "pty" the same emulator on a pseudo-terminal (the serial code path).
SIM = "sim"
PTY = "pty"

# Bounding by the largest float refuses inf, and every comparison refuses nan: TOML
# spells both.
_LARGEST = sys.float_info.max
Finite = Annotated[float, msgspec.Meta(ge=-_LARGEST, le=_LARGEST)]
Positive = Annotated[float, msgspec.Meta(gt=0.0, le=_LARGEST)]
NonNegative = Annotated[float, msgspec.Meta(ge=0.0, le=_LARGEST)]
Vector3 = tuple[Finite, Finite, Finite]
Quaternion = Annotated[tuple[Finite, Finite, Finite, Finite],
                       msgspec.Meta(description="a unit quaternion [w, x, y, z]")]

IDENTITY_QUATERNION = (1.0, 0.0, 0.0, 0.0)
ZERO_VECTOR = (0.0, 0.0, 0.0)
QUATERNION_NORM_TOLERANCE = 1e-3

# A nominal valve limit for profiles that state none, not a measured figure: a real rig
# states its own.
DEFAULT_MAX_JET_FORCE_N = 0.15

@dataclass(frozen=True)
class OnlineSettings:
    """gain: the paper's lambda (0.4). damping: mu as a fraction of the largest
    eigenvalue of S S^T. iterations: model updates per quasistatic step (the paper
    reports one to two; one per sample in per-sample mode). tolerance_deg: stop
    iterating once the orientation error is below this (deg)."""

    gain: float = 0.4
    damping: float = 1e-3
    iterations: int = 2
    tolerance_deg: float = 0.05

    def __post_init__(self) -> None:
        if not 0.0 < self.gain <= 1.0:
            raise ValueError(f"estimator.gain must be in (0, 1], got {self.gain}")
        if not 0.0 <= self.damping < 1.0:
            raise ValueError(f"estimator.damping must be in [0, 1), got {self.damping}")
        if self.iterations < 1:
            raise ValueError(f"estimator.iterations must be >= 1, got {self.iterations}")
        if not self.tolerance_deg >= 0.0:
            raise ValueError(f"estimator.tolerance_deg must be >= 0, got {self.tolerance_deg}")


_ROD = RodParameters()
_CAPSULE = CapsuleParameters()
_ONLINE = OnlineSettings()
_IMU_CALIBRATION = ImuCalibration()


class Table(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """Base of every table: immutable, unknown keys refused (subclasses also pass
    ``kw_only=True``, which is not inherited)."""


def check_unit_quaternion(field: str, q: tuple[float, ...] | None) -> None:
    """Refuse a quaternion whose norm is further from 1 than rounding explains."""
    if q is None:
        return
    norm = math.sqrt(sum(v * v for v in q))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise ValueError(f"{field} must be a unit quaternion [w, x, y, z] (norm within "
                         f"{QUATERNION_NORM_TOLERANCE:g} of 1), got norm {norm:.6g}")


# --- the rig's physics ---------------------------------------------------------------


def _check_vector_within(field_name: str, vector: tuple[float, float, float], limit_m: float) -> None:
    """Each component of a position or offset (m) within +-``limit_m``: finite yet far
    larger is a unit slip, and the frame arithmetic overflows on it."""
    for axis, value in zip("xyz", vector):
        check_within(f"{field_name} ({axis})", value, -limit_m, limit_m, "m")


class GravityTable(Table, kw_only=True):
    in_tracker_m_s2: Vector3  # gravitational acceleration in the tracker frame, m/s^2

    def __post_init__(self) -> None:
        if not math.hypot(*self.in_tracker_m_s2) > 0:
            raise ValueError("in_tracker_m_s2 must not be zero")
        check_within("in_tracker_m_s2 (its length)", math.hypot(*self.in_tracker_m_s2), 0.0, 100.0, "m/s^2")


class BaseTable(Table, kw_only=True):
    """The clamp as set up (nominal: with data, the base sensor measures it)."""

    orientation_in_tracker: Quaternion | None = None  # base -> tracker; None: hanging along gravity
    position_in_tracker_m: Vector3 = ZERO_VECTOR      # clamp origin in the tracker frame, m

    def __post_init__(self) -> None:
        check_unit_quaternion("orientation_in_tracker", self.orientation_in_tracker)
        _check_vector_within("position_in_tracker_m", self.position_in_tracker_m, MAX_PLAUSIBLE_POSITION_M)


class BaseSensorTable(Table, kw_only=True):
    rotation_in_base: Quaternion = IDENTITY_QUATERNION  # sensor frame -> base frame
    offset_in_base_m: Vector3 = ZERO_VECTOR             # sensor origin in the base frame, m

    def __post_init__(self) -> None:
        check_unit_quaternion("rotation_in_base", self.rotation_in_base)
        _check_vector_within("offset_in_base_m", self.offset_in_base_m, 1.0)


class TipSensorTable(Table, kw_only=True):
    rotation_in_tip: Quaternion = IDENTITY_QUATERNION  # sensor frame -> tip frame
    offset_in_tip_m: Vector3 = ZERO_VECTOR             # sensor origin in the tip frame, m

    def __post_init__(self) -> None:
        check_unit_quaternion("rotation_in_tip", self.rotation_in_tip)
        _check_vector_within("offset_in_tip_m", self.offset_in_tip_m, 1.0)


class RodTable(Table, kw_only=True):
    """The soft rod, E linear in arc length from base to tip (`params.RodParameters`)."""

    length_m: Positive = _ROD.length_m              # L, clamp face to tip, m
    radius_m: Positive = _ROD.radius_m              # solid circular section, m
    density_kg_m3: Positive = _ROD.density_kg_m3
    # Thermodynamic bounds of an isotropic solid; 0.5 is incompressible.
    poisson_ratio: Annotated[float, msgspec.Meta(gt=-1.0, le=0.5)] = _ROD.poisson_ratio
    youngs_modulus_base_pa: Positive = _ROD.youngs_modulus_base_pa  # E at the clamp, Pa
    youngs_modulus_tip_pa: Positive = _ROD.youngs_modulus_tip_pa    # E at the tip, Pa

    def __post_init__(self) -> None:
        for name, field_name in (("E0", "youngs_modulus_base_pa"), ("EL", "youngs_modulus_tip_pa"),
                                 ("L", "length_m")):
            check_plausible(name, getattr(self, field_name), field_name)
        # Past these the rod's weight overflows or vanishes: foam to tungsten, 0.5 mm to 10 cm.
        check_within("radius_m", self.radius_m, 5e-4, 0.1, "m")
        check_within("density_kg_m3", self.density_kg_m3, 100.0, 25000.0, "kg/m^3")

    def parameters(self) -> RodParameters:
        return RodParameters(**msgspec.structs.asdict(self))


class CapsuleTable(Table, kw_only=True):
    mass_kg: NonNegative = _CAPSULE.mass_kg  # camera, jets and sensor included
    center_of_mass_in_tip_m: Vector3 = _CAPSULE.center_of_mass_in_tip_m  # tip frame, m

    def __post_init__(self) -> None:
        check_within("mass_kg", self.mass_kg, 0.0, 1.0, "kg")
        _check_vector_within("center_of_mass_in_tip_m", self.center_of_mass_in_tip_m, 1.0)

    def parameters(self) -> CapsuleParameters:
        return CapsuleParameters(self.mass_kg, self.center_of_mass_in_tip_m)


class JetsTable(Table, kw_only=True):
    # Rotation of the jet ring about the tip z axis, deg; 0 is exactly the paper's eq. 5.
    # One turn either way covers every ring; past it, a unit slip (radians read as deg?).
    ring_angle_deg: Annotated[float, msgspec.Meta(ge=-360.0, le=360.0)] = math.degrees(JetLayout().ring_angle_rad)
    # Largest force of each jet, N: one number for all, or one per jet. Commands beyond it
    # are clipped by the valves.
    max_force_n: Positive | tuple[Positive, ...] = DEFAULT_MAX_JET_FORCE_N

    def __post_init__(self) -> None:
        if isinstance(self.max_force_n, tuple) and len(self.max_force_n) != JET_COUNT:
            raise ValueError(f"max_force_n must be a number or a list of {JET_COUNT} numbers (N), "
                             f"got {len(self.max_force_n)} numbers")
        if max(self.max_force_per_jet_n) > MAX_PLAUSIBLE_JET_FORCE_N:
            raise ValueError(f"max_force_n = {max(self.max_force_per_jet_n):g} N is outside the plausible range "
                             f"0 .. {MAX_PLAUSIBLE_JET_FORCE_N:g} N (a unit slip?)")

    def layout(self) -> JetLayout:
        return JetLayout(ring_angle_rad=math.radians(self.ring_angle_deg))

    @property
    def max_force_per_jet_n(self) -> tuple[float, ...]:
        """`max_force_n` for each jet (1, 2, 3), N."""
        if isinstance(self.max_force_n, tuple):
            return tuple(float(f) for f in self.max_force_n)
        return (float(self.max_force_n),) * JET_COUNT


# --- the bench session ---------------------------------------------------------------


class TransportsTable(Table, kw_only=True):
    """Where each device is: "sim", "pty", or a transport URL (``serial:///dev/ttyUSB0?
    baud=115200``, ``pty:///dev/pts/7`` or a bare device path, see drivers/transport)."""

    valves: str = SIM
    tracker: str = SIM
    imu_bus: str | int = SIM  # "sim" (emulated ICM-20948 pair) or an I2C bus number (/dev/i2c-N)

    def __post_init__(self) -> None:
        for name in ("valves", "tracker"):
            value = getattr(self, name)
            if not (value in (SIM, PTY) or "://" in value or value.startswith("/")):
                raise ValueError(f'{name} must be "sim", "pty" or a transport URL (serial:///dev/ttyUSB0, '
                                 f"pty:///dev/pts/7, /dev/ttyUSB0), got {value!r}")
            if value not in (SIM, PTY):
                # Parsed now (not opened), so a bad scheme or baud is named with its key
                # when the profile loads rather than as a driver's error mid-session.
                try:
                    open_transport(value)
                except ValueError as error:
                    raise ValueError(f"{name} is not a usable transport URL: {error}") from None
        if self.imu_bus != SIM and (isinstance(self.imu_bus, str) or self.imu_bus < 0):
            raise ValueError(f'imu_bus must be "sim" or an I2C bus number (>= 0), got {self.imu_bus!r}')

    @property
    def simulated(self) -> bool:
        """True when any device is emulated (the session then builds a digital twin)."""
        return SIM in (self.valves, self.tracker, self.imu_bus) or PTY in (self.valves, self.tracker)

    @property
    def all_simulated(self) -> bool:
        """True when every device is emulated on the session clock, none is real."""
        return not self.real_devices()

    def real_devices(self) -> tuple[str, ...]:
        """Each device that is a real byte stream (a transport URL, a pty or serial port,
        an I2C bus), as ``transports.KEY = value``; none on the simulated rig ("pty"
        alone is the in-process emulator on a pseudo-terminal, which runs on the
        session clock)."""
        found = [f"transports.{name} = {value!r}" for name, value in (("valves", self.valves),
                                                                     ("tracker", self.tracker))
                 if value not in (SIM, PTY)]
        if self.imu_bus != SIM:
            found.append(f"transports.imu_bus = {self.imu_bus!r}")
        return tuple(found)


# The sensors the simulated rig's tracker has (the twin's).
SIMULATED_TOOLS = ("base", "tip")


class TrackerTable(Table, kw_only=True):
    tools: tuple[str, ...] = ("base", "tip")  # names of the tracker's sensors in port order
    use_tx: bool = False                      # poll TX (text) frames instead of BX (binary)
    # Polling rate; the Aurora measures at 40 Hz, so a faster poll would only repeat frames.
    rate_hz: Annotated[float, msgspec.Meta(gt=0.0, le=1.0 / AURORA_FRAME_PERIOD_S)] = 1.0 / AURORA_FRAME_PERIOD_S

    def __post_init__(self) -> None:
        if {"base", "tip"} - set(self.tools) or len(set(self.tools)) != len(self.tools):
            raise ValueError(f'tools must name each of "base" and "tip" once, got {list(self.tools)!r}')


class ImuChipTable(Table, kw_only=True):
    """Magnetometer correction of one chip (`drivers.imu.calibration.ImuCalibration`)."""

    mag_hard_iron_ut: Vector3 = _IMU_CALIBRATION.mag_hard_iron_ut  # subtracted, uT
    mag_soft_iron: tuple[Vector3, Vector3, Vector3] = _IMU_CALIBRATION.mag_soft_iron  # applied after

    def __post_init__(self) -> None:
        try:
            self.calibration()
        except ValueError as error:
            raise ValueError(f"mag_soft_iron is not a valid magnetometer correction: {error}") from None

    def calibration(self) -> ImuCalibration:
        return ImuCalibration(mag_hard_iron_ut=self.mag_hard_iron_ut, mag_soft_iron=self.mag_soft_iron)


IMU_ADDRESSES = (0x68, 0x69)  # ICM-20948: AD0 low or high


class ImuTable(Table, kw_only=True):
    base_address: int = IMU_ADDRESSES[0]
    tip_address: int = IMU_ADDRESSES[1]
    # Output rate asked of the chips (the nearest ICM-20948 rate at or above it is used:
    # 1125 Hz / (1 + divider), divider 0..255); every sample is fused and logged.
    rate_hz: Annotated[float, msgspec.Meta(ge=4.4, le=1125.0)] = 40.0
    fusion: FusionName = DEFAULT_FUSION    # "imufusion" or "madgwick": the orientation filter (docs/imu-fusion.md)
    madgwick_gain: Positive = 0.041        # Madgwick filter beta, rad/s ("madgwick" only)
    # false fuses gyro and accelerometer only: nothing then fixes the tip's heading relative to the
    # base's, and `sensors` says its heading figures measure the filters' start and drift.
    use_magnetometer: bool = True
    gyro_bias_samples: Annotated[int, msgspec.Meta(ge=0)] = 100  # at rest, before the first command
    base: ImuChipTable = msgspec.field(default_factory=ImuChipTable)  # [imu.base]: the base chip's correction
    tip: ImuChipTable = msgspec.field(default_factory=ImuChipTable)   # [imu.tip]

    def __post_init__(self) -> None:
        for name in ("base_address", "tip_address"):
            # Said in hex, as the datasheet and a bus scan (i2cdetect) give them.
            if getattr(self, name) not in IMU_ADDRESSES:
                raise ValueError(f"{name} must be 0x68 or 0x69 (the ICM-20948's AD0 pin low or high), "
                                 f"got {getattr(self, name):#04x}")
        if self.base_address == self.tip_address:
            raise ValueError(f"tip_address must differ from imu.base_address (both {self.base_address:#04x})")


class JetCalibrationTable(Table, kw_only=True):
    """One jet's measured curve: force (N) -> valve duty (per mille)."""

    force_n: tuple[float, ...]      # strictly increasing, >= 0, N
    duty_permille: tuple[int, ...]  # the duty (0..1000) giving each force

    def __post_init__(self) -> None:
        try:
            self.calibration()
        except ValueError as error:
            raise ValueError(f"force_n is not a valid calibration table: {error}") from None

    def calibration(self) -> JetCalibration:
        return JetCalibration(self.force_n, self.duty_permille)


class ValveCalibrationTable(Table, kw_only=True):
    """Per jet; a jet without a table gets duty proportional to force up to its
    ``jets.max_force_n``."""

    jet1: JetCalibrationTable | None = None
    jet2: JetCalibrationTable | None = None
    jet3: JetCalibrationTable | None = None


class ValvesTable(Table, kw_only=True):
    # The firmware's (and emulator's) silence limit; it counts whole milliseconds in 16 bits.
    watchdog_ms: Annotated[float, msgspec.Meta(ge=1.0, le=65535.0)] = 500.0
    heartbeat_ms: Positive = 100.0      # host PING when idle this long
    reply_timeout_ms: Positive = 100.0  # per request, before a retry
    retries: Annotated[int, msgspec.Meta(ge=0, le=10)] = 3  # resends of an unanswered request
    calibration: ValveCalibrationTable = msgspec.field(default_factory=ValveCalibrationTable)

    def __post_init__(self) -> None:
        if self.heartbeat_ms >= self.watchdog_ms / 2:
            # A heartbeat slower than half the watchdog trips it on ordinary scheduling jitter.
            raise ValueError(f"heartbeat_ms must be below half of valves.watchdog_ms ({self.watchdog_ms:g}), "
                             f"got {self.heartbeat_ms:g}")

    def calibrations(self, jets: JetsTable) -> tuple[JetCalibration, ...]:
        """One force -> duty table per jet: the measured one, or linear to the jet's limit."""
        tables = (self.calibration.jet1, self.calibration.jet2, self.calibration.jet3)
        return tuple(table.calibration() if table is not None
                     else JetCalibration((0.0, limit), (0, DUTY_MAX_PERMILLE))
                     for table, limit in zip(tables, jets.max_force_per_jet_n, strict=True))


# Beyond this the simulated devices' loops fall behind the session clock (measured: at
# x3000 a 1 s plan takes 1700 s of session time and no step is estimated).
MAX_TIME_SCALE = 1000.0
# Never slower than real time: the drivers' timeouts are wall time while their waits are
# session time, so below x1 the simulated IMUs' start-up overruns them (measured on the
# sim profile: x0.5 fails "estimate_gyro_bias did not finish within 15 s", x0.1
# "initialize did not finish within 5 s", x1e-300 overflows the OS's sleep), and the
# physical rig runs at x1 only.
MIN_TIME_SCALE = 1.0


MAX_FLUSH_INTERVAL_S = 60.0


class SessionTable(Table, kw_only=True):
    # hold each command this long, session s (the paper: 5 s; at most a day, as in plans)
    settle_s: Annotated[float, msgspec.Meta(gt=0.0, le=MAX_SETTLE_S)] = 5.0
    window_s: Positive = 1.0          # average the last window_s of each step, session s
    # session seconds per wall second (> 1 only when no [transports] device is real)
    time_scale: Annotated[float, msgspec.Meta(ge=MIN_TIME_SCALE, le=MAX_TIME_SCALE)] = 1.0
    # Log flush period, session s: what a crash may lose. The session's log compresses
    # and indexes each chunk on its writer thread, which holds the interpreter for part
    # of it, so a chunk must stay small in wall time too: on the simulated rig at 25x a
    # flush every 0.25 s of wall time (6 s of session data) left the tracker 97.3-98.1 %
    # of its frames, against 98.6-98.8 % with one every 10 ms. At most a minute: a crash
    # loses what was not flushed, and the log is what a session is for.
    flush_interval_s: Annotated[float, msgspec.Meta(gt=0.0, le=MAX_FLUSH_INTERVAL_S)] = 0.25

    def __post_init__(self) -> None:
        if self.window_s > self.settle_s:
            raise ValueError(f"window_s must not exceed session.settle_s ({self.settle_s:g} s), got {self.window_s:g}")


class EstimatorTable(Table, kw_only=True):
    model: str = "cosserat"          # a key of `hydrojet_bench.models.MODELS`
    effects: tuple[str, ...] = ()    # library names or file.py:Class, besides gravity
    online: bool = True              # live online disturbance estimation after calibration
    # `OnlineSettings`: the paper's lambda, damping mu (fraction of the largest eigenvalue
    # of S S^T), model updates per step, and the error (deg) below which iterating stops.
    gain: Finite = _ONLINE.gain
    damping: Finite = _ONLINE.damping
    iterations: int = _ONLINE.iterations
    tolerance_deg: Finite = _ONLINE.tolerance_deg

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise ValueError(f"model must be one of {', '.join(MODELS)}, got {self.model!r}")
        self.online_settings()  # its own ValueError names the estimator key

    def online_settings(self) -> OnlineSettings:
        return OnlineSettings(self.gain, self.damping, self.iterations, self.tolerance_deg)


# --- the simulated rig ---------------------------------------------------------------


# The noisiest sensors a simulation takes (a study's noise scale included): five
# centimetres of tracker noise, 45 degrees of orientation noise, an IMU frame drifting
# a degree per root second (35 degrees over the protocol).
_NOISE_LIMITS = {"em_position_rms_m": 0.05, "em_orientation_rms_deg": 45.0, "imu_orientation_rms_deg": 45.0,
                 "imu_drift_deg_per_sqrt_s": 1.0}


class SensorNoise(Table, kw_only=True):
    """Sensor noise of the digital twin and its emulators ([twin.noise]). Totals are RMS
    over all three axes: each axis gets total / sqrt(3), so the norm of a position error or
    the angle of an orientation error has the stated RMS.

    em_position_rms_m, em_orientation_rms_deg: EM tracker (NDI Aurora) accuracy, white,
        per sample; the orientation error is a body-frame rotation of the sensor. The
        defaults are the paper's (sec. V) figures. Both the twin's EM measurements and
        the session's Aurora emulator use them.
    imu_orientation_rms_deg: white orientation noise of an IMU-fused orientation (the
        twin's own IMU measurements; the byte-level ICM-20948 emulators of a session
        produce raw samples with their own `drivers.imu.emulator.ImuErrorModel`, and the
        session fuses them).
    imu_drift_deg_per_sqrt_s: random-walk drift of each IMU's reference frame (tracker
        side): after t seconds the drift angle has RMS ``imu_drift * sqrt(t)``. The IMU
        defaults are illustrative (a fused ICM-20948 with a magnetometer stays within a
        few tenths of a degree over the ~20 min protocol), not datasheet figures.
    """

    em_position_rms_m: NonNegative = 0.48e-3
    em_orientation_rms_deg: NonNegative = 0.70
    imu_orientation_rms_deg: NonNegative = 0.3
    imu_drift_deg_per_sqrt_s: NonNegative = 0.02

    def __post_init__(self) -> None:
        # Also built in code, where msgspec's constraints do not run.
        for name in msgspec.structs.fields(self):
            value = getattr(self, name.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= _LARGEST:
                raise ValueError(f"{name.name} must be >= 0 and finite, got {value!r}")
            if value > _NOISE_LIMITS[name.name]:
                raise ValueError(f"{name.name} = {value:g} is past {_NOISE_LIMITS[name.name]:g}: sensors that noisy "
                                 "say nothing about a rod a few centimetres long (a millimetre typed as metres?)")

    @classmethod
    def off(cls) -> SensorNoise:
        """Perfect sensors: measurements equal the truth."""
        return cls(em_position_rms_m=0.0, em_orientation_rms_deg=0.0, imu_orientation_rms_deg=0.0,
                   imu_drift_deg_per_sqrt_s=0.0)


class TwinTable(Table, kw_only=True):
    """What the digital twin hides and how it measures (`twin.TwinConfig`)."""

    seed: Annotated[int, msgspec.Meta(ge=0)] = 0  # the twin's and emulators' noise seed
    # Effects the twin's physics adds to gravity: library names or file.py:Class (relative
    # to the profile's folder).
    hidden_effects: tuple[str, ...] = ()
    settle_time_constant_s: NonNegative = 0.5  # first-order settling to a new equilibrium, s
    hidden_effect_values: dict[str, Finite] = {}  # "effect.parameter" = value
    true_parameters: dict[str, Finite] = {}       # flat names: E0, EL, L, wd_fx .. wd_mz
    noise: SensorNoise = msgspec.field(default_factory=SensorNoise)
    # Setup errors the twin simulates (`twin.SetupErrors`): cable i drives jet
    # jet_wiring[i]; the field generator tilted about tracker x then y (deg); the base
    # sensor turned in the clamp by this rotation vector (rad, clamp frame); every jet
    # force reversed (-1); every jet force scaled (the valve table in another unit).
    jet_wiring: tuple[int, int, int] = (1, 2, 3)
    tracker_tilt_deg: tuple[Finite, Finite] = (0.0, 0.0)
    base_sensor_rotvec_rad: tuple[Finite, Finite, Finite] = (0.0, 0.0, 0.0)
    jet_force_sign: int = 1
    jet_force_scale: Positive = 1.0


# --- the whole profile ---------------------------------------------------------------


class RigConfig(Table, kw_only=True):
    """One rig profile, every table typed."""

    name: str = "profile"  # the loader fills in the file name without .toml
    description: str = ""  # one line for people
    gravity: GravityTable
    base: BaseTable = msgspec.field(default_factory=BaseTable)
    base_sensor: BaseSensorTable = msgspec.field(default_factory=BaseSensorTable)
    tip_sensor: TipSensorTable = msgspec.field(default_factory=TipSensorTable)
    rod: RodTable = msgspec.field(default_factory=RodTable)
    capsule: CapsuleTable = msgspec.field(default_factory=CapsuleTable)
    jets: JetsTable = msgspec.field(default_factory=JetsTable)
    transports: TransportsTable = msgspec.field(default_factory=TransportsTable)
    tracker: TrackerTable = msgspec.field(default_factory=TrackerTable)
    imu: ImuTable = msgspec.field(default_factory=ImuTable)
    valves: ValvesTable = msgspec.field(default_factory=ValvesTable)
    session: SessionTable = msgspec.field(default_factory=SessionTable)
    estimator: EstimatorTable = msgspec.field(default_factory=EstimatorTable)
    twin: TwinTable = msgspec.field(default_factory=TwinTable)

    def __post_init__(self) -> None:
        # A step's value is the mean of its last window_s; a window that holds no sample
        # of a stream leaves every step without that sensor (two samples: one may be lost).
        slowest_hz, stream = min((self.tracker.rate_hz, "tracker.rate_hz"), (self.imu.rate_hz, "imu.rate_hz"))
        if self.session.window_s < 2.0 / slowest_hz:
            raise ValueError(f"session.window_s = {self.session.window_s:g} s holds fewer than two samples of the "
                             f"slowest stream ({stream} = {slowest_hz:g}): make it at least {2.0 / slowest_hz:g} s")
        real = self.transports.real_devices()
        if real and self.session.time_scale != 1.0:
            # A real device keeps wall time (its firmware watchdog, the Aurora's frames):
            # a faster session clock would hold each command a fraction of its settle_s.
            # Said from the device's key: the profile that names it is the one to fix,
            # whichever file the time scale came from (sim.toml's x25, extended).
            raise ValueError(f"{real[0]} is a real device, and a rig with any real device runs on wall time, but "
                             f"session.time_scale = {self.session.time_scale:g}: set time_scale = 1 under [session] "
                             "(only the fully simulated rig runs faster)")
        extra_tools = [tool for tool in self.tracker.tools if tool not in SIMULATED_TOOLS]
        if self.transports.tracker in (SIM, PTY) and extra_tools:
            raise ValueError(f"tracker.tools names {', '.join(map(repr, extra_tools))}, but the simulated tracker "
                             f"(transports.tracker = {self.transports.tracker!r}) has the {' and '.join(SIMULATED_TOOLS)} "
                             "sensors only")

    def valve_calibrations(self) -> tuple[JetCalibration, ...]:
        """The valve client's force -> duty table per jet."""
        return self.valves.calibrations(self.jets)
