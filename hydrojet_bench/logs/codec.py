"""Log records to JSON bytes and back.

JSON has no NaN or infinity: a non-finite float is written as null, which reads back as
None where the field may be null and is refused where it may not. Floats are written
as their shortest exact text, so they read back bit for bit. numpy arrays and scalars
in a record are written as the plain numbers they hold.
"""

from __future__ import annotations

import re
from typing import Any

import msgspec
import numpy as np

from ..errors import UserError
from .log_record import LogRecord
from .topics import TOPICS


class LogError(UserError):
    """A log message its topic's record type cannot read; the message names the topic
    and the field."""


def _numpy_as_json(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"cannot write {type(value).__name__} {value!r} in a log message")


_ENCODER = msgspec.json.Encoder(enc_hook=_numpy_as_json)
# Lax (strict=False): JSON Schema counts 3.0 as an integer, and so did the checker that
# guarded logs of earlier versions, so such a log may hold 3.0 in an integer field. Lax
# also reads numbers and booleans written as strings, which no bench writer produces.
_DECODERS = {topic: msgspec.json.Decoder(record_type, strict=False) for topic, record_type in TOPICS.items()}
_AT = re.compile(r"^(?P<what>.*) - at `\$(?P<where>[^`]*)`$", re.DOTALL)


def encode(record: LogRecord) -> bytes:
    """Compact UTF-8 JSON of ``record``."""
    return _ENCODER.encode(record)


def decode(topic: str, data: bytes) -> LogRecord:
    """The record of one message on ``topic`` (a key of `TOPICS`). Raises `LogError`,
    e.g. ``/em/frame.tools[0]: Object missing required field `handle```, for anything
    else than a message of that topic."""
    try:
        return _DECODERS[topic].decode(data)
    except msgspec.ValidationError as error:
        found = _AT.match(str(error))
        if found is None:
            raise LogError(f"{topic}: {error}") from None
        raise LogError(f"{topic}{found['where']}: {found['what']}") from None
    except msgspec.DecodeError as error:
        raise LogError(f"{topic}: {error}") from None
