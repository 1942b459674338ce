"""Linear reading of an MCAP file that keeps every intact record, around damage too.

`mcap.reader.make_reader` starts from the footer, which a killed writer never wrote; the
library's StreamReader reads forward but ends a damaged file with whatever exception the
damage happens to cause. `RecordScanner` reads forward, checks each record's length
against the bytes left and the next record's head, opens chunks with their CRC checked,
and at a record that does not parse skips ahead to the next intact chunk (an opcode,
a length that fits, a body that parses with a matching CRC), so one damaged chunk costs
that chunk only. What it skipped is in `RecordScanner.skipped`; a file that merely
ends early (a killed writer) skips nothing, it is `truncated`.
"""

from __future__ import annotations

import dataclasses
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import (Attachment, Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, McapRecord, Message,
                          MessageIndex, Metadata, MetadataIndex, Schema, Statistics)
from mcap.stream_reader import breakup_chunk

from ..errors import UserError
from ..files import check_regular_input

MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEAD = struct.Struct("<BQ")
_FOOTER_LENGTH = 8 + 8 + 4
_OPCODES = frozenset(int(opcode) for opcode in Opcode)
# A record longer than this is a damaged length field, not a session log.
_MAX_RECORD_LENGTH = 1 << 40

# Records the scanner parses (messages too, parsed apart: they need their length), each
# also to check that its fields fill its length exactly; of them it yields `_WANTED`. The
# indexes and statistics only repeat the data section (the summary's are read for what
# damage cost).
_PARSERS = {
    Opcode.HEADER: Header.read, Opcode.FOOTER: Footer.read, Opcode.SCHEMA: Schema.read,
    Opcode.CHANNEL: Channel.read, Opcode.METADATA: Metadata.read, Opcode.CHUNK: Chunk.read,
    Opcode.ATTACHMENT: Attachment.read, Opcode.DATA_END: DataEnd.read,
    Opcode.MESSAGE_INDEX: MessageIndex.read, Opcode.STATISTICS: Statistics.read, Opcode.CHUNK_INDEX: ChunkIndex.read,
    Opcode.METADATA_INDEX: MetadataIndex.read,
}
_WANTED = frozenset({Opcode.HEADER, Opcode.FOOTER, Opcode.SCHEMA, Opcode.CHANNEL, Opcode.METADATA, Opcode.CHUNK,
                     Opcode.ATTACHMENT, Opcode.DATA_END, Opcode.MESSAGE})
# Where reading resumes after damage: a chunk, or the end of the data section.
_RESYNC = (Opcode.CHUNK, Opcode.DATA_END)


@dataclass(frozen=True)
class SkippedStretch:
    """A damaged stretch of the file, skipped up to the next intact chunk.

    start, end: its byte offsets in the file.
    chunks: chunks it held (from the file's chunk index; else 1 if it began with one).
    messages: messages those chunks held, from the file's message indexes (None if the
        damage took them too).
    last_before_ns, first_after_ns: log time of the last message read before it and
        of the first read after it, ns (None if there is none).
    metadata: names of the metadata records it held (from the file's metadata index;
        else None for one whose name is lost with it, if it began with one).
    """

    start: int
    end: int
    chunks: int
    messages: int | None
    last_before_ns: int | None = None
    first_after_ns: int | None = None
    metadata: tuple[str | None, ...] = ()


class RecordScanner:
    """Iterate over the intact records of an MCAP file in file order (a chunk is replaced
    by the schemas, channels and messages inside it). A complete file's summary schemas
    and channels come first after the header too, so that messages whose chunk lost its
    channel record can still be read.

    path: the file. A file that does not start with the MCAP magic, or is not a regular
        file, raises `UserError` naming it; an empty file, or one holding only the start
        of the magic, is a log cut off before its first record and yields nothing. A file
        holding a second log after the first (two files concatenated) raises `UserError`
        naming the byte where the second begins.
    open_chunks: False skips intact chunks unread (for metadata only).

    A message that repeats an earlier one exactly (channel, sequence number, times and
    bytes) is skipped and counted in `duplicates`.

    After iterating: `complete` (footer and closing magic found), `skipped` (the damaged
    stretches), `duplicates`, `messages_read` (duplicates included), and
    `messages_in_file` (the file's own message count, from a readable summary; None
    without one).
    """

    def __init__(self, path: str | Path, *, open_chunks: bool = True) -> None:
        self.path = Path(path)
        self.open_chunks = open_chunks
        self.complete = False
        self.skipped: list[SkippedStretch] = []
        self.messages_in_file: int | None = None
        self.messages_read = 0
        self.duplicates = 0

    def __iter__(self) -> Iterator[McapRecord]:
        self.complete = False
        self.skipped = []
        self.messages_in_file = None
        self.messages_read = 0
        self.duplicates = 0
        check_regular_input(self.path)
        try:
            data = self.path.read_bytes()
        except OSError as error:
            raise UserError(f"{self.path}: cannot read: {error.strerror or error}") from None
        if not data.startswith(MAGIC):
            if MAGIC.startswith(data):
                return
            raise UserError(f"{self.path}: not an MCAP file (it does not start with the MCAP magic bytes); "
                            "expected a session log written by the bench")
        summary = _Summary.of(data)
        self.messages_in_file = summary.message_count
        position = len(MAGIC)
        last_log_time: int | None = None
        summary_given = False
        # A record written twice (a tool that copied a log badly) would be analysed twice:
        # two settled steps where the session had one. The writer numbers each channel's
        # messages, so two messages the bench wrote alike (a held clock, a still sensor)
        # still differ. One 64-bit hash per message, not a tuple or the bytes: a paper
        # protocol's 142,000 messages took 40 MB more as tuples, about 10 as ints.
        seen: set[int] = set()
        while True:
            parsed = _record_at(data, position, open_chunks=self.open_chunks)
            if parsed is None:
                resume = _next_intact(data, position + 1)
                # The session's metadata records lie before any chunk: resuming at the
                # next chunk would lose the intact ones after a damaged one (the rig
                # profile after a damaged start time).
                resume = min((offset for offset in summary.metadata_offsets()
                              if position < offset < (len(data) if resume is None else resume)
                              and _record_at(data, offset, open_chunks=False) is not None), default=resume)
                second = _second_log(data, position, len(data) if resume is None else resume)
                if second is not None:
                    # Read on, its chunks would be taken for this session's, under this
                    # session's metadata and with times from another clock.
                    raise UserError(f"{self.path} holds a second MCAP log from byte {second} (two files "
                                    "concatenated?): split it, or give one")
                if resume is None:
                    return  # cut off: nothing intact follows
                chunks = summary.chunks_between(position, resume, data)
                known_empty = chunks == 0 and summary.chunk_offsets is not None
                self.skipped.append(SkippedStretch(
                    position, resume, chunks=chunks,
                    messages=0 if known_empty else _messages_indexed(data, position, resume),
                    last_before_ns=last_log_time, metadata=summary.metadata_between(position, resume, data)))
                position = resume
                continue
            opcode, records, end = parsed
            for record in records:
                if isinstance(record, Message):
                    self.messages_read += 1
                    key = hash((record.channel_id, record.sequence, record.log_time, record.publish_time, record.data))
                    if key in seen:
                        self.duplicates += 1
                        continue
                    seen.add(key)
                    if self.skipped and self.skipped[-1].first_after_ns is None:
                        self.skipped[-1] = dataclasses.replace(self.skipped[-1], first_after_ns=record.log_time)
                    last_log_time = record.log_time
                yield record
            if not summary_given:
                summary_given = True
                yield from summary.schemas_and_channels
            if opcode == Opcode.FOOTER:
                self.complete = data[end:] == MAGIC
                return
            if end >= len(data):
                return
            position = end


def _record_at(data: bytes, position: int, *, open_chunks: bool) -> tuple[int, list[McapRecord], int] | None:
    """The record at ``position`` (its opcode, the records it yields, where the next
    begins), or None if it is cut off or damaged."""
    if len(data) - position < _RECORD_HEAD.size:
        return None
    opcode, length = _RECORD_HEAD.unpack_from(data, position)
    end = position + _RECORD_HEAD.size + length
    if opcode not in _OPCODES or end > len(data) or not _plausible_head(data, end):
        return None
    if opcode not in _PARSERS and opcode != Opcode.MESSAGE:
        return opcode, [], end
    # Parsed even when not wanted, to check the length (and a chunk's CRC).
    records = _parse(opcode, data, position, end)
    if records is None:
        return None
    wanted = opcode in _WANTED and (open_chunks or opcode != Opcode.CHUNK)
    return opcode, records if wanted else [], end


def _plausible_head(data: bytes, position: int) -> bool:
    """Whether a record can begin at ``position``: the file ends there or is cut within
    the head, or a known opcode with a sane length is there (the length may run past a
    cut). This catches a damaged length that sent the reader into the middle of data."""
    if len(data) - position < _RECORD_HEAD.size:
        return True
    opcode, length = _RECORD_HEAD.unpack_from(data, position)
    return opcode in _OPCODES and length < _MAX_RECORD_LENGTH


def _second_log(data: bytes, start: int, end: int) -> int | None:
    """Where a second log (its magic, then a header record that parses) begins between
    ``start`` and ``end``, if one does: the first's closing magic, or the record a cut
    left unfinished, cannot be read as a record, so a second log shows up as damage."""
    offset = data.find(MAGIC + bytes([Opcode.HEADER]), start, end)
    while offset >= 0:
        parsed = _record_at(data, offset + len(MAGIC), open_chunks=False)
        if parsed is not None and parsed[0] == Opcode.HEADER:
            return offset
        offset = data.find(MAGIC + bytes([Opcode.HEADER]), offset + 1, end)
    return None


def _next_intact(data: bytes, start: int) -> int | None:
    """The offset of the first intact chunk (or data end) at or after ``start``."""
    candidates = [data.find(bytes([opcode]), start) for opcode in _RESYNC]
    while True:
        found = [offset for offset in candidates if offset >= 0]
        if not found:
            return None
        offset = min(found)
        if _record_at(data, offset, open_chunks=True) is not None:
            return offset
        candidates = [data.find(bytes([opcode]), offset + 1) if candidate == offset else candidate
                      for opcode, candidate in zip(_RESYNC, candidates)]


def _messages_indexed(data: bytes, start: int, end: int) -> int | None:
    """Messages of the damaged chunk at ``start``, from the message indexes that follow
    it (None if its length or its indexes are damaged too)."""
    if len(data) - start < _RECORD_HEAD.size:
        return None
    opcode, length = _RECORD_HEAD.unpack_from(data, start)
    position = start + _RECORD_HEAD.size + length
    if opcode != Opcode.CHUNK or position > end:
        return None
    count = 0
    while position < end:
        parsed = _record_at(data, position, open_chunks=False)
        if parsed is None or parsed[0] != Opcode.MESSAGE_INDEX:
            return None
        (index,) = _parse(Opcode.MESSAGE_INDEX, data, position, parsed[2]) or [None]
        if not isinstance(index, MessageIndex):
            return None
        count += len(index.records)
        position = parsed[2]
    return count


def _parse(opcode: int, data: bytes, position: int, end: int) -> list[McapRecord] | None:
    """The records in one record's body, or None if it does not parse."""
    body = data[position + _RECORD_HEAD.size:end]
    try:
        stream = ReadDataStream(BytesIO(body))
        record = Message.read(stream, len(body)) if opcode == Opcode.MESSAGE else _PARSERS[opcode](stream)
        if stream.count != len(body):
            return None  # a damaged length: the record's own fields say it is longer or shorter
        if isinstance(record, Chunk):
            return breakup_chunk(record, validate_crc=True)
        return [record]
    # The bytes may be damaged in any way, and the parsers and decompressors answer with a
    # zoo of types (struct.error, EndOfFile, UnicodeDecodeError, CRC ValueError, zstd and
    # lz4 errors, MemoryError for a wild size): whichever it is, this record is lost.
    except Exception:
        return None


@dataclass(frozen=True)
class _Summary:
    """What a complete file's summary section says (empty for a cut file or a damaged
    summary)."""

    schemas_and_channels: tuple[McapRecord, ...] = ()
    chunk_offsets: tuple[int, ...] | None = None
    message_count: int | None = None
    metadata_index: tuple[MetadataIndex, ...] | None = None

    @classmethod
    def of(cls, data: bytes) -> _Summary:
        footer_at = len(data) - len(MAGIC) - _RECORD_HEAD.size - _FOOTER_LENGTH
        if footer_at < len(MAGIC) or not data.endswith(MAGIC):
            return cls()
        footer = _parse(Opcode.FOOTER, data, footer_at, len(data) - len(MAGIC))
        if not footer or not isinstance(footer[0], Footer) or not len(MAGIC) <= footer[0].summary_start < footer_at:
            return cls()
        kept: list[McapRecord] = []
        offsets: list[int] = []
        metadata: list[MetadataIndex] = []
        count = None
        position = footer[0].summary_start
        while position < footer_at:
            parsed = _record_at(data, position, open_chunks=False)
            if parsed is None:
                return cls()
            opcode, _, end = parsed
            records = _parse(opcode, data, position, end) if opcode in _PARSERS else []
            for record in records or ():
                if isinstance(record, (Schema, Channel)):
                    kept.append(record)
                elif isinstance(record, ChunkIndex):
                    offsets.append(record.chunk_start_offset)
                elif isinstance(record, Statistics):
                    count = record.message_count
                elif isinstance(record, MetadataIndex):
                    metadata.append(record)
            position = end
        return cls(tuple(kept), tuple(offsets), count, tuple(sorted(metadata, key=lambda index: index.offset)))

    def chunks_between(self, start: int, end: int, data: bytes) -> int:
        if self.chunk_offsets is not None:
            return sum(start <= offset < end for offset in self.chunk_offsets)
        return int(data[start] == Opcode.CHUNK)

    def metadata_offsets(self) -> list[int]:
        return [index.offset for index in self.metadata_index or ()]

    def metadata_between(self, start: int, end: int, data: bytes) -> tuple[str | None, ...]:
        if self.metadata_index is not None:
            return tuple(index.name for index in self.metadata_index if start <= index.offset < end)
        return (None,) if data[start] == Opcode.METADATA else ()
