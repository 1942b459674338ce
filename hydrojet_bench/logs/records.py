"""Linear reading of an MCAP file that keeps every whole record before any damage.

`mcap.reader.make_reader` starts from the footer, which a killed writer never wrote; the
library's StreamReader reads forward but ends a damaged file with whatever exception the
cut happens to cause. `RecordScanner` reads forward too, checks each record's length
against the bytes left before parsing it, opens chunks with their CRC checked, and ends
quietly at the first record that is cut off or does not parse. Afterwards `complete`
says whether the file ended properly (footer and closing magic).
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator
from io import BytesIO
from pathlib import Path

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import (Attachment, Channel, Chunk, DataEnd, Footer, Header, McapRecord, Message, Metadata,
                          Schema)
from mcap.stream_reader import breakup_chunk

from ..errors import UserError

MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEAD = struct.Struct("<BQ")

# Records the bench reads (messages too, parsed apart: they need their length); the rest
# (indexes, statistics, summary offsets) are skipped: they only repeat the data section.
_PARSERS = {
    Opcode.HEADER: Header.read, Opcode.FOOTER: Footer.read, Opcode.SCHEMA: Schema.read,
    Opcode.CHANNEL: Channel.read, Opcode.METADATA: Metadata.read, Opcode.CHUNK: Chunk.read,
    Opcode.ATTACHMENT: Attachment.read, Opcode.DATA_END: DataEnd.read,
}
_WANTED = frozenset(_PARSERS) | {Opcode.MESSAGE}


class RecordScanner:
    """Iterate over the whole records of an MCAP file in file order (a chunk is replaced
    by the schemas, channels and messages inside it).

    path: the file. A file that does not start with the MCAP magic raises `UserError`
        naming it; an empty file, or one holding only the start of the magic, is a log
        cut off before its first record and yields nothing.
    open_chunks: False skips chunks unread (for metadata only).
    """

    def __init__(self, path: str | Path, *, open_chunks: bool = True) -> None:
        self.path = Path(path)
        self.open_chunks = open_chunks
        self.complete = False

    def __iter__(self) -> Iterator[McapRecord]:
        self.complete = False
        try:
            handle = self.path.open("rb")
        except OSError as error:
            raise UserError(f"{self.path}: cannot read: {error.strerror or error}") from None
        with handle:
            size = os.fstat(handle.fileno()).st_size
            start = handle.read(len(MAGIC))
            if start != MAGIC:
                if MAGIC.startswith(start):
                    return
                raise UserError(f"{self.path}: not an MCAP file (it does not start with the MCAP magic bytes); "
                                "expected a session log written by the bench")
            position = len(MAGIC)
            while True:
                head = handle.read(_RECORD_HEAD.size)
                if len(head) < _RECORD_HEAD.size:
                    return
                opcode, length = _RECORD_HEAD.unpack(head)
                position += _RECORD_HEAD.size
                if length > size - position:
                    return  # cut off, or a damaged length field
                position += length
                if opcode not in _WANTED or (opcode == Opcode.CHUNK and not self.open_chunks):
                    handle.seek(length, os.SEEK_CUR)
                    continue
                records = _parse(opcode, handle.read(length))
                if records is None:
                    return
                yield from records
                if opcode == Opcode.FOOTER:
                    self.complete = handle.read(len(MAGIC) + 1) == MAGIC
                    return


def _parse(opcode: int, body: bytes) -> list[McapRecord] | None:
    """The records in one record body, or None if it does not parse."""
    try:
        stream = ReadDataStream(BytesIO(body))
        record = Message.read(stream, len(body)) if opcode == Opcode.MESSAGE else _PARSERS[opcode](stream)
        if isinstance(record, Chunk):
            return breakup_chunk(record, validate_crc=True)
        return [record]
    # The bytes may be damaged in any way, and the parsers and decompressors answer with a
    # zoo of types (struct.error, EndOfFile, UnicodeDecodeError, CRC ValueError, zstd and
    # lz4 errors, MemoryError for a wild size): whichever it is, the readable part ends here.
    except Exception:
        return None
