"""What the shipped Foxglove layout refers to: message paths (a topic, an optional
``{field=="value"}`` filter, then ``.field`` and ``[index]`` steps) and coordinate frames,
and whether a path names fields the topic's record type has."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec.inspect as mi

from hydrojet_bench.logs import TOPICS

LAYOUT = Path(__file__).parents[2] / "docs" / "foxglove" / "hydrojet.json"
_PATH = re.compile(r'^(?P<topic>/[\w/]+?)(?:\{(?P<key>\w+)==(?P<value>"[^"]*"|-?[\d.]+)\})?'
                   r'(?P<steps>(?:\.\w+|\[\d+\])*)$')
_STEP = re.compile(r"\.(\w+)|\[(\d+)\]")
_FRAME_KEYS = ("followTf", "frameId", "fixedFrame")


@dataclass(frozen=True)
class MessagePath:
    text: str
    topic: str
    filter_key: str | None
    filter_value: str | None
    steps: tuple[str | int, ...]  # field names and array indices


def layout_references(layout: Any) -> tuple[list[MessagePath], set[str]]:
    """Every message path (any key or string starting with "/") and every frame
    (``frame:<name>`` keys, followTf, frameId, fixedFrame) in a layout's JSON."""
    paths: list[MessagePath] = []
    frames: set[str] = set()

    def visit(node: Any, key: str | None = None) -> None:
        if isinstance(node, dict):
            for name, value in node.items():
                if name.startswith("frame:"):
                    frames.add(name.removeprefix("frame:"))
                if name.startswith("/"):
                    paths.append(parse_path(name))
                visit(value, name)
        elif isinstance(node, list):
            for item in node:
                visit(item, key)
        elif isinstance(node, str):
            if key in _FRAME_KEYS:
                frames.add(node)
            elif node.startswith("/"):
                paths.append(parse_path(node))

    visit(layout)
    return paths, frames


def parse_path(text: str) -> MessagePath:
    found = _PATH.match(text)
    if found is None:
        raise ValueError(f"not a message path: {text!r}")
    steps = tuple(name if name else int(index) for name, index in _STEP.findall(found["steps"]))
    value = found["value"]
    return MessagePath(text, found["topic"], found["key"], value and value.strip('"'), steps)


def path_problem(path: MessagePath) -> str | None:
    """Why ``path`` names nothing in its topic's messages, or None. A path with steps must
    end at a number (it is plotted)."""
    record_type = TOPICS.get(path.topic)
    if record_type is None:
        return f"{path.text}: no topic {path.topic}"
    fields = _fields(mi.type_info(record_type))
    if path.filter_key is not None:
        if path.filter_key not in fields:
            return f"{path.text}: no field {path.filter_key} to filter on"
        kind = _unwrapped(fields[path.filter_key])
        if isinstance(kind, mi.LiteralType) and path.filter_value not in kind.values:
            return f"{path.text}: {path.filter_key} is never {path.filter_value!r}"
    kind: mi.Type = mi.type_info(record_type)
    for step in path.steps:
        kind = _unwrapped(kind)
        if isinstance(step, int):
            if not isinstance(kind, (mi.VarTupleType, mi.ListType)):
                return f"{path.text}: [{step}] of a {type(kind).__name__}"
            if step >= (kind.max_length or step + 1):
                return f"{path.text}: [{step}] beyond {kind.max_length} items"
            kind = kind.item_type
        else:
            members = _fields(kind) if isinstance(kind, mi.StructType) else {}
            if step not in members:
                return f"{path.text}: no field {step}"
            kind = members[step]
    if path.steps and not isinstance(_unwrapped(kind), (mi.FloatType, mi.IntType)):
        return f"{path.text}: ends at a {type(_unwrapped(kind)).__name__}, not a number"
    return None


def _fields(kind: mi.StructType) -> dict[str, mi.Type]:
    return {field.name: field.type for field in kind.fields}


def _unwrapped(kind: mi.Type) -> mi.Type:
    """``kind`` without null (a field that may be null) and without metadata."""
    while True:
        if isinstance(kind, mi.Metadata):
            kind = kind.type
        elif isinstance(kind, mi.UnionType):
            (kind,) = [member for member in kind.types if not isinstance(member, mi.NoneType)]
        else:
            return kind
