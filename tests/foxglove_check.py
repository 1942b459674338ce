"""A checker of ``foxglove.*`` log messages and their JSON schemas against Foxglove's own
message definitions: the protobuf descriptors the Foxglove SDK (``foxglove-sdk``) ships
with each message type (``foxglove.messages.<Name>.get_schema()``).

A protobuf descriptor is the definition Foxglove generates its JSON schemas from; its
JSON form follows Foxglove's rules, not protobuf's JSON mapping: snake_case field names,
enums as their numbers, ``google.protobuf.Timestamp`` and ``Duration`` as ``{sec, nsec}``.
The descriptors are read with a minimal protobuf wire-format reader, so the oracle needs
nothing but the SDK.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from functools import cache
from typing import Any

import foxglove.messages

# FieldDescriptorProto.Type numbers (google/protobuf/descriptor.proto).
_FLOATS = {1, 2}  # double, float
_INTEGERS = {3, 4, 5, 6, 7, 13, 15, 16, 17, 18}  # int64, uint64, int32, fixed64, fixed32, uint32, sfixed*, sint*
_UNSIGNED = {4, 6, 7, 13}
_BOOL, _STRING, _MESSAGE, _BYTES, _ENUM = 8, 9, 11, 12, 14
_REPEATED = 3
_NS_PER_S = 1_000_000_000


@dataclass(frozen=True)
class Field:
    name: str
    kind: int
    repeated: bool
    type_name: str  # ".package.Message" or ".package.Message.Enum", empty for scalars


@dataclass(frozen=True)
class Definitions:
    """The message and enum types of one schema's descriptor set, by full name."""

    messages: dict[str, tuple[Field, ...]]
    enums: dict[str, frozenset[int]]


def _varint(data: bytes, at: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        byte = data[at]
        at += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            return value, at


def _wire_fields(data: bytes) -> Iterator[tuple[int, int | bytes]]:
    at = 0
    while at < len(data):
        key, at = _varint(data, at)
        number, wire_type = key >> 3, key & 7
        if wire_type == 0:
            value, at = _varint(data, at)
        elif wire_type == 2:
            length, at = _varint(data, at)
            value, at = data[at:at + length], at + length
        elif wire_type in (1, 5):
            size = 8 if wire_type == 1 else 4
            value, at = data[at:at + size], at + size
        else:
            raise ValueError(f"protobuf wire type {wire_type} in a descriptor")
        yield number, value


def _add_message(scope: str, descriptor: bytes, found: Definitions) -> None:
    parts = list(_wire_fields(descriptor))
    name = f"{scope}.{next(value.decode() for number, value in parts if number == 1)}"
    fields = []
    for number, value in parts:
        if number == 2:  # FieldDescriptorProto: 1 name, 4 label, 5 type, 6 type_name
            info = dict(_wire_fields(value))
            fields.append(Field(info[1].decode(), info[5], info.get(4) == _REPEATED, info.get(6, b"").decode()))
        elif number == 3:
            _add_message(name, value, found)
        elif number == 4:
            _add_enum(name, value, found)
    found.messages[name] = tuple(fields)


def _add_enum(scope: str, descriptor: bytes, found: Definitions) -> None:
    parts = list(_wire_fields(descriptor))
    name = f"{scope}.{next(value.decode() for number, value in parts if number == 1)}"
    found.enums[name] = frozenset(dict(_wire_fields(value))[2] for number, value in parts if number == 2)


@cache
def official_definitions(schema_name: str) -> Definitions:
    """The definitions shipped for ``schema_name`` (e.g. ``foxglove.SceneUpdate``)."""
    package, _, message = schema_name.partition(".")
    schema = getattr(foxglove.messages, message).get_schema()
    assert (package, schema.name, schema.encoding) == ("foxglove", schema_name, "protobuf")
    found = Definitions({}, {})
    for number, file in _wire_fields(bytes(schema.data)):  # FileDescriptorSet.file
        assert number == 1
        parts = list(_wire_fields(file))
        scope = "." + next(value.decode() for number, value in parts if number == 2)
        for number, value in parts:
            if number == 4:
                _add_message(scope, value, found)
            elif number == 5:
                _add_enum(scope, value, found)
    return found


def _time_fields(type_name: str) -> tuple[tuple[str, int], ...] | None:
    """Foxglove's JSON form of protobuf's time types: sec, nsec (sec unsigned for a time)."""
    if type_name == ".google.protobuf.Timestamp":
        return ("sec", 13), ("nsec", 13)
    if type_name == ".google.protobuf.Duration":
        return ("sec", 5), ("nsec", 13)
    return None


def _fields(definitions: Definitions, type_name: str) -> tuple[Field, ...]:
    time_fields = _time_fields(type_name)
    if time_fields:
        return tuple(Field(name, kind, False, "") for name, kind in time_fields)
    return definitions.messages[type_name]


def _unknown(fields: tuple[Field, ...], names: set[str], type_name: str, where: str) -> list[str]:
    known = {field.name for field in fields}
    return [f"{where}.{name}: no such field in {type_name}" for name in sorted(names) if name not in known]


def message_problems(schema_name: str, message: Any, bench_fields: frozenset[str] = frozenset({"t_s"})) -> list[str]:
    """How ``message`` (decoded JSON) differs from Foxglove's ``schema_name``: a field
    missing, unknown or of another type, each as ``"field.path: what"``. The top-level
    ``bench_fields`` are the bench's additions and are allowed."""
    definitions = official_definitions(schema_name)
    return _object_problems(definitions, "." + schema_name, message, schema_name, bench_fields)


def _object_problems(definitions: Definitions, type_name: str, value: Any, where: str,
                     extra: frozenset[str] = frozenset()) -> list[str]:
    if not isinstance(value, dict):
        return [f"{where}: expected an object {type_name}, got {type(value).__name__}"]
    fields = _fields(definitions, type_name)
    problems = _unknown(fields, value.keys() - extra, type_name, where)
    for field in fields:
        if field.name not in value:
            problems.append(f"{where}.{field.name}: missing")
        elif field.repeated:
            items = value[field.name]
            if not isinstance(items, list):
                problems.append(f"{where}.{field.name}: expected an array, got {type(items).__name__}")
                continue
            for index, item in enumerate(items):
                problems += _value_problems(definitions, field, item, f"{where}.{field.name}[{index}]")
        else:
            problems += _value_problems(definitions, field, value[field.name], f"{where}.{field.name}")
    if _time_fields(type_name) and not problems and not 0 <= value["nsec"] < _NS_PER_S:
        problems.append(f"{where}.nsec: {value['nsec']} outside [0, 1e9)")
    return problems


def _value_problems(definitions: Definitions, field: Field, value: Any, where: str) -> list[str]:
    kind = field.kind
    if kind == _MESSAGE:
        return _object_problems(definitions, field.type_name, value, where)
    if kind == _ENUM:
        known = definitions.enums[field.type_name]
        ok = isinstance(value, int) and not isinstance(value, bool) and value in known
        return [] if ok else [f"{where}: {value!r} is not a value of {field.type_name} {sorted(known)}"]
    if kind in _FLOATS:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    elif kind in _INTEGERS:
        ok = isinstance(value, int) and not isinstance(value, bool) and (kind not in _UNSIGNED or value >= 0)
    elif kind == _BOOL:
        ok = isinstance(value, bool)
    elif kind in (_STRING, _BYTES):  # bytes: base64 text in JSON
        ok = isinstance(value, str)
    else:
        raise ValueError(f"{where}: protobuf field type {kind} unknown to the checker")
    return [] if ok else [f"{where}: {type(value).__name__} {value!r} where protobuf type {kind} is defined"]


_JSON_TYPES = {_BOOL: "boolean", _STRING: "string", _BYTES: "string", _ENUM: "integer",
               _MESSAGE: "object"} | dict.fromkeys(_FLOATS, "number") | dict.fromkeys(_INTEGERS, "integer")


def json_schema_problems(schema_name: str, schema: dict,
                         bench_fields: frozenset[str] = frozenset({"t_s"})) -> list[str]:
    """How the JSON schema a log registers for ``schema_name`` differs from Foxglove's
    definition: a property missing, unknown or of another JSON type."""
    definitions = official_definitions(schema_name)
    return _schema_problems(definitions, "." + schema_name, schema, schema_name, bench_fields)


def _schema_problems(definitions: Definitions, type_name: str, schema: dict, where: str,
                     extra: frozenset[str] = frozenset()) -> list[str]:
    if schema.get("type") != "object":
        return [f"{where}: type {schema.get('type')!r} where {type_name} is an object"]
    fields = _fields(definitions, type_name)
    properties = schema.get("properties", {})
    problems = _unknown(fields, properties.keys() - extra, type_name, where)
    for field in fields:
        if field.name not in properties:
            problems.append(f"{where}.{field.name}: missing")
            continue
        found = properties[field.name]
        if field.repeated:
            if found.get("type") != "array":
                problems.append(f"{where}.{field.name}: type {found.get('type')!r} where an array is defined")
                continue
            found = found.get("items", {})
        if field.kind == _MESSAGE:
            problems += _schema_problems(definitions, field.type_name, found, f"{where}.{field.name}")
        elif found.get("type") != _JSON_TYPES[field.kind]:
            problems.append(f"{where}.{field.name}: type {found.get('type')!r} where "
                            f"{_JSON_TYPES[field.kind]!r} is defined")
    return problems
