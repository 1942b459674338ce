"""LogWriter and read_log on complete logs: every topic round trips, stored schemas,
what the writer refuses, malformed messages, metadata, flushing, and what other MCAP
readers see."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import msgspec
import numpy as np
import pytest
from json_schema_check import schema_problem
from log_examples import EXAMPLES, METADATA, QUATERNION, START_TIME_UNIX_S, WRITE_ORDER, small_log, write_all_topics
from mcap.reader import make_reader
from mcap.writer import Writer

from hydrojet_bench.cli import main
from hydrojet_bench.errors import UserError
from hydrojet_bench.logs import TOPICS, LogError, LogWriter, read_log, read_metadata
from hydrojet_bench.logs.schemas import schema_name, topic_schema
from hydrojet_bench.logs.topics import EmFrame, Event, FrameTransform, Sample, SceneUpdate


def test_every_topic_round_trips(tmp_path: Path) -> None:
    contents = read_log(small_log(tmp_path / "run.mcap", chunks=2))
    assert not contents.truncated
    assert contents.metadata == METADATA
    assert contents.start_time_unix_s == pytest.approx(START_TIME_UNIX_S, abs=1e-9)
    assert [m.topic for m in contents.messages] == 2 * WRITE_ORDER
    times = [m.t_s for m in contents.messages]
    assert times == sorted(times) and times[0] == 0.0
    by_topic = {m.topic: m for m in contents.messages[:len(TOPICS)]}
    for topic, record in EXAMPLES.items():
        if topic != "/em/frame":
            assert by_topic[topic] == msgspec.structs.replace(record, t_s=by_topic[topic].t_s), topic
    # numpy scalars came back as plain numbers; NaN as None where the field may be null.
    assert by_topic["/bench/sample"].base_orientation == tuple(QUATERNION.tolist())
    assert by_topic["/imu/raw"].accel_m_s2 == tuple(float(np.float32(v)) for v in (0.1, -9.8, 0.2))
    frame = by_topic["/em/frame"]
    assert type(frame.frame_number) is int and frame.frame_number == 1234
    assert frame.tools[1].rms_error_mm is None and frame.tools[0] == EXAMPLES["/em/frame"].tools[0]
    transform = by_topic["/tf"]
    w, x, y, z = QUATERNION
    assert msgspec.to_builtins(transform.rotation) == {"x": x, "y": y, "z": z, "w": w}
    assert msgspec.to_builtins(transform.translation) == {"x": 0.01, "y": 0.0, "z": 0.068}
    assert (transform.parent_frame_id, transform.child_frame_id) == ("base", "tip")
    line = by_topic["/scene/backbone"].entities[0].lines[0]
    assert line.type == 0 and len(line.points) == 5 and msgspec.to_builtins(line.points[-1]) == {
        "x": 0.01, "y": 0.0, "z": 0.068}


def test_foxglove_timestamps_are_log_times(tmp_path: Path) -> None:
    path = small_log(tmp_path / "run.mcap", chunks=1)
    with path.open("rb") as handle:
        for _, channel, message in make_reader(handle).iter_messages(topics=["/tf", "/scene/backbone"]):
            data = json.loads(message.data)
            stamp = data["timestamp"] if channel.topic == "/tf" else data["entities"][0]["timestamp"]
            assert stamp["sec"] * 10**9 + stamp["nsec"] == message.log_time == message.publish_time
            # log time = start + t_s, to the nanosecond
            assert message.log_time == 1_700_000_000_250_000_000 + round(data["t_s"] * 1e9)


def test_stored_messages_conform_to_their_schemas(tmp_path: Path) -> None:
    path = small_log(tmp_path / "run.mcap", chunks=1)
    with path.open("rb") as handle:
        reader = make_reader(handle)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == len(TOPICS)
        for schema, channel, message in reader.iter_messages():
            assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
            assert schema.name == schema_name(TOPICS[channel.topic])
            stored_schema = json.loads(schema.data)
            assert stored_schema == topic_schema(TOPICS[channel.topic])
            assert schema_problem(stored_schema, json.loads(message.data), channel.topic) is None
    assert {s.name for s in summary.schemas.values()} >= {"foxglove.FrameTransform", "foxglove.SceneUpdate"}


@pytest.mark.parametrize(("topic", "change", "problem"), [
    ("/bench/sample", {"source": "optical"}, "/bench/sample.source: Invalid enum value 'optical'"),
    ("/bench/sample", {"sweep": -2}, "/bench/sample.sweep: Expected `int` >= -1"),
    ("/bench/sample", {"tip_orientation": (1.0, 0.0, 0.0)}, "/bench/sample.tip_orientation: Expected `array` of length"),
    ("/bench/sample", {"jet_forces_n": (0.1, float("nan"), 0.0)}, "jet_forces_n[1]: Expected `float`, got `null`"),
    ("/bench/sample", {"step": 1.5}, "/bench/sample.step: Expected `int`, got `float`"),
    ("/em/frame", {"tools": ({"name": "tip"},)}, "/em/frame.tools[0]: Object missing required field `handle`"),
    ("/valves/reply", {"ok": "yes"}, "/valves/reply.ok: Expected `bool`, got `str`"),
    ("/bench/parameters", {"parameters": {"E0": "soft"}}, "/bench/parameters.parameters[...]: Expected `float`"),
    ("/events", {"level": "debug"}, "/events.level: Invalid enum value 'debug'"),
    ("/events", {"message": 1j}, "/events: cannot write complex 1j in a log message"),
])
def test_writer_rejects_records_its_reader_would_refuse(tmp_path: Path, topic, change, problem) -> None:
    # Struct fields are not checked on construction; the writer checks what it encoded.
    with LogWriter(tmp_path / "run.mcap") as log:
        with pytest.raises(ValueError) as error:
            log.write(msgspec.structs.replace(EXAMPLES[topic], **change))
        assert problem in str(error.value)
    assert read_log(tmp_path / "run.mcap").messages == []


def test_writer_rejects_what_is_not_a_record_and_bad_times(tmp_path: Path) -> None:
    with LogWriter(tmp_path / "run.mcap") as log:
        with pytest.raises(ValueError, match="not a log record: dict; records: Sample, "):
            log.write({"t_s": 0.0, "level": "info", "source": "test", "message": "x"})
        with pytest.raises(ValueError, match="t_s must be a finite number"):
            log.write(msgspec.structs.replace(EXAMPLES["/events"], t_s=float("nan")))
        log.write(msgspec.structs.replace(EXAMPLES["/events"], t_s=1.0))  # refusals leave the log writable
        with pytest.raises(ValueError, match="not finite"):
            log.write_backbone(1.0, [[0.0, 0.0, float("nan")]])
        with pytest.raises(ValueError, match=r"expected shape \(4,\)"):
            log.write_transform(1.0, "base", "tip", rotation=[1.0, 0.0, 0.0], translation_m=[0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="unknown log topic"):
        read_log(tmp_path / "run.mcap", topics=["/nope"])
    assert [m.topic for m in read_log(tmp_path / "run.mcap", topics=["/events"]).messages] == ["/events"]


def test_metadata_is_checked_and_written_before_any_message(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="reserved"):
        LogWriter(tmp_path / "a.mcap", metadata={"hydrojet_bench.log": {}})
    with pytest.raises(ValueError, match="metadata bench.steps"):
        LogWriter(tmp_path / "b.mcap", metadata={"bench": {"steps": 229}})
    with pytest.raises(UserError, match="cannot write the session log"):
        LogWriter(tmp_path / "missing" / "c.mcap")
    log = LogWriter(tmp_path / "run.mcap", metadata=METADATA)
    try:
        early = shutil.copy(tmp_path / "run.mcap", tmp_path / "early.mcap")  # as if killed right after opening
    finally:
        log.close()
    assert read_metadata(early) == METADATA
    contents = read_log(early)
    assert contents.truncated and contents.messages == [] and contents.metadata == METADATA


def test_flush_hands_everything_written_to_the_file(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    with LogWriter(path, flush_interval_s=1e6) as log:  # no automatic flush during this test
        write_all_topics(log, 0.0)
        unflushed = read_log(shutil.copy(path, tmp_path / "before.mcap"))
        log.flush()
        flushed = read_log(shutil.copy(path, tmp_path / "after.mcap"))
    assert unflushed.messages == [] and unflushed.truncated
    assert len(flushed.messages) == len(TOPICS) and flushed.truncated
    with LogWriter(path, flush_interval_s=1e-9, overwrite=True) as log:  # every write is past the interval
        write_all_topics(log, 0.0)
        assert len(read_log(shutil.copy(path, tmp_path / "auto.mcap")).messages) == len(TOPICS)
    with pytest.raises(ValueError, match="closed"):
        log.write(EXAMPLES["/events"])
    log.close()  # closing twice is harmless


def _same_log(path: Path, background: bool) -> bytes:
    with LogWriter(path, metadata=METADATA, start_time_unix_s=START_TIME_UNIX_S, flush_interval_s=1e6,
                   reorder_window_s=0.5, background=background) as log:
        t_s = 0.0
        for _ in range(3):
            t_s = write_all_topics(log, t_s)
            log.write(msgspec.structs.replace(EXAMPLES["/events"], t_s=t_s - 0.2))  # late: reordered
            log.flush()
        write_all_topics(log, t_s)  # left for close to write
    return path.read_bytes()


def test_a_log_written_on_the_writer_thread_is_the_same_file(tmp_path: Path) -> None:
    assert _same_log(tmp_path / "thread.mcap", True) == _same_log(tmp_path / "caller.mcap", False)


def test_flush_waits_for_the_writer_thread(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    with LogWriter(path, flush_interval_s=1e6, background=True) as log:
        write_all_topics(log, 0.0)
        log.flush()
        assert len(read_log(shutil.copy(path, tmp_path / "after.mcap")).messages) == len(TOPICS)


def test_an_error_on_the_writer_thread_is_raised_to_the_caller(tmp_path: Path, monkeypatch) -> None:
    from hydrojet_bench.logs import writer

    def full_disk(*_: object) -> None:
        raise OSError(28, "No space left on device")

    path = tmp_path / "run.mcap"
    log = LogWriter(path, flush_interval_s=1e6, background=True)
    monkeypatch.setattr(writer._Chunks, "add", full_disk)
    log.write(EXAMPLES["/events"])
    with pytest.raises(OSError, match="No space left"):
        log.flush()
    with pytest.raises(OSError, match="No space left"):  # nothing is queued for a dead thread
        log.write(EXAMPLES["/events"])
    with pytest.raises(OSError, match="No space left"):  # as a full disk fails the footer
        log.close()
    assert log._stream.closed
    log.close()  # closing twice is harmless


def test_an_existing_log_is_never_overwritten_unless_asked(tmp_path: Path) -> None:
    path = small_log(tmp_path / "run.mcap", chunks=2)
    before = path.read_bytes()
    with pytest.raises(UserError, match=r"run.mcap: a session log already exists there; choose another file or "
                                        r"pass --overwrite"):
        LogWriter(path)
    assert path.read_bytes() == before
    with pytest.raises(UserError, match="is a directory"):
        LogWriter(tmp_path)
    LogWriter(path, overwrite=True).close()
    assert read_log(path).messages == []


def test_log_is_finished_when_the_session_fails(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    with pytest.raises(RuntimeError):
        with LogWriter(path) as log:
            log.write(msgspec.structs.replace(EXAMPLES["/events"], t_s=0.5))
            raise RuntimeError("valve controller lost")
    contents = read_log(path)
    assert not contents.truncated and len(contents.messages) == 1


# --- messages a reader refuses -------------------------------------------------------

def test_a_malformed_message_is_a_log_error_naming_file_topic_and_field(tmp_path: Path, capsys) -> None:
    """As another program (or a bug) could write it: a whole message, in a valid chunk,
    that its topic's record type cannot read."""
    path = tmp_path / "odd.mcap"
    with path.open("wb") as handle:
        writer = Writer(handle)
        writer.start()
        schema = writer.register_schema("hydrojet_bench.Sample", "jsonschema", b"{}")
        samples = writer.register_channel("/bench/sample", "json", schema)
        other = writer.register_channel("/their/topic", "json", schema)
        writer.add_message(other, log_time=0, publish_time=0, data=b'"not ours, not read"')
        writer.add_message(samples, log_time=500_000_000, publish_time=500_000_000,
                           data=json.dumps({"t_s": 0.5, "source": "em", "jet_forces_n": [0.0, 0.0]}).encode())
        writer.finish()
    with pytest.raises(LogError, match=r"odd.mcap, message at t_s=0.5 s: /bench/sample.jet_forces_n: Expected "
                                       r"`array` of length >= 3"):
        read_log(path)
    assert read_log(path, topics=["/events"]).messages == []  # other topics, and unknown ones, are not read
    assert main(["sensors", str(path)]) == 2  # a user's problem: one line, no traceback
    error = " ".join(capsys.readouterr().err.split())  # the CLI's console wraps long lines
    assert "odd.mcap, message at t_s=0.5 s: /bench/sample.jet_forces_n: Expected" in error and "Traceback" not in error


def test_records_are_read_by_type(tmp_path: Path) -> None:
    contents = read_log(small_log(tmp_path / "run.mcap", chunks=2))
    assert [type(m) for m in contents.on(Sample)] == [Sample, Sample]
    assert [m.topic for m in contents.on(EmFrame)] == ["/em/frame"] * 2
    assert len(contents.on(Event)) == len(contents.on(FrameTransform)) == len(contents.on(SceneUpdate)) == 2
