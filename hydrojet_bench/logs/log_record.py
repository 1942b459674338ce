"""`LogRecord`, the base of every log message type, and the array shapes they share.

A record is a frozen `msgspec.Struct` whose fields are the JSON fields of its topic's
messages, ``t_s`` first. Arrays are tuples of floats; `floats` turns numpy arrays and
other sequences into one. Quaternions are (w, x, y, z), scalar first, as everywhere in
the bench (only the Foxglove messages keep Foxglove's ``{x, y, z, w}`` objects).
"""

from __future__ import annotations

from typing import Annotated, ClassVar, overload

import msgspec
import numpy as np
from numpy.typing import ArrayLike

Float3 = Annotated[tuple[float, ...], msgspec.Meta(min_length=3, max_length=3)]
WXYZ = Annotated[tuple[float, ...], msgspec.Meta(min_length=4, max_length=4)]  # a quaternion, scalar first


class LogRecord(msgspec.Struct, frozen=True, kw_only=True):
    """One message of a session log. Subclasses set `topic` (their MCAP channel) and
    `schema_namespace` (the prefix of their schema's name), and declare ``kw_only=True``
    so that ``t_s`` stays the first field on the wire."""

    topic: ClassVar[str]
    schema_namespace: ClassVar[str] = "hydrojet_bench"

    t_s: Annotated[float, msgspec.Meta(description="session time, s (virtual time on the simulated rig)")]


@overload
def floats(values: None) -> None: ...


@overload
def floats(values: ArrayLike) -> tuple[float, ...]: ...


def floats(values: ArrayLike | None) -> tuple[float, ...] | None:
    """``values`` (a numpy array, a sequence of numbers) as a record's tuple of floats;
    None stays None (a field that is not measured)."""
    if values is None:
        return None
    if type(values) is tuple and all(type(value) is float for value in values):
        return values  # already one: a log write per sample, thousands a second
    return tuple(np.asarray(values, dtype=float).tolist())
