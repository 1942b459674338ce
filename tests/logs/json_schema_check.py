"""A checker for the JSON Schema subset the log's generated schemas use: an oracle for
the tests, independent of msgspec, that the schema a viewer reads agrees with the
messages beside it.

Understands type, nullable (OpenAPI's annotation), properties, additionalProperties as a
schema, required, items, minItems, maxItems, enum, minimum and maximum, and refuses a
schema with any other keyword, so that no constraint is ever skipped silently.
"""

from __future__ import annotations

import math
from typing import Any

_ANNOTATIONS = frozenset({"title", "description", "default"})
_KEYWORDS = frozenset({"type", "nullable", "properties", "additionalProperties", "required", "items",
                       "minItems", "maxItems", "enum", "minimum", "maximum"}) | _ANNOTATIONS
_PYTHON_TYPES: dict[str, type | tuple[type, ...]] = {
    "object": dict, "array": list, "string": str, "boolean": bool, "number": (int, float), "integer": int,
}


def schema_problem(schema: dict, value: Any, where: str = "message") -> str | None:
    """The first way ``value`` (decoded JSON) breaks ``schema``, as ``"where.field: what"``,
    or None if it conforms."""
    unknown = schema.keys() - _KEYWORDS
    if unknown:
        raise ValueError(f"{where}: the checker does not understand the keyword(s) {sorted(unknown)}")
    if value is None:
        return None if schema.get("nullable") else f"{where}: null where a value is required"
    kind = schema.get("type")
    if kind is not None and not _has_type(value, kind):
        return f"{where}: expected {kind}, got {type(value).__name__} {value!r}"
    if "enum" in schema and value not in schema["enum"]:
        return f"{where}: {value!r} is not one of {schema['enum']}"
    if "minimum" in schema and value < schema["minimum"]:
        return f"{where}: {value!r} < {schema['minimum']}"
    if "maximum" in schema and value > schema["maximum"]:
        return f"{where}: {value!r} > {schema['maximum']}"
    if isinstance(value, dict):
        properties = schema.get("properties", {})
        missing = [name for name in schema.get("required", ()) if name not in value]
        if missing:
            return f"{where}.{missing[0]}: required field missing"
        for name, item in value.items():
            item_schema = properties.get(name, schema.get("additionalProperties"))
            problem = None if item_schema is None else schema_problem(item_schema, item, f"{where}.{name}")
            if problem:
                return problem
    if isinstance(value, list):
        if not schema.get("minItems", 0) <= len(value) <= schema.get("maxItems", math.inf):
            return f"{where}: {len(value)} items, outside [{schema.get('minItems', 0)}, {schema.get('maxItems')}]"
        for index, item in enumerate(value):
            problem = schema_problem(schema.get("items", {}), item, f"{where}[{index}]")
            if problem:
                return problem
    return None


def _has_type(value: Any, name: str) -> bool:
    if isinstance(value, bool):
        return name == "boolean"
    if name == "integer" and isinstance(value, float):
        return math.isfinite(value) and value.is_integer()  # JSON Schema counts 3.0 as an integer
    return isinstance(value, _PYTHON_TYPES[name])
