"""JSON encoding of log messages: numpy in, plain JSON out, no NaN.

JSON has no NaN or infinity, so a non-finite float is written as null (the schemas mark
which fields may be null). Floats are written by ``repr``, so they read back bit for bit.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

import numpy as np


def jsonable(value: Any, where: str = "message") -> Any:
    """``value`` as plain JSON types: numpy arrays and tuples become lists, numpy scalars
    Python numbers, non-finite floats None. Mapping keys must be strings. Anything else
    raises ValueError naming the field (``where``)."""
    if value is None or isinstance(value, (str, bool, int)):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        result = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise ValueError(f"{where}: keys must be strings, got {key!r}")
            result[key] = jsonable(item, f"{where}.{key}")
        return result
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist(), where)
    if isinstance(value, np.generic):
        return jsonable(value.item(), where)
    if isinstance(value, (list, tuple)):
        return [jsonable(item, f"{where}[{index}]") for index, item in enumerate(value)]
    raise ValueError(f"{where}: cannot write {type(value).__name__} {value!r} as JSON")


def encode(value: Any) -> bytes:
    """Compact UTF-8 JSON of an already `jsonable` value."""
    return json.dumps(value, allow_nan=False, separators=(",", ":"), ensure_ascii=False).encode()


def decode(data: bytes) -> Any:
    return json.loads(data)
