"""One-line words for msgspec's validation errors: ``"<dotted.key> <what was
expected>, got <value>"``, with the nearest known name for an unknown key.

msgspec says ``Expected `float` > 0.0 - at `$.rod.length_m```; what was expected is
worded from the schema's own annotation at that path (bounds, list lengths, a
``Meta(description=...)``), and the value is looked up in the document.
"""

from __future__ import annotations

import difflib
import json
import re
import sys
import types
import typing
from collections.abc import Mapping
from typing import Any

import msgspec

_PATH = re.compile(r"^(?P<message>.*?)(?: - at `\$(?P<path>[^`]*)`)?$", re.DOTALL)
_EXPECTED = re.compile(r"^Expected `")
_MISSING = re.compile(r"^Object missing required field `(?P<field>[^`]+)`$")
_UNKNOWN = re.compile(r"^Object contains unknown field `(?P<field>[^`]+)`$")
_ENUM = re.compile(r"^Invalid enum value ")
_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")
_LARGEST_FLOAT = sys.float_info.max
_SCALAR_WORDS = {float: "a number", int: "an integer", str: "a string", bool: "true or false"}


class Problem(typing.NamedTuple):
    """A worded problem and the keys down to the value it is about (from the top)."""

    text: str
    keys: tuple[str | int | None, ...]


def top_level_problem(document: Mapping[str, Any], schema: type) -> Problem | None:
    """What msgspec would report late, or not word well, about the top level: an unknown
    key (a misspelt table, whose correct name would otherwise be reported missing), then
    the first required field absent, down to the first required key of an absent table."""
    known = schema.__struct_fields__
    for key in document:
        if key not in known:
            return Problem(f"{_key(key)} is not a known key{_suggestion(key, schema, [])}", (key,))
    missing = _first_missing(document, schema)
    return Problem(f"{missing} is required", ()) if missing else None


def _first_missing(document: Mapping[str, Any], schema: type) -> str | None:
    for field in msgspec.structs.fields(schema):
        if field.required and field.encode_name not in document:
            table = _struct_in(field.type)
            inner = _first_missing({}, table) if table is not None else None
            return f"{field.encode_name}.{inner}" if inner else field.encode_name
    return None


def explain(error: str, document: Mapping[str, Any], schema: type) -> Problem:
    """msgspec's ``"Expected `float` > 0.0 - at `$.rod.length_m`"`` as ``"rod.length_m
    must be a finite number > 0, got -0.07"``."""
    match = _PATH.match(error)
    assert match is not None  # the pattern matches any text
    message, raw_path = match["message"], match["path"] or ""
    parts = _pinpoint(_path_parts(raw_path), document, schema)
    dotted = _dotted(parts)
    if found := _MISSING.match(message):
        return Problem(f"{_join(dotted, found['field'])} is required", ())
    if found := _UNKNOWN.match(message):
        return Problem(f"{_join(dotted, found['field'])} is not a known key"
                       f"{_suggestion(found['field'], schema, parts)}", (*parts, found["field"]))
    if _EXPECTED.match(message) or _ENUM.match(message):
        expected = _phrase(_annotation_at(schema, parts))
        value = _value_at(document, parts)
        # [name] where [[name]] was meant: TOML's two spellings differ by a bracket.
        hint = (f" (write each as a [[{dotted}]] block)"
                if expected == "a list of tables" and isinstance(value, Mapping) and dotted else "")
        return Problem(f"{dotted or 'the file'} must be {expected}, got {_describe(value)}{hint}", tuple(parts))
    # A check in a table's __post_init__: its message starts with the (dotted) name of
    # the field it is about; other keys it weighs are named in the text.
    field = [*parts, *message.split(" ", 1)[0].split(".")]
    keys = tuple(field) if _annotation_at(schema, field) is not None else ()
    if dotted and not message.startswith(f"{dotted}."):
        return Problem(f"{dotted}.{message}", keys)
    return Problem(message, keys)


def _path_parts(raw_path: str) -> list[str | int | None]:
    """``.rod.length_m`` / ``.g[1]`` / ``.m[...]`` as keys, indices and None (any key)."""
    parts: list[str | int | None] = []
    for name, index in re.findall(r"\.([^.\[]+)|\[([^\]]*)\]", raw_path):
        if name:
            parts.append(name)
        else:
            parts.append(int(index) if index.isdigit() else None)
    return parts


def _pinpoint(parts: list[str | int | None], document: Mapping[str, Any], schema: type) -> list[str | int | None]:
    """msgspec names a bad value in a key -> value table ``[...]``: find its key."""
    if len(parts) < 2 or parts[-1] is not None:
        return parts
    annotation, entries = _annotation_at(schema, parts[:-1]), _value_at(document, parts[:-1])
    if typing.get_origin(annotation) is not dict or not isinstance(entries, Mapping):
        return parts
    for key, value in entries.items():
        try:
            msgspec.convert(value, typing.get_args(annotation)[1])
        except msgspec.ValidationError:
            return [*parts[:-1], key]
    return parts


def _dotted(parts: list[str | int | None]) -> str:
    text = ""
    for part in parts:
        if isinstance(part, str):
            text += f".{_key(part)}" if text else _key(part)
        else:
            text += f"[{'...' if part is None else part}]"
    return text


def _join(dotted: str, field: str) -> str:
    return f"{dotted}.{_key(field)}" if dotted else _key(field)


def _key(name: str) -> str:
    """A key as TOML writes it: bare, or quoted when it has other characters than
    letters, digits, _ and - (``"gravity.weight_scale"``)."""
    return name if _BARE_KEY.fullmatch(name) else json.dumps(name)


def _value_at(document: Any, parts: list[str | int | None]) -> Any:
    value = document
    for part in parts:
        if part is None:
            return _MISSING_VALUE
        try:
            value = value[part]
        except (KeyError, IndexError, TypeError):
            return _MISSING_VALUE
    return value


_MISSING_VALUE = object()


def _describe(value: Any) -> str:
    if value is _MISSING_VALUE:
        return "another type"
    if isinstance(value, Mapping):
        return "a table"
    return repr(value)


def _suggestion(field: str, schema: type, parts: list[str | int | None]) -> str:
    """``"; did you mean `session`?"`` with the table's keys, from the schema at ``parts``."""
    table = _struct_at(schema, parts)
    if table is None:
        return ""
    known = list(table.__struct_fields__)
    close = difflib.get_close_matches(field, known, n=1, cutoff=0.75)
    hint = f"; did you mean {close[0]}?" if close else ""
    where = f"[{_dotted(parts)}]" if parts else "the top level"
    return f"{hint} ({where} takes {', '.join(known)})"


def _annotation_at(schema: type, parts: list[str | int | None]) -> Any:
    """The schema's type for the value at ``parts``."""
    current: Any = schema
    for part in parts:
        current = _member_for(_without_none(current), part)
        if typing.get_origin(current) is typing.Annotated and isinstance(part, int):
            current = typing.get_args(current)[0]  # a constrained list: its items
        origin, arguments = typing.get_origin(current), typing.get_args(current)
        if isinstance(part, str) and _struct_in(current) is not None:
            current = typing.get_type_hints(_struct_in(current), include_extras=True).get(part)
        elif origin is dict:
            current = arguments[1]
        elif origin is list and isinstance(part, int):
            current = arguments[0]
        elif origin is tuple and isinstance(part, int):
            current = arguments[0] if arguments[-1] is Ellipsis else arguments[min(part, len(arguments) - 1)]
        else:
            return None
    return current


def _member_for(annotation: Any, part: str | int | None) -> Any:
    """The member of a union (``float | tuple[float, ...]``) that an index or key enters."""
    if typing.get_origin(annotation) not in (typing.Union, types.UnionType):
        return annotation
    for member in typing.get_args(annotation):
        origin = typing.get_origin(member)
        if (origin in (tuple, list) and isinstance(part, int)) or \
                (isinstance(part, str) and (origin is dict or _struct_in(member) is not None)):
            return member
    return annotation


def _without_none(annotation: Any) -> Any:
    arguments = [a for a in typing.get_args(annotation) if a is not type(None)]
    if typing.get_origin(annotation) in (typing.Union, types.UnionType) and len(arguments) == 1:
        return arguments[0]
    return annotation


def _phrase(annotation: Any) -> str:
    """What a value of the schema type ``annotation`` looks like, in words."""
    annotation = _without_none(annotation)
    origin, arguments = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is typing.Annotated:
        described = [meta.description for meta in arguments[1:] if getattr(meta, "description", None)]
        if described:
            return described[0]
        words = _SCALAR_WORDS.get(arguments[0]) or _phrase(arguments[0])
        bounds = []
        for meta in arguments[1:]:
            for name, symbol in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<=")):
                bound = getattr(meta, name, None)
                if bound is None:
                    continue
                if abs(bound) == _LARGEST_FLOAT:
                    words = words.replace("a number", "a finite number")
                else:
                    bounds.append(f"{symbol} {bound:g}" if isinstance(bound, float) else f"{symbol} {bound}")
            shortest, longest = getattr(meta, "min_length", None), getattr(meta, "max_length", None)
            limits = ((("exactly", shortest),) if shortest is not None and shortest == longest
                      else (("at least", shortest), ("at most", longest)))
            bounds += [f"with {limit} {length} entr{'y' if length == 1 else 'ies'}"
                       for limit, length in limits if length is not None]
        return " ".join([words, " and ".join(bounds)]).strip()
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_phrase(a) for a in arguments if a is not type(None))
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(argument) for argument in arguments)
    if origin is list:
        return _phrase(tuple[arguments[0], ...])
    if origin is tuple:
        item = _phrase(arguments[0]).removeprefix("a ").removeprefix("an ")
        # The item's first noun only: "list of numbers" -> "lists of numbers".
        item = re.sub(r"\b(number|string|integer|list|table)\b", r"\1s", item, count=1)
        if arguments[-1] is Ellipsis:
            return f"a list of {item}"
        return f"a list of {len(arguments)} {item}"
    if origin is dict:
        return f"a table of {_phrase(arguments[1]).removeprefix('a ')}s"
    if _struct_in(annotation) is not None:
        return "a table"
    return _SCALAR_WORDS.get(annotation, "a value of another type")


def _struct_at(schema: type, parts: list[str | int | None]) -> type | None:
    return _struct_in(_annotation_at(schema, parts))


def _struct_in(annotation: Any) -> type | None:
    """The Struct type inside ``annotation`` (``X``, ``X | None``), if any."""
    if isinstance(annotation, type) and issubclass(annotation, msgspec.Struct):
        return annotation
    for argument in typing.get_args(annotation):
        if isinstance(argument, type) and issubclass(argument, msgspec.Struct):
            return argument
    return None
