"""Rig profiles: what a measurement table does not say about the rig, read from TOML.

A profile describes one rig (the physical HydroJet bench, or the simulated one): the
direction of gravity in the tracker frame, where the two orientation sensors sit on
their bodies, the rod and capsule, and the jets. ``load_profile(path)`` reads and
validates it; ``profile.model_parameters()`` turns it into `ModelParameters`.

Frames
------
* *tracker frame*: the frame the sensors are measured in (the EM tracker's, or the
  world frame of the IMU orientation filter). Dataset orientations and positions live
  here.
* *base frame*: the clamp's frame, z along the undeformed rod from base to tip (the
  frame the models work in, see `hydrojet_bench.params`).
* *tip frame*: the rod's material frame at s = L.

A sensor is mounted on its body by a fixed rotation and offset, with the same convention
as `RodProblem`'s ``*_sensor_mounting``: ``R_sensor = R_body @ R_mount`` and
``p_sensor = p_body + R_body @ offset``. So the measured base sensor orientation times
the inverse base mounting is the clamp's orientation in the tracker frame, and gravity
in the base frame is ``R_clamp_in_tracker^T g_tracker``. That changes with every sample
if the base moves, which is why `ModelParameters.gravity_in_base_m_s2` is filled *per
sample or per quasistatic step* from the measured base orientation
(`RigProfile.gravity_in_base_m_s2`, `RigProfile.model_parameters(base_sensor_orientation)`,
`Dataset.gravity_in_base_m_s2()`), and from the profile's nominal clamp orientation only
when no measurement is at hand.

Schema (every key optional unless marked; unknown keys inside these tables are errors)
------------------------------------------------------------------------------------
::

    name = "hydrojet-v1"              # default: the file name without .toml
    description = "..."

    [gravity]
    in_tracker_m_s2 = [0, 0, -9.81]   # REQUIRED: gravitational acceleration, tracker frame

    [base]                             # the clamp, as set up (nominal; the sensor measures it)
    orientation_in_tracker = [w, x, y, z]   # default: rod axis hanging along gravity
    position_in_tracker_m = [x, y, z]       # default [0, 0, 0]

    [base_sensor]                      # defaults: at the clamp, with the base frame's axes
    rotation_in_base = [1, 0, 0, 0]    # sensor frame -> base frame, (w, x, y, z)
    offset_in_base_m = [0, 0, 0]       # sensor origin in the base frame

    [tip_sensor]                       # defaults: at the rod tip, with the tip frame's axes
    rotation_in_tip = [1, 0, 0, 0]
    offset_in_tip_m = [0, 0, 0]

    [rod]        # length_m radius_m density_kg_m3 poisson_ratio youngs_modulus_base_pa youngs_modulus_tip_pa
    [capsule]    # mass_kg center_of_mass_in_tip_m
    [jets]       # ring_angle_deg (0 = paper eq. 5); max_force_n (one number or one per jet)

Defaults for [rod], [capsule] and [jets] are the HydroJet values of
`hydrojet_bench.params`. Any other top-level table ([transports], [imu], [tracker],
[valves], [estimator], [twin], ...) belongs to other parts of the bench: it is kept raw,
unvalidated, in `RigProfile.extra_tables` (see `RigProfile.table`).

Every error is a `UserError` naming the file and the dotted key and saying what was
expected, e.g. ``profiles/x.toml: rod.length_m must be > 0, got -0.07``.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from .errors import UserError
from .geometry import matrix_from_quat, quat_conjugate, quat_from_matrix, quat_multiply, quat_rotate, se3
from .params import CapsuleParameters, JetLayout, ModelParameters, RodParameters

Vector3 = tuple[float, float, float]
Quaternion = tuple[float, float, float, float]

# Where the shipped profiles live (a checkout or an editable install).
PROFILES_DIR = Path(__file__).resolve().parent.parent / "profiles"

# A profile quaternion may be written with a few digits (0.7071...); anything further
# from unit norm than this is a typo, not rounding.
_QUATERNION_NORM_TOLERANCE = 1e-3

# Tables other parts of the bench are expected to add; listed for documentation only:
# every unknown top-level table is kept raw, whether listed here or not.
EXTENSION_TABLES = ("transports", "imu", "tracker", "valves", "estimator", "twin")

_TOP_LEVEL_KEYS = ("name", "description")
_TABLE_KEYS: dict[str, tuple[str, ...]] = {
    "gravity": ("in_tracker_m_s2",),
    "base": ("orientation_in_tracker", "position_in_tracker_m"),
    "base_sensor": ("rotation_in_base", "offset_in_base_m"),
    "tip_sensor": ("rotation_in_tip", "offset_in_tip_m"),
    "rod": ("length_m", "radius_m", "density_kg_m3", "poisson_ratio",
            "youngs_modulus_base_pa", "youngs_modulus_tip_pa"),
    "capsule": ("mass_kg", "center_of_mass_in_tip_m"),
    "jets": ("ring_angle_deg", "max_force_n"),
}

# Default jet force limit (N): the top of `hydrojet-bench demo`'s sweep. Not a measured
# figure: a real rig states its own (jets.max_force_n).
DEFAULT_MAX_JET_FORCE_N = 0.15


def _unit_quaternion(value: ArrayLike) -> np.ndarray:
    q = np.asarray(value, dtype=float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def hanging_orientation(gravity_in_tracker_m_s2: ArrayLike) -> Quaternion:
    """The clamp orientation (w, x, y, z) whose z axis points along gravity (a rod hanging
    straight down), by the shortest rotation from the tracker's z axis; when gravity is
    along -z the half turn is taken about the tracker's x axis."""
    g = np.asarray(gravity_in_tracker_m_s2, dtype=float)
    down = g / np.linalg.norm(g)
    z = np.array([0.0, 0.0, 1.0])
    cos_angle = float(np.dot(z, down))
    if cos_angle < -1.0 + 1e-12:
        return (0.0, 1.0, 0.0, 0.0)
    # Half-angle form: q = (1 + cos, z x down) normalised.
    q = _unit_quaternion(np.concatenate([[1.0 + cos_angle], np.cross(z, down)]))
    return tuple(float(v) for v in q)  # type: ignore[return-value]


@dataclass(frozen=True)
class SensorMounting:
    """How a sensor sits on its body (the clamp or the rod tip).

    rotation_in_body: unit quaternion (w, x, y, z) mapping sensor-frame vectors into the
        body frame, so ``R_sensor = R_body @ R(rotation_in_body)``.
    offset_in_body_m: the sensor's origin in the body frame, m.
    """

    rotation_in_body: Quaternion = (1.0, 0.0, 0.0, 0.0)
    offset_in_body_m: Vector3 = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        q = np.asarray(self.rotation_in_body, dtype=float)
        if q.shape != (4,) or not np.all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1.0) > _QUATERNION_NORM_TOLERANCE:
            raise ValueError(f"rotation_in_body must be a unit quaternion (w, x, y, z), got {self.rotation_in_body!r}")
        p = np.asarray(self.offset_in_body_m, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"offset_in_body_m must be 3 finite numbers, got {self.offset_in_body_m!r}")
        object.__setattr__(self, "rotation_in_body", tuple(float(v) for v in _unit_quaternion(q)))
        object.__setattr__(self, "offset_in_body_m", tuple(float(v) for v in p))

    def body_orientation(self, sensor_orientation: ArrayLike) -> np.ndarray:
        """Body orientation(s) in the tracker frame from sensor orientation(s) (..., 4):
        ``q_body = q_sensor * conj(q_mount)``."""
        return quat_multiply(np.asarray(sensor_orientation, dtype=float),
                             quat_conjugate(self.rotation_in_body))

    def sensor_orientation(self, body_orientation: ArrayLike) -> np.ndarray:
        """Sensor orientation(s) from body orientation(s): ``q_sensor = q_body * q_mount``."""
        return quat_multiply(np.asarray(body_orientation, dtype=float), np.asarray(self.rotation_in_body))

    def body_position_m(self, sensor_orientation: ArrayLike, sensor_position_m: ArrayLike) -> np.ndarray:
        """Body origin(s) in the tracker frame from sensor pose(s):
        ``p_body = p_sensor - R_body @ offset``."""
        body = self.body_orientation(sensor_orientation)
        return np.asarray(sensor_position_m, dtype=float) - quat_rotate(body, self.offset_in_body_m)

    def transform(self) -> np.ndarray:
        """4x4 pose of the sensor in the body frame (``g_sensor_in_body``)."""
        return se3(matrix_from_quat(self.rotation_in_body), self.offset_in_body_m)


class SensorPoses(NamedTuple):
    """What the two sensors read, tracker frame: orientations (..., 4) as (w, x, y, z)
    and positions (..., 3) in m."""

    base_orientation: np.ndarray
    base_position_m: np.ndarray
    tip_orientation: np.ndarray
    tip_position_m: np.ndarray


@dataclass(frozen=True)
class RigProfile:
    """One rig, as `load_profile` reads it (see the module docstring for the schema).

    gravity_in_tracker_m_s2: gravitational acceleration in the tracker frame, m/s^2.
    base_orientation_in_tracker, base_position_in_tracker_m: the clamp's nominal pose in
        the tracker frame (the simulated rig places its clamp here; with real data the
        base sensor measures it).
    base_sensor, tip_sensor: mountings on the clamp and on the rod tip.
    rod, capsule, jets: as in `ModelParameters`.
    max_jet_force_n: largest force each jet (1, 2, 3) can deliver, N; commands beyond it
        are clipped by the valves.
    extra_tables: unknown top-level tables, raw (read-only mapping of plain TOML values).
    path: the file it came from, or None if built in code.
    """

    name: str = "default"
    gravity_in_tracker_m_s2: Vector3 = (0.0, 0.0, -9.81)
    base_orientation_in_tracker: Quaternion = (0.0, 1.0, 0.0, 0.0)
    base_position_in_tracker_m: Vector3 = (0.0, 0.0, 0.0)
    base_sensor: SensorMounting = field(default_factory=SensorMounting)
    tip_sensor: SensorMounting = field(default_factory=SensorMounting)
    rod: RodParameters = field(default_factory=RodParameters)
    capsule: CapsuleParameters = field(default_factory=CapsuleParameters)
    jets: JetLayout = field(default_factory=JetLayout)
    max_jet_force_n: Vector3 = (DEFAULT_MAX_JET_FORCE_N,) * 3
    description: str = ""
    path: Path | None = None
    extra_tables: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        g = np.asarray(self.gravity_in_tracker_m_s2, dtype=float)
        if g.shape != (3,) or not np.all(np.isfinite(g)) or not np.linalg.norm(g) > 0:
            raise ValueError(f"gravity_in_tracker_m_s2 must be 3 finite numbers, not all zero, "
                             f"got {self.gravity_in_tracker_m_s2!r}")
        q = np.asarray(self.base_orientation_in_tracker, dtype=float)
        if q.shape != (4,) or not np.all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1.0) > _QUATERNION_NORM_TOLERANCE:
            raise ValueError("base_orientation_in_tracker must be a unit quaternion (w, x, y, z), "
                             f"got {self.base_orientation_in_tracker!r}")
        p = np.asarray(self.base_position_in_tracker_m, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"base_position_in_tracker_m must be 3 finite numbers, got {self.base_position_in_tracker_m!r}")
        limits = np.asarray(self.max_jet_force_n, dtype=float)
        if limits.shape != (3,) or not np.all(np.isfinite(limits)) or np.any(limits <= 0):
            raise ValueError(f"max_jet_force_n must be 3 finite numbers > 0, got {self.max_jet_force_n!r}")
        object.__setattr__(self, "gravity_in_tracker_m_s2", tuple(float(v) for v in g))
        object.__setattr__(self, "base_orientation_in_tracker", tuple(float(v) for v in _unit_quaternion(q)))
        object.__setattr__(self, "base_position_in_tracker_m", tuple(float(v) for v in p))
        object.__setattr__(self, "max_jet_force_n", tuple(float(v) for v in limits))
        object.__setattr__(self, "extra_tables", MappingProxyType(dict(self.extra_tables)))

    @property
    def source(self) -> str:
        """How to name this profile in messages: its file, or its name."""
        return str(self.path) if self.path is not None else f"profile {self.name!r}"

    def table(self, name: str) -> dict[str, Any]:
        """A raw extension table such as ``"transports"``; empty if the profile has none."""
        value = self.extra_tables.get(name, {})
        return dict(value) if isinstance(value, Mapping) else {}

    # --- frames ------------------------------------------------------------------

    def clamp_orientation_in_tracker(self, base_sensor_orientation: ArrayLike | None = None) -> np.ndarray:
        """Clamp (base frame) orientation(s) in the tracker frame, (w, x, y, z): from measured
        base sensor orientation(s) (..., 4), or the nominal one when None."""
        if base_sensor_orientation is None:
            return np.array(self.base_orientation_in_tracker)
        return self.base_sensor.body_orientation(base_sensor_orientation)

    def gravity_in_base_m_s2(self, base_sensor_orientation: ArrayLike | None = None) -> np.ndarray:
        """Gravity in the base frame, m/s^2: ``R_clamp^T g_tracker`` with the clamp
        orientation from base sensor orientation(s) (..., 4) -> (..., 3), or from the
        nominal clamp orientation when None -> (3,)."""
        clamp = self.clamp_orientation_in_tracker(base_sensor_orientation)
        return quat_rotate(quat_conjugate(clamp), np.asarray(self.gravity_in_tracker_m_s2))

    def sensor_poses_in_tracker(self, tip_pose_in_base: ArrayLike,
                                clamp_orientation_in_tracker: ArrayLike | None = None,
                                clamp_position_in_tracker_m: ArrayLike | None = None) -> SensorPoses:
        """What ideal sensors on this rig read for a rod shape: the inverse of
        `Dataset.tip_orientation_in_base` / `tip_position_in_base_m`.

        tip_pose_in_base: 4x4 (or a stack (..., 4, 4)) pose of the rod tip in the base
            frame, as a model's ``Solution.tip_pose_in_base``.
        clamp_orientation_in_tracker, clamp_position_in_tracker_m: the clamp's pose
            (default: the profile's nominal one).
        """
        g = np.asarray(tip_pose_in_base, dtype=float)
        clamp_q = np.asarray(self.base_orientation_in_tracker if clamp_orientation_in_tracker is None
                             else clamp_orientation_in_tracker, dtype=float)
        clamp_p = np.asarray(self.base_position_in_tracker_m if clamp_position_in_tracker_m is None
                             else clamp_position_in_tracker_m, dtype=float)
        tip_body_q = quat_multiply(clamp_q, quat_from_matrix(g[..., :3, :3]))
        tip_body_p = clamp_p + quat_rotate(clamp_q, g[..., :3, 3])
        base_q = self.base_sensor.sensor_orientation(clamp_q)
        base_p = clamp_p + quat_rotate(clamp_q, self.base_sensor.offset_in_body_m)
        shape = tip_body_q.shape
        return SensorPoses(
            base_orientation=np.broadcast_to(base_q, shape).copy(),
            base_position_m=np.broadcast_to(base_p, shape[:-1] + (3,)).copy(),
            tip_orientation=self.tip_sensor.sensor_orientation(tip_body_q),
            tip_position_m=tip_body_p + quat_rotate(tip_body_q, self.tip_sensor.offset_in_body_m),
        )

    def model_parameters(self, base_sensor_orientation: ArrayLike | None = None, **changes: Any) -> ModelParameters:
        """`ModelParameters` of this rig: rod, capsule, jets, and gravity in the base frame
        for one base sensor orientation (4,) (None: the nominal clamp orientation).

        For data with a moving base, make one per sample or per quasistatic step (or
        ``dataclasses.replace(params, gravity_in_base_m_s2=...)`` with
        `Dataset.gravity_in_base_m_s2`). ``changes`` are further `ModelParameters` fields
        (``disturbance=``, ``effect_values=``)."""
        if base_sensor_orientation is not None and np.shape(base_sensor_orientation) != (4,):
            raise ValueError("model_parameters takes one base sensor orientation (4,), got shape "
                             f"{np.shape(base_sensor_orientation)}; use gravity_in_base_m_s2 for many")
        gravity = self.gravity_in_base_m_s2(base_sensor_orientation)
        return ModelParameters(rod=self.rod, capsule=self.capsule, jets=self.jets,
                               gravity_in_base_m_s2=tuple(float(v) for v in gravity), **changes)


# --- loading ---------------------------------------------------------------------


def resolve_profile_path(spec: str | Path) -> Path:
    """A profile file from a path, or from the name of a shipped profile (``"sim"`` ->
    ``profiles/sim.toml``) when no such file exists."""
    path = Path(spec)
    if path.is_file():
        return path
    if path.suffix == "" and path.parent == Path("."):
        shipped = PROFILES_DIR / f"{path.name}.toml"
        if shipped.is_file():
            return shipped
    known = ", ".join(sorted(p.stem for p in PROFILES_DIR.glob("*.toml"))) or "none"
    raise UserError(f"rig profile {str(spec)!r} not found: give a TOML file or the name of a "
                    f"shipped profile ({known})")


class TableReader:
    """Typed access to one profile document, raising `UserError` naming file and key.
    ``table_keys``: the tables this reader owns and the keys each takes."""

    def __init__(self, source: str, document: Mapping[str, Any],
                 table_keys: Mapping[str, tuple[str, ...]] = _TABLE_KEYS) -> None:
        self.source = source
        self.document = document
        self.table_keys = table_keys

    def fail(self, key: str, message: str) -> UserError:
        return UserError(f"{self.source}: {key} {message}")

    def table(self, name: str) -> Mapping[str, Any]:
        value = self.document.get(name, {})
        if not isinstance(value, Mapping):
            raise self.fail(name, f"must be a table ([{name}]), got {_describe(value)}")
        allowed = self.table_keys[name]
        for key in value:
            if key not in allowed:
                raise self.fail(f"{name}.{key}", f"is not a known key; [{name}] takes {', '.join(allowed)}")
        return value

    def number(self, table: str, key: str, *, positive: bool = False, minimum: float | None = None,
               required: bool = False) -> float | None:
        values = self.table(table)
        dotted = f"{table}.{key}"
        if key not in values:
            if required:
                raise self.fail(dotted, "is required")
            return None
        value = values[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(dotted, f"must be a number, got {_describe(value)}")
        value = float(value)
        if not math.isfinite(value):
            raise self.fail(dotted, f"must be finite, got {value!r}")
        if positive and not value > 0:
            raise self.fail(dotted, f"must be > 0, got {value!r}")
        if minimum is not None and value < minimum:
            raise self.fail(dotted, f"must be >= {minimum:g}, got {value!r}")
        return value

    def vector(self, table: str, key: str, size: int, *, required: bool = False,
               what: str = "") -> tuple[float, ...] | None:
        values = self.table(table)
        dotted = f"{table}.{key}"
        expected = what or f"a list of {size} numbers"
        if key not in values:
            if required:
                raise self.fail(dotted, f"is required ({expected})")
            return None
        value = values[key]
        if not isinstance(value, list) or len(value) != size:
            raise self.fail(dotted, f"must be {expected}, got {_describe(value)}")
        for index, item in enumerate(value):
            if isinstance(item, bool) or not isinstance(item, (int, float)) or not math.isfinite(item):
                raise self.fail(f"{dotted}[{index}]", f"must be a finite number, got {_describe(item)}")
        return tuple(float(v) for v in value)

    def quaternion(self, table: str, key: str) -> Quaternion | None:
        q = self.vector(table, key, 4, what="a unit quaternion [w, x, y, z]")
        if q is None:
            return None
        norm = math.sqrt(sum(v * v for v in q))
        if abs(norm - 1.0) > _QUATERNION_NORM_TOLERANCE:
            raise self.fail(f"{table}.{key}", f"must be a unit quaternion [w, x, y, z] (norm within "
                            f"{_QUATERNION_NORM_TOLERANCE:g} of 1), got norm {norm:.6g}")
        return tuple(v / norm for v in q)  # type: ignore[return-value]

    def integer(self, table: str, key: str, *, minimum: int | None = None,
                maximum: int | None = None) -> int | None:
        values = self.table(table)
        if key not in values:
            return None
        value = values[key]
        dotted = f"{table}.{key}"
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(dotted, f"must be an integer, got {_describe(value)}")
        if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
            bounds = f"{minimum if minimum is not None else '-inf'}..{maximum if maximum is not None else 'inf'}"
            raise self.fail(dotted, f"must be in {bounds}, got {value!r}")
        return value

    def boolean(self, table: str, key: str) -> bool | None:
        values = self.table(table)
        if key not in values:
            return None
        if not isinstance(values[key], bool):
            raise self.fail(f"{table}.{key}", f"must be true or false, got {_describe(values[key])}")
        return values[key]

    def string(self, table: str, key: str) -> str | None:
        values = self.table(table)
        if key not in values:
            return None
        if not isinstance(values[key], str):
            raise self.fail(f"{table}.{key}", f"must be a string, got {_describe(values[key])}")
        return values[key]

    def strings(self, table: str, key: str) -> tuple[str, ...] | None:
        values = self.table(table)
        if key not in values:
            return None
        value = values[key]
        if not isinstance(value, list) or not all(isinstance(item, str) for item in value):
            raise self.fail(f"{table}.{key}", f"must be a list of strings, got {_describe(value)}")
        return tuple(value)

    def text(self, key: str) -> str | None:
        if key not in self.document:
            return None
        value = self.document[key]
        if not isinstance(value, str):
            raise self.fail(key, f"must be a string, got {_describe(value)}")
        return value


def _describe(value: Any) -> str:
    if isinstance(value, Mapping):
        return "a table"
    if isinstance(value, list):
        return f"a list of {len(value)} items"
    return repr(value)


def _only_set(**values: Any) -> dict[str, Any]:
    return {key: value for key, value in values.items() if value is not None}


def load_profile(spec: str | Path) -> RigProfile:
    """Read and validate a rig profile: a TOML file, or a shipped profile's name."""
    path = resolve_profile_path(spec)
    source = str(path)
    try:
        with path.open("rb") as handle:
            document = tomllib.load(handle)
    except tomllib.TOMLDecodeError as error:
        raise UserError(f"{source}: not valid TOML: {error}") from None
    except OSError as error:
        raise UserError(f"{source}: cannot read: {error.strerror or error}") from None
    return profile_from_mapping(document, source=source, path=path)


def profile_from_mapping(document: Mapping[str, Any], *, source: str = "<profile>",
                         path: Path | None = None) -> RigProfile:
    """Build a `RigProfile` from an already parsed TOML document (``source`` names it in
    errors)."""
    reader = TableReader(source, document)
    extra: dict[str, Any] = {}
    for key, value in document.items():
        if key in _TABLE_KEYS or key in _TOP_LEVEL_KEYS:
            continue
        if isinstance(value, Mapping):
            extra[key] = value  # another part of the bench owns this table
        else:
            raise reader.fail(key, "is not a known top-level key; expected name, description or a table "
                              f"([{'], ['.join(_TABLE_KEYS)}] or an extension table)")

    gravity = reader.vector("gravity", "in_tracker_m_s2", 3, required=True)
    assert gravity is not None
    if not math.hypot(*gravity) > 0:
        raise reader.fail("gravity.in_tracker_m_s2", "must not be zero")
    base_orientation = reader.quaternion("base", "orientation_in_tracker") or hanging_orientation(gravity)
    base_position = reader.vector("base", "position_in_tracker_m", 3) or (0.0, 0.0, 0.0)
    base_sensor = SensorMounting(
        reader.quaternion("base_sensor", "rotation_in_base") or (1.0, 0.0, 0.0, 0.0),
        reader.vector("base_sensor", "offset_in_base_m", 3) or (0.0, 0.0, 0.0),
    )
    tip_sensor = SensorMounting(
        reader.quaternion("tip_sensor", "rotation_in_tip") or (1.0, 0.0, 0.0, 0.0),
        reader.vector("tip_sensor", "offset_in_tip_m", 3) or (0.0, 0.0, 0.0),
    )

    rod_values = _only_set(**{key: reader.number("rod", key) for key in _TABLE_KEYS["rod"]})
    capsule_values = _only_set(mass_kg=reader.number("capsule", "mass_kg", minimum=0.0),
                               center_of_mass_in_tip_m=reader.vector("capsule", "center_of_mass_in_tip_m", 3))
    ring_angle_deg = reader.number("jets", "ring_angle_deg")
    max_force = _max_force(reader)
    try:
        # The params classes validate ranges themselves; their messages already name
        # "rod.length_m" etc., which are exactly the profile's keys.
        rod = RodParameters(**rod_values)
        capsule = CapsuleParameters(**capsule_values)
        jets = JetLayout(ring_angle_rad=math.radians(ring_angle_deg or 0.0))
    except ValueError as error:
        raise UserError(f"{source}: {error}") from None

    name = reader.text("name") or (path.stem if path is not None else "profile")
    return RigProfile(
        name=name,
        gravity_in_tracker_m_s2=gravity,  # type: ignore[arg-type]
        base_orientation_in_tracker=base_orientation,
        base_position_in_tracker_m=base_position,  # type: ignore[arg-type]
        base_sensor=base_sensor,
        tip_sensor=tip_sensor,
        rod=rod,
        capsule=capsule,
        jets=jets,
        max_jet_force_n=max_force,
        description=reader.text("description") or "",
        path=path,
        extra_tables=extra,
    )


def _max_force(reader: TableReader) -> Vector3:
    values = reader.table("jets")
    if "max_force_n" not in values:
        return (DEFAULT_MAX_JET_FORCE_N,) * 3
    raw = values["max_force_n"]
    if isinstance(raw, (int, float)) and not isinstance(raw, bool):
        forces: Sequence[float] = (reader.number("jets", "max_force_n", positive=True),) * 3  # type: ignore[assignment]
    else:
        forces = reader.vector("jets", "max_force_n", 3, what="a number or a list of 3 numbers (N)")  # type: ignore[assignment]
        for index, force in enumerate(forces):
            if not force > 0:
                raise reader.fail(f"jets.max_force_n[{index}]", f"must be > 0, got {force!r}")
    return tuple(forces)  # type: ignore[return-value]
