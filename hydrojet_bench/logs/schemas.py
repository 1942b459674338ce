"""The session log's topics, their JSON schemas, and a checker for the schema subset used.

Every topic is one MCAP channel with ``message_encoding = "json"`` and a schema with
``encoding = "jsonschema"``. Every message carries ``t_s``, the session time in s
(virtual time on the simulated rig). Quaternions are ``[w, x, y, z]`` arrays (scalar
first, as everywhere in the bench) except inside the Foxglove messages, whose
``{x, y, z, w}`` objects follow Foxglove's own schemas. Lengths in m, forces in N,
moments in N m, angles in deg where a name says ``_deg``.

Every field is required unless its description says "optional"; other fields are
allowed. Fields marked ``"nullable": true`` may hold null (not measured, or a non-finite
number, which JSON cannot carry). That is the OpenAPI annotation, not JSON Schema's
``"type": [..., "null"]``: Foxglove and Lichtblick derive each channel's message
definition from its schema and accept only one type name per field, typed ``items`` for
every array and ``properties`` for every object, which the schemas here keep to.

`/tf` and `/scene/backbone` use the public Foxglove schemas ``foxglove.FrameTransform``
and ``foxglove.SceneUpdate`` (field names and types as Foxglove publishes them, written
here for the fields the bench uses, plus ``t_s``), so a log opens in Foxglove's or
Lichtblick's 3D panel.

The file also holds one metadata record of its own, `LOG_METADATA_NAME`, written right
after the header: the format version and the wall-clock time of ``t_s = 0``.
"""

from __future__ import annotations

import math
from typing import Any

JsonSchema = dict[str, Any]

SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "json"
LOG_METADATA_NAME = "hydrojet_bench.log"
FORMAT_VERSION = "1"
START_TIME_KEY = "start_time_unix_ns"


# --- building blocks -------------------------------------------------------------------

def _number(description: str, **limits: float) -> JsonSchema:
    return {"type": "number", "description": description, **limits}


def _integer(description: str, **limits: float) -> JsonSchema:
    return {"type": "integer", "description": description, **limits}


def _string(description: str, choices: tuple[str, ...] | None = None) -> JsonSchema:
    schema: JsonSchema = {"type": "string", "description": description}
    if choices:
        schema["enum"] = list(choices)
    return schema


def _vector(size: int, description: str) -> JsonSchema:
    return {"type": "array", "description": description, "items": {"type": "number"},
            "minItems": size, "maxItems": size}


def _quaternion(description: str) -> JsonSchema:
    return _vector(4, f"{description}; unit quaternion [w, x, y, z]")


def _nullable(schema: JsonSchema) -> JsonSchema:
    return {**schema, "description": f"{schema['description']}; null if unknown", "nullable": True}


def _object(description: str, properties: dict[str, JsonSchema], optional: tuple[str, ...] = (),
            title: str | None = None) -> JsonSchema:
    schema: JsonSchema = {"type": "object", "description": description, "properties": properties,
                          "required": [name for name in properties if name not in optional]}
    if title:
        schema = {"title": title, **schema}
    return schema


def _topic(name: str, description: str, properties: dict[str, JsonSchema],
           optional: tuple[str, ...] = ()) -> tuple[str, JsonSchema]:
    """A bench topic's schema: ``t_s`` first, then its own fields."""
    return name, _object(description, {"t_s": T_S, **properties}, optional, title=name)


T_S = _number("session time, s (virtual time on the simulated rig)")
FORCES = _vector(3, "jet forces q1, q2, q3, N")

# --- Foxglove (field names and types after the public foxglove.* JSON schemas) ---------

_TIME = _object("time since the Unix epoch", {"sec": _integer("s", minimum=0),
                                               "nsec": _integer("ns", minimum=0, maximum=999_999_999)},
                title="time")
_DURATION = _object("duration", {"sec": _integer("s"), "nsec": _integer("ns", minimum=0, maximum=999_999_999)},
                    title="duration")
_XYZ = {axis: _number(f"{axis} coordinate") for axis in "xyz"}
_VECTOR3 = _object("vector in 3D space", dict(_XYZ), title="foxglove.Vector3")
_POINT3 = _object("point in 3D space", dict(_XYZ), title="foxglove.Point3")
_FOX_QUATERNION = _object("rotation as a quaternion", {**_XYZ, "w": _number("w (scalar) part")},
                          title="foxglove.Quaternion")
_POSE = _object("pose", {"position": _VECTOR3, "orientation": _FOX_QUATERNION}, title="foxglove.Pose")
_COLOR = _object("RGBA colour, each in [0, 1]", {c: _number(c) for c in "rgba"}, title="foxglove.Color")
_KEY_VALUE = _object("key and value", {"key": _string("key"), "value": _string("value")},
                     title="foxglove.KeyValuePair")
LINE_STRIP = 0
_LINE = _object("series of points connected by lines", {
    "type": _integer("0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST", minimum=0, maximum=2),
    "pose": _POSE,
    "thickness": _number("line thickness (m unless scale_invariant, then pixels)"),
    "scale_invariant": {"type": "boolean", "description": "thickness in screen pixels"},
    "points": {"type": "array", "items": _POINT3, "description": "points along the line"},
    "color": _COLOR,
    "colors": {"type": "array", "items": _COLOR, "description": "per-point colours (empty: use color)"},
    "indices": {"type": "array", "items": _integer("index", minimum=0), "description": "empty: no indexing"},
}, title="foxglove.LinePrimitive")


def _primitives(kind: str) -> JsonSchema:
    return {"type": "array", "description": f"{kind} primitives (the bench writes none; see foxglove.SceneEntity)",
            "items": {"type": "object", "properties": {}, "description": f"foxglove {kind} primitive"}}


_ENTITY = _object("visual element of a 3D scene", {
    "timestamp": _TIME,
    "frame_id": _string("frame of reference"),
    "id": _string("entity id; replaces any earlier entity with the same id on this topic"),
    "lifetime": _DURATION,
    "frame_locked": {"type": "boolean", "description": "follow frame_id as it moves"},
    "metadata": {"type": "array", "items": _KEY_VALUE, "description": "user metadata"},
    "arrows": _primitives("arrow"), "cubes": _primitives("cube"), "spheres": _primitives("sphere"),
    "cylinders": _primitives("cylinder"),
    "lines": {"type": "array", "items": _LINE, "description": "line primitives"},
    "triangles": _primitives("triangle list"), "texts": _primitives("text"), "models": _primitives("model"),
}, title="foxglove.SceneEntity")
_DELETION = _object("removal of earlier entities", {
    "timestamp": _TIME, "type": _integer("0 MATCHING_ID, 1 ALL", minimum=0, maximum=1),
    "id": _string("entity id for MATCHING_ID"),
}, title="foxglove.SceneEntityDeletion")

FRAME_TRANSFORM: JsonSchema = _object("pose of a child frame in its parent frame (HydroJet Bench adds t_s)", {
    "t_s": T_S,
    "timestamp": _TIME,
    "parent_frame_id": _string("parent frame"),
    "child_frame_id": _string("child frame"),
    "translation": _VECTOR3,
    "rotation": _FOX_QUATERNION,
}, title="foxglove.FrameTransform")
SCENE_UPDATE: JsonSchema = _object("update of the entities of a 3D scene (HydroJet Bench adds t_s)", {
    "t_s": T_S,
    "deletions": {"type": "array", "items": _DELETION, "description": "entities to delete"},
    "entities": {"type": "array", "items": _ENTITY, "description": "entities to add or replace"},
}, title="foxglove.SceneUpdate")

# --- the bench's topics ----------------------------------------------------------------

_TOOL = _object("one tracked sensor of an EM frame", {
    "name": _string("sensor name, e.g. base or tip"),
    "handle": _integer("port handle"),
    "status": _string('"ok", "missing", "out_of_volume", "disabled", ...'),
    "orientation": _nullable(_quaternion("sensor orientation, tracker frame")),
    "position_m": _nullable(_vector(3, "sensor position, tracker frame, m")),
    "rms_error_mm": _nullable(_number("tracker's RMS fit error, mm")),
})

TOPICS: dict[str, tuple[str, JsonSchema]] = {
    "/bench/sample": _topic("hydrojet_bench.Sample", "one row of the CSV contract (hydrojet_bench/data/csv_io.py): "
                            "commanded forces and the raw sensor poses, tracker frame", {
        "source": _string("which sensors measured the poses", ("em", "imu")),
        "jet_forces_n": FORCES,
        "sweep": _integer("-1 for calibration or unlabelled, else the validation sweep", minimum=-1),
        "step": _integer("quasistatic step"),
        "base_orientation": _quaternion("base sensor orientation, tracker frame"),
        "tip_orientation": _quaternion("tip sensor orientation, tracker frame"),
        "base_position_m": _nullable(_vector(3, "base sensor position, tracker frame, m")),
        "tip_position_m": _nullable(_vector(3, "tip sensor position, tracker frame, m")),
        "flags": _integer("optional SampleFlag bits (sensor missing, out of volume); SATURATED is "
                          "recomputed from the profile on reading, as for CSV", minimum=0),
    }, optional=("flags",)),
    "/imu/raw": _topic("hydrojet_bench.ImuRaw", "one ICM-20948 reading", {
        "sensor": _string("which IMU", ("base", "tip")),
        "address": _integer("I2C address"),
        "accel_m_s2": _vector(3, "acceleration, sensor frame, m/s^2"),
        "gyro_rad_s": _vector(3, "angular rate, sensor frame, rad/s"),
        "mag_ut": _nullable(_vector(3, "magnetic field, sensor frame, uT")),
        "temperature_c": _nullable(_number("die temperature, deg C")),
    }),
    "/imu/orientation": _topic("hydrojet_bench.ImuOrientation", "orientation filter output", {
        "base": _quaternion("base IMU orientation, filter world frame"),
        "tip": _quaternion("tip IMU orientation, filter world frame"),
        "tip_in_base": _quaternion("tip IMU relative to base IMU"),
    }),
    "/em/frame": _topic("hydrojet_bench.EmFrame", "one NDI Aurora frame", {
        "frame_number": _integer("tracker frame counter"),
        "system_status": _string("system status word, as the tracker reports it"),
        "tools": {"type": "array", "items": _TOOL, "description": "the sensors of this frame"},
    }),
    "/valves/command": _topic("hydrojet_bench.ValveCommand", "a command sent to the valve controller", {
        "command": _string("the command"),
        "duties_permille": _nullable({**_vector(3, "valve duty cycles, permille"),
                                      "items": _number("duty, permille", minimum=0, maximum=1000)}),
        "jet_forces_n": _nullable(FORCES),
    }),
    "/valves/reply": _topic("hydrojet_bench.ValveReply", "the valve controller's answer", {
        "command": _string("the command answered"),
        "ok": {"type": "boolean", "description": "accepted"},
        "code": _nullable(_string("error code")),
        "detail": _nullable(_string("error detail")),
    }),
    "/bench/step": _topic("hydrojet_bench.Step", "a finished quasistatic step, averaged", {
        "index": _integer("step index in the plan", minimum=0),
        "count": _integer("steps in the plan", minimum=0),
        "sweep": _integer("-1 for calibration, else the sweep", minimum=-1),
        "step": _integer("step label"),
        "jet_forces_n": FORCES,
        "samples": _integer("samples averaged", minimum=0),
        "tip_in_base_measured": _quaternion("measured tip orientation in the base frame"),
        "tip_position_in_base_m": _nullable(_vector(3, "measured tip position in the base frame, m")),
        "time_s": _number("optional: time of the last sample averaged, s"),
        "base_orientation": _quaternion("optional: averaged base sensor orientation, tracker frame"),
        "tip_orientation": _quaternion("optional: averaged tip sensor orientation, tracker frame"),
        "base_position_m": _nullable(_vector(3, "optional: averaged base sensor position, tracker frame, m")),
        "tip_position_m": _nullable(_vector(3, "optional: averaged tip sensor position, tracker frame, m")),
    }, optional=("time_s", "base_orientation", "tip_orientation", "base_position_m", "tip_position_m")),
    "/model/prediction": _topic("hydrojet_bench.ModelPrediction", "the model's tip for a step", {
        "index": _integer("step index", minimum=0),
        "method": _string('optional: "ref" (calibrated, constant disturbance) or "online" (eq. 4)'),
        "tip_in_base": _quaternion("predicted tip orientation in the base frame"),
        "tip_position_in_base_m": _vector(3, "predicted tip position in the base frame, m"),
        "bend_deg": _number("bending angle, deg"),
        "orientation_error_deg": _number("angle between predicted and measured tip orientation, deg"),
        "position_error_mm": _nullable(_number("distance between predicted and measured tip, mm")),
    }, optional=("method",)),
    "/estimate/disturbance": _topic("hydrojet_bench.Disturbance", "online disturbance estimate (eq. 4)", {
        "index": _integer("step index", minimum=0),
        "force_n": _vector(3, "disturbance force, tip frame, N"),
        "moment_nm": _vector(3, "disturbance moment, tip frame, N m"),
        "moment_norm_nm": _number("norm of the moment, N m"),
        "orientation_error_deg_before": _number("orientation error before the update, deg"),
        "orientation_error_deg_after": _number("orientation error after the update, deg"),
        "iterations": _integer("updates applied", minimum=0),
    }),
    "/bench/parameters": _topic("hydrojet_bench.Parameters", "the model parameters in use", {
        "model": _string("model name"),
        "effects": {"type": "array", "items": _string("effect name"), "description": "effects enabled"},
        "parameters": {"type": "object", "properties": {}, "additionalProperties": _number("value, SI units"),
                       "description": "parameter name (E0, EL, L, w_d components, effect.parameter) -> value"},
        "calibrated": {"type": "boolean", "description": "the values come from a calibration"},
        "rms_orientation_deg_before": _nullable(_number("calibration RMS orientation error before, deg")),
        "rms_orientation_deg_after": _nullable(_number("calibration RMS orientation error after, deg")),
    }),
    "/events": _topic("hydrojet_bench.Event", "something worth a line in the session's story", {
        "level": _string("severity", ("info", "warning", "error")),
        "source": _string("which part of the bench"),
        "message": _string("what happened"),
    }),
    "/tf": ("foxglove.FrameTransform", FRAME_TRANSFORM),
    "/scene/backbone": ("foxglove.SceneUpdate", SCENE_UPDATE),
}


# --- checking a message against a schema -------------------------------------------------

_ANNOTATIONS = frozenset({"title", "description", "$comment"})
_KEYWORDS = frozenset({"type", "nullable", "properties", "additionalProperties", "required", "items",
                       "minItems", "maxItems", "enum", "minimum", "maximum"}) | _ANNOTATIONS


# Decoded JSON holds only these types (and `jsonable` output too), so no ABCs are needed.
_PYTHON_TYPES: dict[str, type | tuple[type, ...]] = {
    "object": dict, "array": list, "string": str, "boolean": bool, "null": type(None),
    "number": (int, float), "integer": int,
}


def _has_type(value: Any, name: str) -> bool:
    if isinstance(value, bool):
        return name == "boolean"
    if name == "integer" and isinstance(value, float):
        return math.isfinite(value) and value.is_integer()  # JSON Schema counts 3.0 as an integer
    return isinstance(value, _PYTHON_TYPES[name])


def schema_problem(schema: JsonSchema, value: Any, where: str = "message") -> str | None:
    """The first way ``value`` (decoded JSON) breaks ``schema``, as ``"where.field: what"``,
    or None if it conforms. Understands only the keywords the bench's schemas use
    (type, nullable, properties, additionalProperties as a schema, required, items,
    minItems, maxItems, enum, minimum, maximum) and
    refuses a schema with any other, so no constraint is ever skipped silently."""
    if id(schema) not in _VERIFIED:
        _verify_keywords(schema)
    found = _problem(schema, value)
    if found is None:
        return None
    path, message = found
    return f"{where}{''.join(reversed(path))}: {message}"


def _verify_keywords(schema: JsonSchema) -> None:
    unknown = schema.keys() - _KEYWORDS
    if unknown:
        raise ValueError(f"schema_problem does not understand the keyword(s) {sorted(unknown)}")
    if not isinstance(schema.get("additionalProperties", {}), dict):
        raise ValueError("schema_problem understands additionalProperties only as a schema")
    for child in schema.get("properties", {}).values():
        _verify_keywords(child)
    for key in ("items", "additionalProperties"):
        if key in schema:
            _verify_keywords(schema[key])


def _problem(schema: JsonSchema, value: Any) -> tuple[list[str], str] | None:
    """(path parts, innermost last-first, message) of the first problem, or None. The
    path is only built on failure: checking runs on every message written."""
    if value is None and schema.get("nullable"):
        return None
    types = schema.get("type")
    if types is not None:
        names = (types,) if isinstance(types, str) else types
        if not any(_has_type(value, name) for name in names):
            return [], f"expected {' or '.join(names)}, got {_describe(value)}"
    if "enum" in schema and value not in schema["enum"]:
        return [], f"must be one of {', '.join(map(repr, schema['enum']))}, got {value!r}"
    if "minimum" in schema and value < schema["minimum"]:
        return [], f"must be >= {schema['minimum']}, got {value!r}"
    if "maximum" in schema and value > schema["maximum"]:
        return [], f"must be <= {schema['maximum']}, got {value!r}"
    if isinstance(value, dict):
        for name in schema.get("required", ()):
            if name not in value:
                return [f".{name}"], "required field missing"
        properties = schema.get("properties", {})
        for name, field_schema in properties.items():
            if name in value:
                found = _problem(field_schema, value[name])
                if found is not None:
                    found[0].append(f".{name}")
                    return found
        if "additionalProperties" in schema:
            for name, item in value.items():
                found = None if name in properties else _problem(schema["additionalProperties"], item)
                if found is not None:
                    found[0].append(f".{name}")
                    return found
    elif isinstance(value, list):
        low, high = schema.get("minItems", 0), schema.get("maxItems")
        if len(value) < low or (high is not None and len(value) > high):
            wanted = str(low) if low == high else f"{low} to {high if high is not None else 'any number of'}"
            return [], f"expected {wanted} items, got {len(value)}"
        if "items" in schema:
            item_schema = schema["items"]
            for index, item in enumerate(value):
                found = _problem(item_schema, item)
                if found is not None:
                    found[0].append(f"[{index}]")
                    return found
    return None


def _describe(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, dict):
        return "an object"
    if isinstance(value, list):
        return f"a list of {len(value)}"
    return f"{type(value).__name__} {value!r}"


def _verified(schemas: list[JsonSchema]) -> frozenset[int]:
    for schema in schemas:
        _verify_keywords(schema)
    return frozenset(map(id, schemas))


# The shipped schemas are verified once, at import; any other on every call.
_VERIFIED = _verified([schema for _, schema in TOPICS.values()])
