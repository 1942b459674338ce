"""Foxglove's ``foxglove.FrameTransform`` and ``foxglove.SceneUpdate`` messages, as log records.

Field names and types are those of Foxglove's definitions (all fields, plus the bench's
``t_s``; tests/logs/foxglove_check.py checks them against the ones the Foxglove SDK
ships), so a log opens in Foxglove's or Lichtblick's 3D panel. Kept as msgspec types
rather than the SDK's message classes: those encode protobuf only and cannot be read
back, and the log's reader turns every message into a typed record.
Their quaternions are Foxglove's ``{x, y, z, w}`` objects, not the bench's (w, x, y, z).
"""

from __future__ import annotations

from typing import Annotated, ClassVar

from msgspec import Meta, Struct

from .log_record import LogRecord

LINE_STRIP = 0
Nanoseconds = Annotated[int, Meta(ge=0, le=999_999_999, description="ns")]


class Time(Struct, frozen=True):
    """Time since the Unix epoch."""

    sec: Annotated[int, Meta(ge=0, description="s")]
    nsec: Nanoseconds


class Duration(Struct, frozen=True):
    """A duration."""

    sec: Annotated[int, Meta(description="s")]
    nsec: Nanoseconds


class Vector3(Struct, frozen=True):
    """A vector in 3D space."""

    x: float
    y: float
    z: float


class Point3(Struct, frozen=True):
    """A point in 3D space."""

    x: float
    y: float
    z: float


class Quaternion(Struct, frozen=True):
    """A rotation as a quaternion, w the scalar part."""

    x: float
    y: float
    z: float
    w: float


class Pose(Struct, frozen=True):
    """A position and orientation."""

    position: Vector3
    orientation: Quaternion


class Color(Struct, frozen=True):
    """An RGBA colour, each in [0, 1]."""

    r: float
    g: float
    b: float
    a: float


class KeyValuePair(Struct, frozen=True):
    """A key and its value."""

    key: str
    value: str


class LinePrimitive(Struct, frozen=True):
    """A series of points connected by lines."""

    type: Annotated[int, Meta(ge=0, le=2, description="0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST")]
    pose: Pose
    thickness: Annotated[float, Meta(description="line thickness (m unless scale_invariant, then pixels)")]
    scale_invariant: Annotated[bool, Meta(description="thickness in screen pixels")]
    points: Annotated[tuple[Point3, ...], Meta(description="points along the line")]
    color: Color
    colors: Annotated[tuple[Color, ...], Meta(description="per-point colours (empty: use color)")]
    indices: Annotated[tuple[Annotated[int, Meta(ge=0)], ...], Meta(description="empty: no indexing")]


class ArrowPrimitive(Struct, frozen=True):
    """An arrow along the pose's +x, tail at its position (m)."""

    pose: Pose
    shaft_length: float
    shaft_diameter: float
    head_length: float
    head_diameter: float
    color: Color


class CubePrimitive(Struct, frozen=True):
    """A box centred on the pose, ``size`` its edges (m)."""

    pose: Pose
    size: Vector3
    color: Color


class SpherePrimitive(Struct, frozen=True):
    """An ellipsoid centred on the pose, ``size`` its diameters (m)."""

    pose: Pose
    size: Vector3
    color: Color


class CylinderPrimitive(Struct, frozen=True):
    """A cylinder or truncated cone along the pose's z, ``size`` its bounding box (m)."""

    pose: Pose
    size: Vector3
    bottom_scale: float
    top_scale: float
    color: Color


class TriangleListPrimitive(Struct, frozen=True):
    """Triangles, three points each."""

    pose: Pose
    points: tuple[Point3, ...]
    color: Color
    colors: tuple[Color, ...]
    indices: tuple[Annotated[int, Meta(ge=0)], ...]


class TextPrimitive(Struct, frozen=True):
    """A text label."""

    pose: Pose
    billboard: bool
    font_size: float
    scale_invariant: bool
    color: Color
    text: str


class ModelPrimitive(Struct, frozen=True):
    """A 3D model from a URL or embedded data (base64)."""

    pose: Pose
    scale: Vector3
    color: Color
    override_color: bool
    url: str
    media_type: str
    data: str


class SceneEntity(Struct, frozen=True, kw_only=True):
    """A visual element of a 3D scene."""

    timestamp: Time
    frame_id: Annotated[str, Meta(description="frame of reference")]
    id: Annotated[str, Meta(description="entity id; replaces any earlier entity with the same id on this topic")]
    lifetime: Duration
    frame_locked: Annotated[bool, Meta(description="follow frame_id as it moves")]
    metadata: tuple[KeyValuePair, ...] = ()
    arrows: tuple[ArrowPrimitive, ...] = ()
    cubes: tuple[CubePrimitive, ...] = ()
    spheres: tuple[SpherePrimitive, ...] = ()
    cylinders: tuple[CylinderPrimitive, ...] = ()
    lines: tuple[LinePrimitive, ...] = ()
    triangles: tuple[TriangleListPrimitive, ...] = ()
    texts: tuple[TextPrimitive, ...] = ()
    models: tuple[ModelPrimitive, ...] = ()


class SceneEntityDeletion(Struct, frozen=True):
    """A removal of earlier entities."""

    timestamp: Time
    type: Annotated[int, Meta(ge=0, le=1, description="0 MATCHING_ID, 1 ALL")]
    id: Annotated[str, Meta(description="entity id for MATCHING_ID")]


class FrameTransform(LogRecord, kw_only=True):
    """The pose of a child frame in its parent frame (HydroJet Bench adds t_s)."""

    topic: ClassVar[str] = "/tf"
    schema_namespace: ClassVar[str] = "foxglove"
    timestamp: Time
    parent_frame_id: Annotated[str, Meta(description="parent frame")]
    child_frame_id: Annotated[str, Meta(description="child frame")]
    translation: Vector3
    rotation: Quaternion


class SceneUpdate(LogRecord, kw_only=True):
    """An update of the entities of a 3D scene (HydroJet Bench adds t_s)."""

    topic: ClassVar[str] = "/scene/backbone"
    schema_namespace: ClassVar[str] = "foxglove"
    deletions: Annotated[tuple[SceneEntityDeletion, ...], Meta(description="entities to delete")] = ()
    entities: Annotated[tuple[SceneEntity, ...], Meta(description="entities to add or replace")] = ()
