"""Rig profiles: what a measurement table does not say about the rig, read from TOML.

A profile describes one rig (the physical HydroJet bench, or the simulated one): the
direction of gravity in the tracker frame, where the two orientation sensors sit on
their bodies, the rod and capsule, and the jets. ``load_profile(path)`` reads and
validates it; ``profile.model_parameters()`` turns it into `ModelParameters`.

Frames
------
* *tracker frame*: the frame the sensors are measured in (the EM tracker's, or the
  earth frame of the IMU orientation filter). Dataset orientations and positions live
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

The profile format (tables, keys, units, defaults, ``extends``) is documented in one
place, `hydrojet_bench.config.schema`; `RigProfile.config` is the typed tree every part
of the bench reads (devices, session, estimator, twin). Every error is a `UserError`
naming the file and the dotted key, e.g. ``profiles/x.toml: rod.length_m must be a
finite number > 0, got -0.07``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import msgspec
import numpy as np
from numpy.typing import ArrayLike

from .config import PROFILES_DIR, RigConfig, config_from_mapping, load_config, resolve_profile_path
from .config.schema import IDENTITY_QUATERNION, QUATERNION_NORM_TOLERANCE, ZERO_VECTOR, OnlineSettings
from .geometry import matrix_from_quat, quat_conjugate, quat_from_matrix, quat_multiply, quat_rotate, se3
from .params import CapsuleParameters, JetLayout, ModelParameters, RodParameters

Vector3 = tuple[float, float, float]
Quaternion = tuple[float, float, float, float]

__all__ = ["PROFILES_DIR", "RigProfile", "SensorMounting", "SensorPoses", "hanging_orientation", "load_profile",
           "profile_from_mapping"]


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

    rotation_in_body: Quaternion = IDENTITY_QUATERNION
    offset_in_body_m: Vector3 = ZERO_VECTOR

    def __post_init__(self) -> None:
        q = np.asarray(self.rotation_in_body, dtype=float)
        if q.shape != (4,) or not np.all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1.0) > QUATERNION_NORM_TOLERANCE:
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


# The profile tables the models and the sensor frames are made of (not the devices', the
# session's or the twin's), less what no prediction reads: where the clamp stands in the
# tracker's field (predictions are in the base sensor's frame) and the valves' force limit.
PHYSICS_TABLES = ("gravity", "base", "base_sensor", "tip_sensor", "rod", "capsule", "jets")
NOT_PREDICTED = frozenset({"base.position_in_tracker_m", "jets.max_force_n"})

@dataclass(frozen=True)
class RigProfile:
    """One rig: its typed configuration and the physics it implies.

    config: every table of the profile (`hydrojet_bench.config.schema.RigConfig`).
    path: the file it came from, or None if built in code.

    Derived from ``config`` (frames: see the module docstring):
    gravity_in_tracker_m_s2: gravitational acceleration in the tracker frame, m/s^2.
    base_orientation_in_tracker, base_position_in_tracker_m: the clamp's nominal pose in
        the tracker frame, unit quaternion (w, x, y, z) and m (the simulated rig places
        its clamp here; with real data the base sensor measures it).
    base_sensor, tip_sensor: mountings on the clamp and on the rod tip.
    rod, capsule, jets: as in `ModelParameters`.
    max_jet_force_n: largest force of each jet (1, 2, 3), N; commands beyond it are
        clipped by the valves.
    """

    config: RigConfig
    path: Path | None = None
    gravity_in_tracker_m_s2: Vector3 = field(init=False, compare=False)
    base_orientation_in_tracker: Quaternion = field(init=False, compare=False)
    base_position_in_tracker_m: Vector3 = field(init=False, compare=False)
    base_sensor: SensorMounting = field(init=False, compare=False)
    tip_sensor: SensorMounting = field(init=False, compare=False)
    rod: RodParameters = field(init=False, compare=False)
    capsule: CapsuleParameters = field(init=False, compare=False)
    jets: JetLayout = field(init=False, compare=False)
    max_jet_force_n: tuple[float, ...] = field(init=False, compare=False)

    def __post_init__(self) -> None:
        config = self.config
        gravity = tuple(float(v) for v in config.gravity.in_tracker_m_s2)
        orientation = config.base.orientation_in_tracker or hanging_orientation(gravity)
        derived = {
            "gravity_in_tracker_m_s2": gravity,
            "base_orientation_in_tracker": tuple(float(v) for v in _unit_quaternion(orientation)),
            "base_position_in_tracker_m": tuple(float(v) for v in config.base.position_in_tracker_m),
            "base_sensor": SensorMounting(config.base_sensor.rotation_in_base, config.base_sensor.offset_in_base_m),
            "tip_sensor": SensorMounting(config.tip_sensor.rotation_in_tip, config.tip_sensor.offset_in_tip_m),
            "rod": config.rod.parameters(),
            "capsule": config.capsule.parameters(),
            "jets": config.jets.layout(),
            "max_jet_force_n": config.jets.max_force_per_jet_n,
        }
        for name, value in derived.items():
            object.__setattr__(self, name, value)

    @property
    def name(self) -> str:
        return self.config.name

    @property
    def description(self) -> str:
        return self.config.description

    def with_tables(self, **tables: msgspec.Struct) -> RigProfile:
        """This rig with whole tables of its configuration replaced, e.g.
        ``gravity=GravityTable(in_tracker_m_s2=(9.81, 0.0, 0.0))``."""
        return RigProfile(msgspec.structs.replace(self.config, **tables), self.path)

    def online_settings(self) -> OnlineSettings:
        """The online estimator's settings (`[estimator]`): what the rig's live sessions
        used, so every offline estimate of its data uses them too."""
        return self.config.estimator.online_settings()

    def physics(self) -> dict[str, float | bool | list]:
        """The tables the models read (`PHYSICS_TABLES`), flattened to "table.key" values
        as TOML writes them (tuples as lists; unset values left out): what a parameter
        file records of the rig it was calibrated on, to tell another rig's values."""
        flat: dict[str, float | bool | list] = {}
        for table in PHYSICS_TABLES:
            for key, value in msgspec.to_builtins(getattr(self.config, table)).items():
                if value is not None and f"{table}.{key}" not in NOT_PREDICTED:
                    flat[f"{table}.{key}"] = list(value) if isinstance(value, tuple) else value
        return flat

    @property
    def source(self) -> str:
        """How to name this profile in messages: its file, or its name."""
        return str(self.path) if self.path is not None else f"profile {self.name!r}"

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


def load_profile(spec: str | Path) -> RigProfile:
    """Read and check a rig profile: a TOML file, or a shipped profile's name."""
    path = resolve_profile_path(spec)
    return RigProfile(load_config(path), path)


def profile_from_mapping(document: Mapping[str, Any], *, source: str = "<profile>",
                         path: Path | None = None) -> RigProfile:
    """A `RigProfile` from an already parsed TOML document (``source`` names it in
    errors; ``extends`` resolves from ``path``'s folder)."""
    return RigProfile(config_from_mapping(document, source=source, path=path), path)
