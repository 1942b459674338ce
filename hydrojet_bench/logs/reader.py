"""Reading session logs, complete, cut off or damaged: `read_log` and `read_metadata`."""

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
class LogDamage:
    """What a damaged log lost; the readers kept everything else.

    skipped_stretches: damaged stretches of the file skipped (each up to the next intact
        chunk); skipped_bytes: their total size, bytes.
    chunks_lost: chunks in them; messages_lost: messages in them, all topics (None if
        the damage took the file's indexes too).
    lost_spans_s: ((from_t_s, to_t_s), ...): session times, s, between which messages
        are missing (None at an end that has no intact message).
    undecodable_messages: whole messages of the topics read that their record type
        could not read, skipped.
    duplicated_records: messages that repeat an earlier one exactly, skipped (all topics).
    metadata_lost: names of the metadata records in the damaged stretches (None for one
        whose name is lost too).
    """

    skipped_stretches: int
    skipped_bytes: int
    chunks_lost: int
    messages_lost: int | None
    lost_spans_s: tuple[tuple[float | None, float | None], ...]
    undecodable_messages: int
    duplicated_records: int = 0
    metadata_lost: tuple[str | None, ...] = ()

    def lost_metadata(self, name: str) -> bool:
        """Whether the metadata record ``name`` may be one the damage took."""
        return name in self.metadata_lost or None in self.metadata_lost

    def describe(self) -> str:
        """One line: what was lost."""
        parts = []
        # A stretch that held metadata records only is said as such: "0 damaged chunks,
        # 0 messages" hid that the rig profile was lost.
        only_metadata = bool(self.metadata_lost) and not self.chunks_lost and self.messages_lost == 0
        if self.metadata_lost:
            names = sorted({"(name unreadable)" if name is None else repr(name) for name in self.metadata_lost})
            held = (": the rig profile, plan and model the session ran are lost with it"
                    if self.lost_metadata("bench") else
                    ": the session's start time is lost with it (times count from the first message)"
                    if self.lost_metadata(LOG_METADATA_NAME) else "")
            size = f" ({self.skipped_bytes} bytes)" if only_metadata else ""
            parts.append(f"damaged metadata record(s) {', '.join(names)} skipped{size}{held}")
        if self.skipped_stretches and not only_metadata:
            messages = "an unknown number of" if self.messages_lost is None else str(self.messages_lost)
            spans = ", ".join(f"{_time(start)} to {_time(end)}" for start, end in self.lost_spans_s)
            parts.append(f"{self.chunks_lost} damaged chunk(s) skipped ({self.skipped_bytes} bytes, {messages} "
                         f"messages, session time {spans})")
        if self.undecodable_messages:
            parts.append(f"{self.undecodable_messages} unreadable message(s) skipped")
        if self.duplicated_records:
            parts.append(f"{self.duplicated_records} duplicated record(s) skipped (each an exact repeat of one "
                         "before it)")
        return "; ".join(parts)

    def as_dict(self) -> dict[str, object]:
        return {"skipped_stretches": self.skipped_stretches, "skipped_bytes": self.skipped_bytes,
                "chunks_lost": self.chunks_lost, "messages_lost": self.messages_lost,
                "lost_spans_s": [list(span) for span in self.lost_spans_s],
                "undecodable_messages": self.undecodable_messages, "duplicated_records": self.duplicated_records,
                "metadata_lost": list(self.metadata_lost)}


def _time(t_s: float | None) -> str:
    return "?" if t_s is None else f"{t_s:.3f} s"


@dataclass(frozen=True)
class LogContents:
    """What a log holds.

    messages: the records, in file order (the order they were written); a record's
        ``topic`` names its topic, its ``t_s`` is its session time, s.
    metadata: the writer's named metadata records, e.g. ``metadata["bench"]["profile_name"]``.
    truncated: True unless the file ended properly (footer and closing magic), i.e. the
        writer was killed or the file was cut (or damaged at its end); everything whole
        before the cut is kept.
    start_time_unix_s: wall-clock time of ``t_s = 0``, s since the Unix epoch (None if the
        file does not say).
    damage: what damage inside the file cost (None if there was none).
    """

    messages: list[LogRecord]
    metadata: dict[str, dict[str, str]]
    truncated: bool
    start_time_unix_s: float | None = None
    damage: LogDamage | None = None

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
    """Every whole message of a session log (of ``topics`` only, if given), complete,
    truncated or damaged, as records. A damaged chunk, or a message its record type
    cannot read, is skipped and counted in `LogContents.damage`. Raises `UserError` for a
    file that is not MCAP, `LogError` naming the file, topic and field when not one
    message of a topic can be read (a log of another format, not damage), and ValueError
    for a topic not in `TOPICS`. Channels of other topics or not in JSON (another
    program's MCAP) are skipped."""
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
    read_on: dict[str, int] = {}
    unreadable: dict[str, LogError] = {}
    undecodable = 0
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
                read_on[topic] = read_on.get(topic, 0) + 1
            except LogError as error:
                undecodable += 1
                log_time_s = (record.log_time - (first_log_time if start_ns is None else start_ns)) / _NS_PER_S
                unreadable.setdefault(topic, LogError(f"{path}, message at t_s={log_time_s!r} s: {error}"))
    for topic, error in unreadable.items():
        if topic not in read_on:
            raise error
    origin = first_log_time if start_ns is None else start_ns
    return LogContents(messages=messages, metadata=metadata, truncated=not scanner.complete,
                       start_time_unix_s=None if start_ns is None else start_ns / _NS_PER_S,
                       damage=damage_of(scanner, undecodable, origin))


def damage_of(scanner: RecordScanner, undecodable: int, origin_ns: int | None) -> LogDamage | None:
    """What a finished scan of ``scanner`` skipped, with ``undecodable`` messages, times
    relative to ``origin_ns`` (the log's t_s = 0, ns)."""
    skipped = scanner.skipped
    if not skipped and not undecodable and not scanner.duplicates:
        return None

    def session_time(log_time: int | None) -> float | None:
        return None if log_time is None or origin_ns is None else (log_time - origin_ns) / _NS_PER_S

    if scanner.messages_in_file is not None:
        lost: int | None = scanner.messages_in_file - scanner.messages_read
    else:
        counts = [stretch.messages for stretch in skipped]
        lost = None if None in counts else sum(counts)
    return LogDamage(skipped_stretches=len(skipped), skipped_bytes=sum(s.end - s.start for s in skipped),
                     chunks_lost=sum(s.chunks for s in skipped), messages_lost=lost,
                     lost_spans_s=tuple((session_time(s.last_before_ns), session_time(s.first_after_ns))
                                        for s in skipped),
                     undecodable_messages=undecodable, duplicated_records=scanner.duplicates,
                     metadata_lost=tuple(name for stretch in skipped for name in stretch.metadata))


def read_metadata(path: str | Path) -> dict[str, dict[str, str]]:
    """The named metadata records of a log (complete or truncated), without reading its
    messages. Raises `UserError` for a file that is not MCAP."""
    return {record.name: dict(record.metadata) for record in RecordScanner(path, open_chunks=False)
            if isinstance(record, Metadata) and record.name != LOG_METADATA_NAME}
