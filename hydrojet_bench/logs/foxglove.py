"""Foxglove's ``foxglove.FrameTransform`` and ``foxglove.SceneUpdate`` messages, as log records.

Field names and types follow Foxglove's public JSON schemas (for the fields the bench
uses, plus the bench's ``t_s``), so a log opens in Foxglove's or Lichtblick's 3D panel.
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


class OtherPrimitive(Struct, frozen=True):
    """A kind of primitive the bench never writes; its fields are not read."""


class SceneEntity(Struct, frozen=True, kw_only=True):
    """A visual element of a 3D scene."""

    timestamp: Time
    frame_id: Annotated[str, Meta(description="frame of reference")]
    id: Annotated[str, Meta(description="entity id; replaces any earlier entity with the same id on this topic")]
    lifetime: Duration
    frame_locked: Annotated[bool, Meta(description="follow frame_id as it moves")]
    metadata: tuple[KeyValuePair, ...] = ()
    arrows: tuple[OtherPrimitive, ...] = ()
    cubes: tuple[OtherPrimitive, ...] = ()
    spheres: tuple[OtherPrimitive, ...] = ()
    cylinders: tuple[OtherPrimitive, ...] = ()
    lines: tuple[LinePrimitive, ...] = ()
    triangles: tuple[OtherPrimitive, ...] = ()
    texts: tuple[OtherPrimitive, ...] = ()
    models: tuple[OtherPrimitive, ...] = ()


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
