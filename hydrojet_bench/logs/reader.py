"""Reading session logs, complete or cut off: `read_log` and `read_metadata`."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from mcap.records import Channel, Message, Metadata

from .codec import LogError, decode
from .format import LOG_METADATA_NAME, MESSAGE_ENCODING, START_TIME_KEY
from .log_record import LogRecord
from .records import RecordScanner
from .topics import TOPICS

_NS_PER_S = 10**9  # an int: int / int divides with correct rounding
Record = TypeVar("Record", bound=LogRecord)


@dataclass(frozen=True)
class LogContents:
    """What a log holds.

    messages: the records, in file order (the order they were written); a record's
        ``topic`` names its topic, its ``t_s`` is its session time, s.
    metadata: the writer's named metadata records, e.g. ``metadata["bench"]["profile_name"]``.
    truncated: True unless the file ended properly (footer and closing magic), i.e. the
        writer was killed or the file was cut or damaged; everything whole before the
        damage is kept.
    start_time_unix_s: wall-clock time of ``t_s = 0``, s since the Unix epoch (None if the
        file does not say).
    """

    messages: list[LogRecord]
    metadata: dict[str, dict[str, str]]
    truncated: bool
    start_time_unix_s: float | None = None

    def on(self, record_type: type[Record]) -> list[Record]:
        """The messages of one topic, given by its record type, in file order."""
        return [message for message in self.messages if type(message) is record_type]


def start_time_ns(metadata: dict[str, str]) -> int | None:
    """The log's ``t_s = 0`` in ns since the Unix epoch, from its own metadata record."""
    try:
        return int(metadata[START_TIME_KEY])
    except (KeyError, ValueError):
        return None


def read_log(path: str | Path, topics: Iterable[str] | None = None) -> LogContents:
    """Every whole message of a session log (of ``topics`` only, if given), complete or
    truncated, as records. Raises `UserError` for a file that is not MCAP, `LogError`
    naming the file, topic and field for a message its record type cannot read, and
    ValueError for a topic not in `TOPICS`. Channels of other topics or not in JSON
    (another program's MCAP) are skipped."""
    wanted = None if topics is None else set(topics)
    unknown = sorted((wanted or set()) - TOPICS.keys())
    if unknown:
        raise ValueError(f"unknown log topic(s) {', '.join(unknown)}; topics: {', '.join(TOPICS)}")
    scanner = RecordScanner(path)
    channels: dict[int, str | None] = {}
    metadata: dict[str, dict[str, str]] = {}
    start_ns: int | None = None
    first_log_time: int | None = None
    messages: list[LogRecord] = []
    for record in scanner:
        if isinstance(record, Metadata):
            if record.name == LOG_METADATA_NAME:
                start_ns = start_time_ns(record.metadata)
            else:
                metadata[record.name] = dict(record.metadata)
        elif isinstance(record, Channel):
            keep = (record.message_encoding == MESSAGE_ENCODING and record.topic in TOPICS
                    and (wanted is None or record.topic in wanted))
            channels.setdefault(record.id, record.topic if keep else None)
        elif isinstance(record, Message):
            first_log_time = record.log_time if first_log_time is None else first_log_time
            topic = channels.get(record.channel_id)
            if topic is None:
                continue
            try:
                messages.append(decode(topic, record.data))
            except LogError as error:
                log_time_s = (record.log_time - (first_log_time if start_ns is None else start_ns)) / _NS_PER_S
                raise LogError(f"{path}, message at t_s={log_time_s!r} s: {error}") from None
    return LogContents(messages=messages, metadata=metadata, truncated=not scanner.complete,
                       start_time_unix_s=None if start_ns is None else start_ns / _NS_PER_S)


def read_metadata(path: str | Path) -> dict[str, dict[str, str]]:
    """The named metadata records of a log (complete or truncated), without reading its
    messages. Raises `UserError` for a file that is not MCAP."""
    return {record.name: dict(record.metadata) for record in RecordScanner(path, open_chunks=False)
            if isinstance(record, Metadata) and record.name != LOG_METADATA_NAME}
