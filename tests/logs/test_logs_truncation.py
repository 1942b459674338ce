"""Crash safety: a killed writer, a log cut at every byte, damage, garbage, recovery."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import msgspec
import pytest
from log_examples import EXAMPLES, METADATA, cut_inside_chunk, events_log, small_log
from mcap.reader import make_reader
from mcap.writer import Writer

from hydrojet_bench.errors import UserError
from hydrojet_bench.logs import read_log, read_metadata, recover_log
from hydrojet_bench.logs.format import RECOVERY_METADATA_NAME

# Writes ~200 messages/s of session time = its own wall time, and prints each t_s once
# the write has returned, until killed.
WRITER = """
import sys, time
from hydrojet_bench.logs import LogWriter
from hydrojet_bench.logs.topics import Event
with LogWriter(sys.argv[1], metadata={"bench": {"profile_name": "sim"}}, flush_interval_s=1.0) as log:
    start = time.monotonic()
    index = 0
    while True:
        t_s = time.monotonic() - start
        log.write(Event(t_s=t_s, level="info", source="test", message=str(index)))
        print(repr(t_s), flush=True)
        index += 1
        time.sleep(0.005)
"""
KILL_AFTER_S = 2.5


def test_sigkill_loses_about_one_flush_interval_at_most(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    child = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], stdout=subprocess.PIPE, text=True)
    written: list[float] = []
    try:
        assert child.stdout is not None
        for line in child.stdout:
            written.append(float(line))
            if written[-1] >= KILL_AFTER_S:
                break
    finally:
        child.send_signal(signal.SIGKILL)
        remaining, _ = child.communicate(timeout=30)
    written += [float(line) for line in remaining.split()]
    assert child.returncode == -signal.SIGKILL and written[-1] >= KILL_AFTER_S

    contents = read_log(path)
    assert contents.truncated and contents.metadata == {"bench": {"profile_name": "sim"}}
    kept = contents.messages
    assert [m.message for m in kept] == [str(i) for i in range(len(kept))]  # a prefix, in order
    assert kept, "nothing survived"
    # The writer flushes once 1 s has passed since the last flush, so what was written
    # after the last flush spans 1 s plus one message interval (0.5 s of slack for a
    # busy machine delaying the child between two writes).
    assert written[-1] - kept[-1].t_s < 1.5

    report = recover_log(path, tmp_path / "recovered.mcap")
    assert (report.messages, report.last_t_s, report.truncated) == (len(kept), pytest.approx(kept[-1].t_s), True)
    with (tmp_path / "recovered.mcap").open("rb") as handle:
        reader = make_reader(handle)
        assert reader.get_summary() is not None
        assert [json.loads(m.data) for _, _, m in reader.iter_messages()] == [msgspec.to_builtins(m) for m in kept]
    assert read_log(tmp_path / "recovered.mcap").messages == kept


def test_every_truncation_yields_a_prefix(tmp_path: Path) -> None:
    full_path = events_log(tmp_path / "full.mcap", chunks=3)
    full = read_log(full_path)
    cut = shutil.copy(full_path, tmp_path / "cut.mcap")
    size = cut.stat().st_size
    counts = []
    with cut.open("r+b") as handle:
        # Shorten one file in place, from the end: rewriting a file per offset is far slower.
        for offset in range(size - 1, -1, -1):
            os.ftruncate(handle.fileno(), offset)
            contents = read_log(cut)
            count = len(contents.messages)
            assert contents.truncated, offset
            assert contents.messages == full.messages[:count], offset
            assert contents.metadata in ({}, {"bench": METADATA["bench"]}, METADATA), offset
            assert read_metadata(cut) == contents.metadata, offset
            counts.append(count)
    assert counts == sorted(counts, reverse=True)  # fewer bytes never read more messages
    # Whole chunks only.
    assert set(counts) == {0, len(full.messages) // 3, 2 * len(full.messages) // 3, len(full.messages)}
    assert not full.truncated


def test_damage_in_the_middle_costs_that_chunk_only(tmp_path: Path) -> None:
    full_path = small_log(tmp_path / "full.mcap", chunks=3)
    full = read_log(full_path)
    third = len(full.messages) // 3
    with full_path.open("rb") as handle:
        second_chunk = make_reader(handle).get_summary().chunk_indexes[1]
    data = bytearray(full_path.read_bytes())
    # A byte of the second chunk's compressed data: its CRC no longer matches.
    data[second_chunk.chunk_start_offset + second_chunk.chunk_length - 20] ^= 0xFF
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    contents = read_log(damaged)
    assert not contents.truncated  # the file still ends properly
    assert contents.messages == full.messages[:third] + full.messages[2 * third:]
    damage = contents.damage
    assert damage is not None and (damage.chunks_lost, damage.messages_lost, damage.undecodable_messages) == (1, third, 0)
    assert damage.lost_spans_s == (pytest.approx((full.messages[third - 1].t_s, full.messages[2 * third].t_s)),)
    assert "1 damaged chunk(s) skipped" in damage.describe() and f"{third} messages" in damage.describe()
    assert read_log(full_path).damage is None

    report = recover_log(damaged, tmp_path / "recovered.mcap")
    assert report.messages == 2 * third and report.damage == damage
    recovered = read_log(tmp_path / "recovered.mcap")
    assert recovered.messages == contents.messages and recovered.damage is None


def test_a_damaged_length_field_still_finds_the_next_chunk(tmp_path: Path) -> None:
    full_path = small_log(tmp_path / "full.mcap", chunks=3)
    full = read_log(full_path)
    third = len(full.messages) // 3
    with full_path.open("rb") as handle:
        second_chunk = make_reader(handle).get_summary().chunk_indexes[1]
    for byte in range(1, 9):  # each byte of the chunk's record length
        data = bytearray(full_path.read_bytes())
        data[second_chunk.chunk_start_offset + byte] ^= 0x10
        damaged = tmp_path / "damaged.mcap"
        damaged.write_bytes(bytes(data))
        contents = read_log(damaged)
        assert contents.messages == full.messages[:third] + full.messages[2 * third:], byte
        # The summary at the end of a complete file still counts what was lost.
        assert contents.damage is not None and contents.damage.messages_lost == third, byte


def test_damage_in_a_cut_log_is_counted_from_the_message_index(tmp_path: Path) -> None:
    full_path = small_log(tmp_path / "full.mcap", chunks=4)
    full = read_log(full_path)
    quarter = len(full.messages) // 4
    cut = cut_inside_chunk(full_path, 3, tmp_path / "cut.mcap")
    with full_path.open("rb") as handle:
        first_chunk = make_reader(handle).get_summary().chunk_indexes[0]
    data = bytearray(cut.read_bytes())
    data[first_chunk.chunk_start_offset + first_chunk.chunk_length - 20] ^= 0xFF
    cut.write_bytes(bytes(data))
    contents = read_log(cut)
    assert contents.truncated
    assert contents.damage is not None and contents.damage.messages_lost == quarter
    # Chunk 0 held the first schemas and channels; the later chunks repeat none, so their
    # messages are lost with it (a complete log has them in its summary).
    assert len(contents.messages) <= 2 * quarter


@contextlib.contextmanager
def hand_made_events(path: Path):
    """An MCAP writer of hand-made /events messages: (writer, channel id, an event as JSON)."""
    with path.open("wb") as handle:
        writer = Writer(handle)
        writer.start()
        schema = writer.register_schema("hydrojet_bench.Event", "jsonschema", b"{}")
        yield writer, writer.register_channel("/events", "json", schema), json.loads(
            msgspec.json.encode(EXAMPLES["/events"]))
        writer.finish()


def test_one_unreadable_message_among_good_ones_is_skipped_and_counted(tmp_path: Path) -> None:
    path = tmp_path / "odd.mcap"
    with hand_made_events(path) as (writer, events, good):
        for index in range(5):
            message = {**good, "t_s": float(index)} if index != 2 else {"t_s": 2.0, "level": 3}
            writer.add_message(events, log_time=index * 10**9, publish_time=index * 10**9,
                               data=json.dumps(message).encode())
    contents = read_log(path)
    assert [m.t_s for m in contents.messages] == [0.0, 1.0, 3.0, 4.0]
    assert contents.damage is not None and contents.damage.undecodable_messages == 1
    assert contents.damage.describe() == "1 unreadable message(s) skipped"


def test_recovery_of_a_truncated_log(tmp_path: Path) -> None:
    full_path = small_log(tmp_path / "full.mcap", chunks=3)
    full = read_log(full_path)
    cut = cut_inside_chunk(full_path, 2, tmp_path / "cut.mcap")
    kept = read_log(cut)
    assert len(kept.messages) == 2 * len(full.messages) // 3

    report = recover_log(cut, tmp_path / "out.mcap")
    assert report.truncated and report.messages == len(kept.messages)
    assert report.first_t_s == 0.0 and report.last_t_s == pytest.approx(kept.messages[-1].t_s, abs=1e-9)
    with (tmp_path / "out.mcap").open("rb") as handle:
        reader = make_reader(handle)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == len(kept.messages)
        assert {m.name: m.metadata for m in reader.iter_metadata()}["bench"] == METADATA["bench"]
    recovered = read_log(tmp_path / "out.mcap")
    assert not recovered.truncated
    # The copy's metadata: the source's, and what the source lost (the cut).
    recovery = recovered.metadata.pop(RECOVERY_METADATA_NAME)
    assert recovered.messages == kept.messages and recovered.metadata == kept.metadata
    assert recovery == {"source": str(cut), "truncated": "true", "damage": ""}
    assert recovered.start_time_unix_s == kept.start_time_unix_s

    # A complete log is copied whole.
    report = recover_log(full_path, tmp_path / "copy.mcap")
    assert not report.truncated and report.messages == len(full.messages)
    assert read_log(tmp_path / "copy.mcap").messages == full.messages
    with pytest.raises(UserError, match="must not overwrite its source"):
        recover_log(full_path, full_path)


def test_what_is_not_a_log_is_a_user_error(tmp_path: Path) -> None:
    for name, content in (("table.mcap", b"t,q1,q2\n0,0,0\n"), ("image.mcap", b"\x89PNG\r\n\x1a\n" + bytes(64)),
                          ("noise.mcap", bytes(range(256)))):
        path = tmp_path / name
        path.write_bytes(content)
        for read in (read_log, read_metadata, lambda p: recover_log(p, tmp_path / "out.mcap")):
            with pytest.raises(UserError, match=f"{name}: not an MCAP file"):
                read(path)
    assert not (tmp_path / "out.mcap").exists() and not (tmp_path / "out.mcap.partial").exists()
    with pytest.raises(UserError, match="absent.mcap: cannot read"):
        read_log(tmp_path / "absent.mcap")
    # A writer killed before its first byte reached the disk left a log with nothing in it.
    (tmp_path / "empty.mcap").write_bytes(b"")
    empty = read_log(tmp_path / "empty.mcap")
    assert empty.truncated and empty.messages == [] and empty.metadata == {}


def test_two_logs_concatenated_are_refused_with_where_the_second_begins(tmp_path: Path) -> None:
    first = small_log(tmp_path / "first.mcap", chunks=2)
    second = events_log(tmp_path / "second.mcap", chunks=2)
    cut = cut_inside_chunk(first, 1, tmp_path / "cut.mcap")
    for head in (first, cut):  # a finished log, and one a crash left unfinished
        joined = tmp_path / "joined.mcap"
        joined.write_bytes(head.read_bytes() + second.read_bytes())
        where = f"joined.mcap holds a second MCAP log from byte {head.stat().st_size} \\(two files concatenated\\?\\)"
        for read in (read_log, read_metadata, lambda p: recover_log(p, tmp_path / "out.mcap")):
            with pytest.raises(UserError, match=where):
                read(joined)
        assert not (tmp_path / "out.mcap").exists()


def test_a_record_written_twice_is_read_once_and_counted(tmp_path: Path) -> None:
    path = tmp_path / "doubled.mcap"
    with hand_made_events(path) as (writer, events, event):
        for index, copies in enumerate((1, 2, 1, 3)):
            data = json.dumps({**event, "t_s": float(index)}).encode()
            for _ in range(copies):
                writer.add_message(events, log_time=index * 10**9, publish_time=index * 10**9, data=data,
                                   sequence=index)
        # The same message under its own sequence number: the bench wrote it twice (a
        # held clock), so it is kept.
        writer.add_message(events, log_time=3 * 10**9, publish_time=3 * 10**9, data=data, sequence=4)
    contents = read_log(path)
    assert [m.t_s for m in contents.messages] == [0.0, 1.0, 2.0, 3.0, 3.0]
    damage = contents.damage
    assert damage is not None and (damage.duplicated_records, damage.skipped_stretches, damage.messages_lost) == (3, 0, 0)
    assert damage.describe().startswith("3 duplicated record(s) skipped")
    report = recover_log(path, tmp_path / "recovered.mcap")
    assert report.messages == 5 and report.damage == damage
    assert read_log(tmp_path / "recovered.mcap").messages == contents.messages
