"""The JSON schema of each log topic, generated from its record type.

`msgspec.json.schema` writes references into ``$defs``, ``anyOf`` with null for a field
that may be null, and enums without a type. Foxglove and Lichtblick derive each
channel's message definition from its schema and accept only one type name per field,
typed ``items`` for every array and ``properties`` for every object, without resolving
references; so `topic_schema` inlines the references, marks a field that may be null
with the OpenAPI annotation ``"nullable": true`` (JSON Schema's ``"type": [..., "null"]``
is not understood there) and gives every enum its type.
"""

from __future__ import annotations

import inspect
from functools import cache
from typing import Any

import msgspec

from .log_record import LogRecord

JsonSchema = dict[str, Any]
_JSON_TYPES = {str: "string", bool: "boolean", int: "integer", float: "number"}


def schema_name(record_type: type[LogRecord]) -> str:
    """The name a topic's schema is registered under, e.g. ``hydrojet_bench.Sample``."""
    return f"{record_type.schema_namespace}.{record_type.__name__}"


@cache
def topic_schema(record_type: type[LogRecord]) -> JsonSchema:
    """The self-contained JSON schema of ``record_type``'s messages, as plain JSON values."""
    generated = msgspec.json.schema(record_type)
    schema = _viewer_form(generated, generated.get("$defs", {}))
    return msgspec.json.decode(msgspec.json.encode({**schema, "title": schema_name(record_type)}))  # () -> []


def topic_schema_json(record_type: type[LogRecord]) -> bytes:
    """`topic_schema` as the JSON bytes a log (or a live Foxglove channel) registers."""
    return msgspec.json.encode(topic_schema(record_type))


def _viewer_form(node: JsonSchema, defs: dict[str, JsonSchema]) -> JsonSchema:
    """``node`` with references inlined, nullable fields annotated and enums typed."""
    if "$ref" in node:
        rest = {key: value for key, value in node.items() if key not in ("$ref", "$defs")}
        return _viewer_form({**defs[node["$ref"].rsplit("/", 1)[-1]], **rest}, defs)
    if "anyOf" in node:
        kinds = [branch for branch in node["anyOf"] if branch != {"type": "null"}]
        if len(kinds) != 1 or len(node["anyOf"]) != 2:
            raise ValueError(f"a viewer's schema cannot express the union {node['anyOf']}")
        rest = {key: value for key, value in node.items() if key != "anyOf"}
        merged = {**_viewer_form(kinds[0], defs), **rest, "nullable": True}
        merged["description"] = f"{merged['description']}; null if unknown" if "description" in merged \
            else "null if unknown"
        return merged
    result = dict(node)
    if "description" in result:
        result["description"] = inspect.cleandoc(result["description"])
    if "enum" in result and "type" not in result:
        kinds = {_JSON_TYPES[type(value)] for value in result["enum"]}
        if len(kinds) != 1:
            raise ValueError(f"a viewer's schema cannot express the mixed enum {result['enum']}")
        result["type"] = kinds.pop()
    if result.get("type") == "object":
        result["properties"] = {name: _viewer_form(field, defs) for name, field in result.get("properties", {}).items()}
    for key in ("items", "additionalProperties"):
        if isinstance(result.get(key), dict):
            result[key] = _viewer_form(result[key], defs)
    return result
