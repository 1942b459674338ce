"""`recover_log`: rewrite whatever of a log is readable into a valid, finished MCAP file.

Records are copied as they are (message bytes, times and sequence numbers untouched),
so the copy of a complete log holds the same messages, and the copy of a truncated or
damaged one every intact chunk's messages, now with a summary and footer that any MCAP
reader (`mcap.reader.make_reader`, Foxglove, Lichtblick) accepts.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.writer import CompressionType, Writer

from ..errors import UserError
from ..files import OVERWRITE_HINT, publish
from .reader import LogDamage, damage_of, read_metadata, start_time_ns
from .records import RecordScanner
from .format import LOG_METADATA_NAME, RECOVERY_METADATA_NAME
from .writer import LIBRARY


@dataclass(frozen=True)
class RecoveryReport:
    """What `recover_log` kept.

    messages: messages written to the recovered file.
    last_t_s, first_t_s: session time of the last and first of them, s (None if none);
        from the log's start time, or relative to the first message if it has none.
    truncated: the input did not end properly (killed writer, cut file).
    damage: what damage inside the input cost (None if none).
    """

    messages: int
    last_t_s: float | None
    truncated: bool
    first_t_s: float | None = None
    damage: LogDamage | None = None


def recovered_path(log: str | Path) -> Path:
    """Where `hydrojet-bench recover` writes by default: ``run.mcap`` -> ``run.recovered.mcap``."""
    return Path(log).with_suffix(".recovered.mcap")


def recover_log(src: str | Path, dst: str | Path, *, overwrite: bool = False) -> RecoveryReport:
    """Copy every intact record of ``src`` (a log, possibly truncated or damaged) into a
    finished MCAP file ``dst``. ``dst`` appears only once complete, and never replaces an
    existing file unless ``overwrite``. Raises `UserError` if ``src`` is not MCAP, cannot
    be read, or is ``dst``, or ``dst`` exists."""
    src, dst = Path(src), Path(dst)
    if dst.resolve() == src.resolve():
        raise UserError(f"{dst}: the recovered log must not overwrite its source; choose another output")
    if dst.is_file() and not overwrite:
        # "A recovered log already exists there" read as a stale copy to replace, when
        # it may be a session's own log.
        raise UserError(f"{dst}: {_what_is_at(dst)}; {OVERWRITE_HINT}")

    def write(partial: Path) -> RecoveryReport:
        with partial.open("wb") as handle:
            return _copy(RecordScanner(src), Writer(handle, compression=CompressionType.ZSTD), str(src))

    return publish(dst, "recovered log", write, overwrite=overwrite)


def _what_is_at(path: Path) -> str:
    """What the existing file ``path`` is, said as "... already exists there"."""
    if path.stat().st_size == 0:
        return "an empty file already exists there"
    try:
        metadata = read_metadata(path)
    except UserError:
        return "a file that is no MCAP log already exists there"
    if RECOVERY_METADATA_NAME in metadata:
        return "a recovered log already exists there"
    if "bench" in metadata:
        return ("a session log already exists there (a session's own record, not a recovered copy: --overwrite "
                "would lose it)")
    return "an MCAP file that is no recovered log already exists there"


def _copy(scanner: RecordScanner, writer: Writer, source: str) -> RecoveryReport:
    started = False
    schemas: dict[int, int] = {0: 0}  # source id -> copy id; 0 is "no schema" in both
    channels: dict[int, int] = {}
    start_ns: int | None = None
    first: int | None = None
    last: int | None = None
    count = 0
    earlier: dict[str, str] = {}
    for record in scanner:
        if not started:
            header = record if isinstance(record, Header) else Header(profile="", library=LIBRARY)
            writer.start(profile=header.profile, library=header.library)
            started = True
        if isinstance(record, Metadata):
            if record.name == RECOVERY_METADATA_NAME:
                earlier = record.metadata  # a copy of a copy: what the first source lost stays said
                continue
            writer.add_metadata(record.name, record.metadata)
            if record.name == LOG_METADATA_NAME:
                start_ns = start_time_ns(record.metadata)
        elif isinstance(record, Schema) and record.id not in schemas:
            schemas[record.id] = writer.register_schema(record.name, record.encoding, record.data)
        elif isinstance(record, Channel) and record.id not in channels and record.schema_id in schemas:
            channels[record.id] = writer.register_channel(record.topic, record.message_encoding,
                                                          schemas[record.schema_id], record.metadata)
        elif isinstance(record, Message) and record.channel_id in channels:
            writer.add_message(channels[record.channel_id], log_time=record.log_time, data=record.data,
                               publish_time=record.publish_time, sequence=record.sequence)
            first = record.log_time if first is None else first
            last = record.log_time
            count += 1
        elif isinstance(record, Attachment):
            writer.add_attachment(record.create_time, record.log_time, record.name, record.media_type, record.data)
    if not started:
        writer.start(library=LIBRARY)
    origin = first if start_ns is None else start_ns

    def session_time(log_time: int | None) -> float | None:
        return None if log_time is None or origin is None else (log_time - origin) / 10**9

    report = RecoveryReport(messages=count, last_t_s=session_time(last), truncated=not scanner.complete,
                            first_t_s=session_time(first), damage=damage_of(scanner, 0, origin))
    lost = "; ".join(filter(None, (earlier.get("damage", ""), "" if report.damage is None
                                   else f"{source}: {report.damage.describe()}")))
    truncated = report.truncated or earlier.get("truncated") == "true"
    writer.add_metadata(RECOVERY_METADATA_NAME, {"source": earlier.get("source", source),
                                                 "truncated": "true" if truncated else "false", "damage": lost})
    writer.finish()
    return report
