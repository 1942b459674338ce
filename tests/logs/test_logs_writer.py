"""LogWriter and read_log on complete logs: every topic round trips, JSON encoding,
schemas, metadata, flushing, and what other MCAP readers see."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from log_examples import EXAMPLES, METADATA, QUATERNION, START_TIME_UNIX_S, small_log, write_all_topics
from mcap.reader import make_reader

from hydrojet_bench.errors import UserError
from hydrojet_bench.logs import TOPICS, LogWriter, read_log, read_metadata, schema_problem
from hydrojet_bench.logs.codec import decode, encode, jsonable


def test_every_topic_round_trips(tmp_path: Path) -> None:
    contents = read_log(small_log(tmp_path / "run.mcap", chunks=2))
    assert not contents.truncated
    assert contents.metadata == METADATA
    assert contents.start_time_unix_s == pytest.approx(START_TIME_UNIX_S, abs=1e-9)
    assert [m.topic for m in contents.messages] == 2 * (list(EXAMPLES) + ["/tf", "/scene/backbone"])
    times = [m.t_s for m in contents.messages]
    assert times == sorted(times) and times[0] == 0.0
    by_topic = {m.topic: m for m in contents.messages[:len(TOPICS)]}
    for topic, message in EXAMPLES.items():
        data = by_topic[topic].data
        assert data == {"t_s": by_topic[topic].t_s, **jsonable(message)}, topic
    # numpy arrays, float32 and int64 came back as plain JSON values; NaN as null.
    assert by_topic["/bench/sample"].data["base_orientation"] == QUATERNION.tolist()
    assert by_topic["/imu/raw"].data["accel_m_s2"] == [float(np.float32(v)) for v in (0.1, -9.8, 0.2)]
    assert by_topic["/em/frame"].data["tools"][1]["rms_error_mm"] is None
    transform = by_topic["/tf"].data
    w, x, y, z = QUATERNION
    assert transform["rotation"] == {"x": x, "y": y, "z": z, "w": w}
    assert transform["translation"] == {"x": 0.01, "y": 0.0, "z": 0.068}
    assert (transform["parent_frame_id"], transform["child_frame_id"]) == ("base", "tip")
    line = by_topic["/scene/backbone"].data["entities"][0]["lines"][0]
    assert line["type"] == 0 and len(line["points"]) == 5 and line["points"][-1] == {"x": 0.01, "y": 0.0, "z": 0.068}


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
            assert schema.name == TOPICS[channel.topic][0]
            stored_schema = json.loads(schema.data)
            assert stored_schema == TOPICS[channel.topic][1]
            assert schema_problem(stored_schema, json.loads(message.data)) is None, channel.topic
    assert {s.name for s in summary.schemas.values()} >= {"foxglove.FrameTransform", "foxglove.SceneUpdate"}


def _viewer_problems(schema: dict, where: str) -> list[str]:
    """What Foxglove's and Lichtblick's JSON-schema reader (parseJsonSchema in their
    mcap-support package) cannot turn into a message definition: a root or nested object
    without "properties", a field whose "type" is not one type name, an array without
    typed "items"."""
    problems = [] if isinstance(schema.get("properties"), dict) else [f"{where}: object without properties"]
    for name, field in schema.get("properties", {}).items():
        kind = field.get("type")
        if kind not in ("boolean", "string", "number", "integer", "object", "array"):
            problems.append(f"{where}.{name}: type {kind!r}")
        elif kind == "object":
            problems += _viewer_problems(field, f"{where}.{name}")
        elif kind == "array":
            items = field.get("items", {})
            if items.get("type") not in ("boolean", "string", "number", "integer", "object"):
                problems.append(f"{where}.{name}: array items of type {items.get('type')!r}")
            elif items["type"] == "object":
                problems += _viewer_problems(items, f"{where}.{name}[]")
    return problems


def test_schemas_are_readable_by_foxglove_and_lichtblick() -> None:
    for topic, (_, schema) in TOPICS.items():
        assert schema["type"] == "object" and _viewer_problems(schema, topic) == []
    assert _viewer_problems({"type": "object", "properties": {"a": {"type": ["array", "null"]}}}, "t") == [
        "t.a: type ['array', 'null']"]


@pytest.mark.parametrize(("topic", "change", "problem"), [
    ("/bench/sample", {"source": "optical"}, "/bench/sample.source: must be one of 'em', 'imu'"),
    ("/bench/sample", {"sweep": -2}, "/bench/sample.sweep: must be >= -1"),
    ("/bench/sample", {"tip_orientation": [1.0, 0.0, 0.0]}, "tip_orientation: expected 4 items, got 3"),
    ("/bench/sample", {"jet_forces_n": [0.1, float("nan"), 0.0]}, "jet_forces_n[1]: expected number, got null"),
    ("/bench/sample", {"step": 1.5}, "/bench/sample.step: expected integer, got float 1.5"),
    ("/em/frame", {"tools": [{"name": "tip"}]}, "/em/frame.tools[0].handle: required field missing"),
    ("/valves/reply", {"ok": "yes"}, "/valves/reply.ok: expected boolean"),
    ("/bench/parameters", {"parameters": {"E0": "soft"}}, "/bench/parameters.parameters.E0: expected number"),
    ("/events", {"level": "debug"}, "/events.level: must be one of"),
])
def test_writer_rejects_messages_that_break_the_schema(tmp_path: Path, topic, change, problem) -> None:
    with LogWriter(tmp_path / "run.mcap") as log:
        with pytest.raises(ValueError) as error:
            log.write(topic, {**EXAMPLES[topic], **change}, t_s=1.0)
        assert problem in str(error.value)
        missing = dict(EXAMPLES[topic])
        missing.pop(next(iter(missing)))
        with pytest.raises(ValueError, match="required field missing"):
            log.write(topic, missing, t_s=1.0)
    assert read_log(tmp_path / "run.mcap").messages == []


def test_writer_rejects_unknown_topics_and_bad_times(tmp_path: Path) -> None:
    with LogWriter(tmp_path / "run.mcap") as log:
        with pytest.raises(ValueError, match="unknown log topic '/em/frames'"):
            log.write("/em/frames", EXAMPLES["/em/frame"], t_s=0.0)
        with pytest.raises(ValueError, match="t_s must be a finite number"):
            log.write("/events", EXAMPLES["/events"], t_s=float("nan"))
        with pytest.raises(ValueError, match="says 2.0 s but was written at t_s=1.0"):
            log.write("/events", {**EXAMPLES["/events"], "t_s": 2.0}, t_s=1.0)
        log.write("/events", {**EXAMPLES["/events"], "t_s": 1.0}, t_s=1.0)  # agreeing t_s is fine
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
    with LogWriter(path, flush_interval_s=1e-9) as log:  # every write is past the interval
        write_all_topics(log, 0.0)
        assert len(read_log(shutil.copy(path, tmp_path / "auto.mcap")).messages) == len(TOPICS)
    with pytest.raises(ValueError, match="closed"):
        log.write("/events", EXAMPLES["/events"], t_s=0.0)
    log.close()  # closing twice is harmless


def test_log_is_finished_when_the_session_fails(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    with pytest.raises(RuntimeError):
        with LogWriter(path) as log:
            log.write("/events", EXAMPLES["/events"], t_s=0.5)
            raise RuntimeError("valve controller lost")
    contents = read_log(path)
    assert not contents.truncated and len(contents.messages) == 1


# --- JSON encoding ---------------------------------------------------------------------

finite_or_not = st.floats(allow_nan=True, allow_infinity=True)


def _expected(value: float) -> float | None:
    return value if math.isfinite(value) else None


leaves = st.one_of(
    st.none(), st.booleans(), st.text(max_size=8), st.integers(-2**62, 2**62),
    finite_or_not.map(lambda v: (v, _expected(v))),
    finite_or_not.map(lambda v: (np.float64(v), _expected(v))),
    st.floats(width=32, allow_nan=True).map(lambda v: (np.float32(v), _expected(float(np.float32(v))))),
    st.integers(-2**31, 2**31).map(lambda v: (np.int64(v), v)),
    st.lists(finite_or_not, max_size=5).map(lambda vs: (np.array(vs, dtype=float), [_expected(v) for v in vs])),
).map(lambda leaf: leaf if isinstance(leaf, tuple) else (leaf, leaf))
values = st.recursive(leaves, lambda children: st.one_of(
    st.lists(children, max_size=4).map(lambda pairs: ([raw for raw, _ in pairs], [exp for _, exp in pairs])),
    st.lists(children, max_size=4).map(lambda pairs: (tuple(raw for raw, _ in pairs), [exp for _, exp in pairs])),
    st.dictionaries(st.text(max_size=6), children, max_size=4).map(
        lambda items: ({k: raw for k, (raw, _) in items.items()}, {k: exp for k, (_, exp) in items.items()})),
), max_leaves=12)


@settings(max_examples=150, deadline=None)
@given(values)
def test_json_encoding_is_exact_and_has_no_nan(pair) -> None:
    raw, expected = pair
    encoded = encode(jsonable(raw))
    assert b"NaN" not in encoded and b"Infinity" not in encoded
    assert decode(encoded) == expected  # floats bit for bit (== on floats, None for non-finite)


def test_json_encoding_refuses_what_json_cannot_hold() -> None:
    with pytest.raises(ValueError, match=r"message.a\[1\]: cannot write complex"):
        jsonable({"a": [1, 2j]})
    with pytest.raises(ValueError, match="keys must be strings"):
        jsonable({1: "x"})


def test_schema_checker_refuses_keywords_it_does_not_know() -> None:
    with pytest.raises(ValueError, match="pattern"):
        schema_problem({"type": "string", "pattern": "^a"}, "b")
    assert schema_problem({"type": "integer"}, 3.0) is None  # JSON Schema: 3.0 is an integer
    assert schema_problem({"type": "integer"}, True) == "message: expected integer, got bool True"
