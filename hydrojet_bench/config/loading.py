"""Reading typed TOML files: profiles (with ``extends``) and any other `msgspec` schema.

Every problem is a `UserError` of one line naming the file (`messages` words it).
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

import msgspec

from ..errors import UserError
from .messages import explain, top_level_problem
from .schema import RigConfig

T = TypeVar("T")

# Where the shipped profiles live (a checkout or an editable install).
PROFILES_DIR = Path(__file__).resolve().parents[2] / "profiles"


def read_toml(path: Path, what: str = "file") -> dict[str, Any]:
    """A TOML file's document; unreadable or malformed files are `UserError`s (``what``
    the file is names a missing one)."""
    try:
        # A byte-order mark (some Windows editors write one) is no TOML; CSV inputs allow it too.
        return tomllib.loads(path.read_bytes().decode("utf-8").removeprefix("\ufeff"))
    except FileNotFoundError:
        raise UserError(f"{path}: no such {what}") from None
    except tomllib.TOMLDecodeError as error:
        raise UserError(f"{path}: not valid TOML: {error}") from None
    except UnicodeDecodeError as error:
        raise UserError(f"{path}: not UTF-8 text (byte {error.start}); save it as UTF-8") from None
    except OSError as error:
        raise UserError(f"{path}: cannot read: {error.strerror or error}") from None


def convert(document: Mapping[str, Any], schema: type[T], source: str,
            origins: Mapping[tuple[str, ...], str] | None = None) -> T:
    """``document`` as a ``schema`` instance; ``source`` names the document in errors,
    or, for a value that came from another file, ``origins`` (keys down to a value ->
    the file it came from, `_resolve_extends`) names that one."""
    problem = top_level_problem(document, schema)
    if problem is None:
        try:
            return msgspec.convert(document, schema)
        except msgspec.ValidationError as error:
            problem = explain(str(error), document, schema)
    origin = (origins or {}).get(tuple(key for key in problem.keys if isinstance(key, str)), source)
    where = source if origin == source else f"{origin} (extended by {source})"
    raise UserError(f"{where}: {problem.text}")


def resolve_profile_path(spec: str | Path, relative_to: Path | None = None) -> Path:
    """A profile file from a path (relative to ``relative_to`` if given), or from the name
    of a shipped profile (``"sim"`` -> ``profiles/sim.toml``) when no such file exists."""
    path = Path(spec)
    candidate = relative_to / path if relative_to is not None and not path.is_absolute() else path
    if candidate.is_file():
        return candidate
    if path.suffix == "" and path.parent == Path("."):
        shipped = PROFILES_DIR / f"{path.name}.toml"
        if shipped.is_file():
            return shipped
    known = ", ".join(sorted(p.stem for p in PROFILES_DIR.glob("*.toml"))) or "none"
    raise UserError(f"rig profile {str(spec)!r} not found: give a TOML file or the name of a "
                    f"shipped profile ({known})")


def load_config(path: Path) -> RigConfig:
    """The profile at ``path`` (its ``extends`` chain merged), typed and checked."""
    return config_from_mapping(read_toml(path), source=str(path), path=path)


def config_from_mapping(document: Mapping[str, Any], *, source: str, path: Path | None = None) -> RigConfig:
    """A parsed profile document, typed and checked. ``extends`` resolves against
    ``path``'s folder (the working directory without one); ``name`` defaults to
    ``path``'s stem."""
    origins: dict[tuple[str, ...], str] = {}
    merged = _resolve_extends(document, source, path, (path.resolve(),) if path is not None else (), origins)
    if "name" not in document:
        # A child profile is its own rig: it never inherits its parent's name.
        merged.pop("name", None)
        if path is not None:
            merged["name"] = path.stem
    return convert(merged, RigConfig, source, origins)


def _resolve_extends(document: Mapping[str, Any], source: str, path: Path | None,
                     seen: tuple[Path, ...], origins: dict[tuple[str, ...], str]) -> dict[str, Any]:
    """``document`` over its ``extends`` chain; ``origins`` gets each key (a table's and
    each value's, as the keys down to it) and the file whose value is kept."""
    child = dict(document)
    parent_spec = child.pop("extends", None)
    if parent_spec is None:
        _note_origins(child, source, (), origins)
        return child
    if not isinstance(parent_spec, str):
        raise UserError(f"{source}: extends must be a profile name or a relative path, got {parent_spec!r}")
    try:
        parent_path = resolve_profile_path(parent_spec, path.parent if path is not None else None)
    except UserError as error:
        raise UserError(f"{source}: extends {error}") from None
    if parent_path.resolve() in seen:
        chain = " -> ".join(str(p) for p in (*seen, parent_path.resolve()))
        raise UserError(f"{source}: extends {parent_spec!r} makes a cycle ({chain})")
    parent = _resolve_extends(read_toml(parent_path), str(parent_path), parent_path,
                              (*seen, parent_path.resolve()), origins)
    _note_origins(child, source, (), origins)  # after the parent's: the child's values win
    return _merge(parent, child)


def _note_origins(document: Mapping[str, Any], source: str, keys: tuple[str, ...],
                  origins: dict[tuple[str, ...], str]) -> None:
    for key, value in document.items():
        origins[(*keys, key)] = source
        if isinstance(value, Mapping):
            _note_origins(value, source, (*keys, key), origins)


def _merge(parent: Mapping[str, Any], child: Mapping[str, Any]) -> dict[str, Any]:
    """``child`` over ``parent``, tables merged key by key, any other value replaced."""
    merged = dict(parent)
    for key, value in child.items():
        if isinstance(value, Mapping) and isinstance(merged.get(key), Mapping):
            merged[key] = _merge(merged[key], value)
        else:
            merged[key] = value
    return merged
