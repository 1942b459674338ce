"""`hydrojet-bench recover`: what it writes and what it says."""

from __future__ import annotations

from pathlib import Path

from log_examples import cut_inside_chunk, events_log
from mcap.reader import make_reader

from hydrojet_bench.cli import main
from hydrojet_bench.logs import read_log
from hydrojet_bench.logs.condition import log_condition


def test_recover_writes_beside_the_log_and_reports_what_it_kept(tmp_path: Path, capsys) -> None:
    full = events_log(tmp_path / "full.mcap", chunks=3)
    session = cut_inside_chunk(full, 1, tmp_path / "session.mcap")
    kept = read_log(session).messages
    assert len(kept) == 4

    assert main(["recover", str(session)]) == 0
    out = capsys.readouterr().out
    assert f"{session} was truncated" in out
    assert f"wrote {tmp_path / 'session.recovered.mcap'}: 4 messages, t = 0.000 s to 0.300 s (0.300 s)" in out
    assert read_log(tmp_path / "session.recovered.mcap").messages == kept

    assert main(["recover", str(full), "-o", str(tmp_path / "copy.mcap")]) == 0
    out = capsys.readouterr().out
    assert f"{full} was complete" in out and "12 messages, t = 0.000 s to 2.300 s" in out


def test_recover_refuses_what_is_not_a_log(tmp_path: Path, capsys) -> None:
    notes = tmp_path / "notes.mcap"
    notes.write_text("not a log\n")
    assert main(["recover", str(notes)]) == 2
    error = " ".join(capsys.readouterr().err.split())  # the CLI's console wraps long lines
    assert "notes.mcap: not an MCAP file" in error
    assert not (tmp_path / "notes.recovered.mcap").exists()
    empty = tmp_path / "empty.mcap"
    empty.touch()
    assert main(["recover", str(empty)]) == 2
    assert "empty.mcap: empty file (0 bytes): nothing to recover" in " ".join(capsys.readouterr().err.split())
    assert not (tmp_path / "empty.recovered.mcap").exists()


def test_recover_keeps_the_chunks_after_a_damaged_one_and_says_what_was_lost(tmp_path: Path, capsys) -> None:
    full = events_log(tmp_path / "full.mcap", chunks=3)
    with full.open("rb") as handle:
        middle = make_reader(handle).get_summary().chunk_indexes[1]
    data = bytearray(full.read_bytes())
    data[middle.chunk_start_offset + middle.chunk_length - 5] ^= 0x01
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    assert main(["recover", str(damaged)]) == 0
    captured = capsys.readouterr()
    assert f"{damaged} ended properly" in captured.out
    assert f"wrote {tmp_path / 'damaged.recovered.mcap'}: 8 messages, t = 0.000 s to 2.300 s" in captured.out
    assert captured.err.startswith(f"warning: {damaged} is damaged: 1 damaged chunk(s) skipped (")
    assert "4 messages, session time 0.300 s to 2.000 s); kept every intact chunk" in captured.err
    kept = [m.message for m in read_log(tmp_path / "damaged.recovered.mcap").messages]
    assert kept == ["0.0", "0.1", "0.2", "0.3", "2.0", "2.1", "2.2", "2.3"]
    # The copy is whole, but what its source lost stays said by every analysis of it.
    condition = log_condition(tmp_path / "damaged.recovered.mcap")
    assert not condition.whole and condition.damage is None
    assert condition.notice().startswith(f"{tmp_path / 'damaged.recovered.mcap'}: it was recovered from a log that "
                                         f"was damaged ({damaged}: 1 damaged chunk(s) skipped (")
    # And a copy of the copy still says it.
    assert main(["recover", str(tmp_path / "damaged.recovered.mcap"), "-o", str(tmp_path / "again.mcap")]) == 0
    assert log_condition(tmp_path / "again.mcap").recovered_loss == condition.recovered_loss
