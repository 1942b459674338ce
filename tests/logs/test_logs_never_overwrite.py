"""Nothing recorded is overwritten: session logs, recovered logs and recordings are new
files (or replaced with --overwrite only), names are unique under concurrency, and an
input that is not a regular file is refused instead of read forever."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import pytest
from log_examples import events_log

from hydrojet_bench.cli import main
from hydrojet_bench.errors import UserError
from hydrojet_bench.files import create_new, create_numbered, publish
from hydrojet_bench.logs import read_log


def one_line(capsys) -> str:
    error = capsys.readouterr().err
    assert "Traceback" not in error
    return " ".join(error.split())  # the CLI's console wraps long lines


def test_concurrent_sessions_in_the_same_second_get_different_logs(tmp_path: Path) -> None:
    wanted = tmp_path / "sessions" / "sim-20261123-200000.mcap"
    start = threading.Barrier(12)
    names: list[Path] = []

    def reserve() -> None:
        start.wait()
        names.append(create_numbered(wanted, "session log"))

    threads = [threading.Thread(target=reserve) for _ in range(12)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(set(names)) == 12 and wanted in names
    assert {path.name for path in names} == {wanted.name} | {f"sim-20261123-200000-{n}.mcap" for n in range(1, 12)}


def test_exclusive_create_lets_one_of_two_writers_win(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    start = threading.Barrier(2)
    outcomes: list[str] = []

    def open_it() -> None:
        start.wait()
        try:
            create_new(path, "session log").close()
            outcomes.append("created")
        except UserError as error:
            outcomes.append(str(error))

    threads = [threading.Thread(target=open_it) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert sorted(outcomes, key=len) == [
        "created", f"{path}: a session log already exists there; choose another file or pass --overwrite"]


def test_publish_never_replaces_a_file_that_appeared_meanwhile(tmp_path: Path) -> None:
    path = tmp_path / "out.csv"

    def write(partial: Path) -> int:
        partial.write_text("mine\n")
        path.write_text("someone else's\n")  # appears while this one is written
        return 1

    with pytest.raises(UserError, match="already exists"):
        publish(path, "recording", write)
    assert path.read_text() == "someone else's\n" and os.listdir(tmp_path) == ["out.csv"]
    assert publish(path, "recording", lambda partial: partial.write_text("new\n"), overwrite=True) == 4
    assert path.read_text() == "new\n" and os.listdir(tmp_path) == ["out.csv"]


def test_run_refuses_an_existing_log(tmp_path: Path, capsys) -> None:
    log = events_log(tmp_path / "session.mcap")
    before = log.read_bytes()
    assert main(["run", "--plan", "hold:1", "--no-live", "--log", str(log)]) == 2
    assert f"{log}: a session log already exists there; choose another file or pass --overwrite" in one_line(capsys)
    assert log.read_bytes() == before
    assert main(["run", "--plan", "hold:1", "--no-live", "--log", str(tmp_path)]) == 2
    assert "is a directory" in one_line(capsys)


def test_recover_refuses_an_existing_output(tmp_path: Path, capsys) -> None:
    log = events_log(tmp_path / "session.mcap")
    taken = tmp_path / "taken.mcap"
    taken.write_bytes(b"precious")
    assert main(["recover", str(log), "-o", str(taken)]) == 2
    assert f"{taken}: a file that is no MCAP log already exists there" in one_line(capsys)
    assert taken.read_bytes() == b"precious"
    # What is there is said: a session's own log is no stale copy to replace.
    other = events_log(tmp_path / "other.mcap")
    assert main(["recover", str(log), "-o", str(other)]) == 2
    assert one_line(capsys) == (f"error: {other}: a session log already exists there (a session's own record, not "
                                "a recovered copy: --overwrite would lose it); choose another file or pass "
                                "--overwrite")
    copy = tmp_path / "copy.mcap"
    assert main(["recover", str(log), "-o", str(copy)]) == 0
    capsys.readouterr()
    assert main(["recover", str(log), "-o", str(copy)]) == 2
    assert f"{copy}: a recovered log already exists there" in one_line(capsys)
    assert main(["recover", str(log), "-o", str(taken), "--overwrite"]) == 0
    assert len(read_log(taken).messages) == 12
    assert main(["recover", str(log), "-o", str(tmp_path / "missing" / "out.mcap")]) == 2
    assert "its folder" in (message := one_line(capsys)) and "does not exist" in message


def test_simulate_refuses_an_existing_file_or_a_directory_before_simulating(tmp_path: Path, capsys) -> None:
    taken = tmp_path / "data.csv"
    taken.write_text("precious\n")
    assert main(["simulate", "-o", str(taken)]) == 2
    assert f"{taken}: a recording already exists there; choose another file or pass --overwrite" in one_line(capsys)
    assert taken.read_text() == "precious\n"
    assert main(["simulate", "-o", str(tmp_path)]) == 2
    assert f"{tmp_path}: is a directory; give the recording a file name" in one_line(capsys)
    # A CSV under a log's name would be read as a damaged log, and could replace one.
    log = tmp_path / "session.mcap"
    log.write_bytes(b"\x89MCAP0\r\n")
    assert main(["simulate", "-o", str(log), "--overwrite"]) == 2
    assert f"{log}: simulate writes a CSV table; name it with .csv" in one_line(capsys)
    assert log.read_bytes() == b"\x89MCAP0\r\n"


def test_simulate_creates_a_missing_folder(tmp_path: Path, monkeypatch) -> None:
    from hydrojet_bench.commands import simulate

    output = tmp_path / "new" / "folder" / "data.csv"
    # The twin itself is tested elsewhere; here only where its rows go.
    monkeypatch.setattr(simulate, "write_csv", lambda dataset, path: Path(path).write_text("rows\n") and 7)
    monkeypatch.setattr(simulate.DigitalTwin, "run_plan", lambda self, plan: _Recording())
    assert main(["simulate", "-o", str(output)]) == 0
    assert output.read_text() == "rows\n" and os.listdir(output.parent) == ["data.csv"]


class _Recording:
    def to_dataset(self, profile, source):
        return None


@pytest.mark.parametrize(("name", "command"), [("session.mcap", ["recover"]), ("session.mcap", ["replay"]),
                                               ("session.mcap", ["calibrate", "-o", "p.toml"]),
                                               ("data.csv", ["calibrate", "-o", "p.toml"])])
def test_a_fifo_as_input_is_refused_not_waited_on(tmp_path: Path, capsys, name: str, command: list[str]) -> None:
    fifo = tmp_path / name
    os.mkfifo(fifo)
    assert main([command[0], str(fifo), *command[1:]]) == 2
    assert f"{fifo}: cannot read: it is a FIFO; expected a regular file" in one_line(capsys)


def test_an_output_never_replaces_an_input_or_other_data(tmp_path: Path, capsys) -> None:
    """`calibrate run.csv -o run.csv` used to replace the table with a parameter file,
    and `--json params.toml` the parameters with JSON: refused before any work."""
    table = tmp_path / "run.csv"
    assert main(["simulate", "-o", str(table), "--seed", "1"]) == 0
    params, document = tmp_path / "p.toml", tmp_path / "p.json"
    capsys.readouterr()
    recorded = table.read_bytes()
    for arguments, path, what in (
            (["calibrate", str(table), "-o", str(table)], table, "parameter file"),
            (["calibrate", str(table), "-o", str(params), "--json", str(table)], table, "JSON document")):
        assert main(arguments) == 2
        assert one_line(capsys) == (f"error: {path}: exists and is not a {what}; refusing to replace it (is it an "
                                    "input?): "
                                    f"give the {what} another path")
        assert table.read_bytes() == recorded and not params.exists()
    # Earlier outputs of the same kind are replaced, as calibrating again means to.
    for _ in range(2):
        assert main(["calibrate", str(table), "-o", str(params), "--json", str(document)]) == 0
    assert main(["calibrate", str(table), "-o", str(tmp_path)]) == 2
    assert one_line(capsys) == f"error: {tmp_path}: is a directory; give the parameter file a file name"
    written = params.read_bytes()
    assert main(["compare", str(table), "--params", str(params), "--json", str(params)]) == 2
    assert "p.toml: exists and is not a JSON document" in one_line(capsys)
    assert params.read_bytes() == written
    # Both outputs on one new file: the fit ran and wrote the parameters, then the JSON
    # was refused over them. Now refused before the fit.
    both = tmp_path / "both.toml"
    assert main(["calibrate", str(table), "-o", str(both), "--json", str(both)]) == 2
    assert one_line(capsys) == f"error: {both}: named by both -o and --json; give each its own file"
    assert not both.exists()
