"""The record types of the log topics: JSON round trips, what a reader refuses, the
generated schemas (against the messages and against Foxglove's rules), and logs
written before the record types existed."""

from __future__ import annotations

import json
import re
from pathlib import Path

import msgspec
import msgspec.inspect
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from json_schema_check import schema_problem
from log_examples import ADDED_SINCE_FORMAT_1, EXAMPLES, small_log
from mcap.reader import make_reader
from record_strategies import records_of

from hydrojet_bench.bench.replay import read_session
from hydrojet_bench.errors import UserError
from hydrojet_bench.logs import TOPICS, LogError, read_log
from hydrojet_bench.logs.codec import decode, encode
from hydrojet_bench.logs.schemas import schema_name, topic_schema
from hydrojet_bench.logs.topics import EmFrame, Event, ImuRaw, Sample, Step

# Written by the bench before the record types (hand-written schemas, dict messages):
# every topic once, as `small_log(chunks=1)` writes it.
FORMAT_1_LOG = Path(__file__).parent / "data" / "format1_all_topics.mcap"
JSON_TYPES = ("boolean", "string", "number", "integer", "object", "array")


@pytest.mark.parametrize("topic", list(TOPICS))
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_every_topic_round_trips_through_json(topic: str, data: st.DataObject) -> None:
    record = data.draw(records_of(TOPICS[topic]))
    encoded = encode(record)
    assert decode(topic, encoded) == record  # floats bit for bit
    assert schema_problem(topic_schema(TOPICS[topic]), json.loads(encoded), topic) is None


@pytest.mark.parametrize("topic", list(TOPICS))
@settings(max_examples=60, deadline=None)
@given(data=st.one_of(st.binary(max_size=64), st.text(max_size=64).map(str.encode),
                      st.recursive(st.none() | st.booleans() | st.floats() | st.text(max_size=4),
                                   lambda children: st.lists(children, max_size=3)
                                   | st.dictionaries(st.text(max_size=4), children, max_size=3),
                                   max_leaves=8).map(lambda value: json.dumps(value).encode())))
def test_anything_else_on_a_topic_is_a_log_error(topic: str, data: bytes) -> None:
    try:
        record = decode(topic, data)
    except LogError as error:
        assert str(error).startswith(topic) and "\n" not in str(error)
    else:
        assert type(record) is TOPICS[topic]


def test_log_errors_name_the_topic_and_field() -> None:
    assert issubclass(LogError, UserError)  # one line on the command line, no traceback
    sample = json.loads(encode(EXAMPLES["/bench/sample"]))
    cases = [
        ({**sample, "source": "optical"}, "/bench/sample.source: Invalid enum value 'optical'"),
        ({**sample, "jet_forces_n": [0.1, None, 0.0]}, "/bench/sample.jet_forces_n[1]: Expected `float`, got `null`"),
        ({**sample, "tip_orientation": [1.0, 0.0, 0.0]}, "/bench/sample.tip_orientation: Expected `array` of length"),
        ({key: value for key, value in sample.items() if key != "step"},
         "/bench/sample: Object missing required field `step`"),
        ([1, 2], "/bench/sample: Expected `object`, got `array`"),
    ]
    for message, problem in cases:
        with pytest.raises(LogError, match=re.escape(problem)):
            decode("/bench/sample", json.dumps(message).encode())
    with pytest.raises(LogError, match="^/events: JSON is malformed"):
        decode("/events", b'{"t_s": 0.0, "level": info}')


def test_non_finite_floats_are_null_and_read_back_as_none_where_allowed() -> None:
    frame = EXAMPLES["/em/frame"]
    encoded = encode(frame)
    assert b"NaN" not in encoded and b"Infinity" not in encoded
    tip = json.loads(encoded)["tools"][1]
    assert tip["rms_error_mm"] is None and decode("/em/frame", encoded).tools[1].rms_error_mm is None
    raw = msgspec.structs.replace(EXAMPLES["/imu/raw"], temperature_c=float("-inf"))
    assert decode("/imu/raw", encode(raw)).temperature_c is None
    with pytest.raises(LogError, match=r"/imu/raw.accel_m_s2\[0\]: Expected `float`, got `null`"):
        decode("/imu/raw", encode(msgspec.structs.replace(raw, accel_m_s2=(float("nan"), 0.0, 9.8))))


def test_integral_floats_in_integer_fields_still_read() -> None:
    # The checker that guarded logs before the record types counted 3.0 as an integer.
    step = json.loads(encode(EXAMPLES["/bench/step"]))
    assert decode("/bench/step", json.dumps({**step, "index": 3.0, "sweep": -1.0}).encode()) == EXAMPLES["/bench/step"]


def _viewer_problems(schema: dict, where: str) -> list[str]:
    """What Foxglove's and Lichtblick's JSON-schema reader (parseJsonSchema in their
    mcap-support package) cannot turn into a message definition: a root or nested object
    without "properties", a field whose "type" is not one type name (a reference, a
    union), an array without typed "items"."""
    problems = [] if isinstance(schema.get("properties"), dict) else [f"{where}: object without properties"]
    for name, field in schema.get("properties", {}).items():
        kind = field.get("type")
        if kind not in JSON_TYPES:
            problems.append(f"{where}.{name}: type {kind!r}")
        elif kind == "object":
            problems += _viewer_problems(field, f"{where}.{name}")
        elif kind == "array":
            items = field.get("items", {})
            if items.get("type") not in JSON_TYPES[:-1]:
                problems.append(f"{where}.{name}: array items of type {items.get('type')!r}")
            elif items["type"] == "object":
                problems += _viewer_problems(items, f"{where}.{name}[]")
    return problems


def test_schemas_are_readable_by_foxglove_and_lichtblick() -> None:
    for topic, record_type in TOPICS.items():
        schema = topic_schema(record_type)
        assert schema["type"] == "object" and _viewer_problems(schema, topic) == []
        assert "$ref" not in json.dumps(schema) and "anyOf" not in json.dumps(schema), topic
    assert _viewer_problems({"type": "object", "properties": {"a": {"type": ["array", "null"]}}}, "t") == [
        "t.a: type ['array', 'null']"]
    assert _viewer_problems({"type": "object", "properties": {"a": {"$ref": "#/$defs/A"}}}, "t") == ["t.a: type None"]


def test_schemas_describe_the_fields() -> None:
    sample = topic_schema(Sample)
    assert sample["title"] == schema_name(Sample) == "hydrojet_bench.Sample"
    assert sample["description"].startswith("One row of the CSV contract")
    assert list(sample["properties"])[0] == "t_s"
    assert sample["properties"]["source"] == {"description": "which sensors measured the poses", "type": "string",
                                              "enum": ["em", "imu"]}
    assert sample["properties"]["sweep"]["minimum"] == -1
    position = sample["properties"]["tip_position_m"]
    assert position["nullable"] is True and position["description"].endswith("m; null if unknown")
    assert (position["type"], position["items"], position["minItems"], position["maxItems"]) == (
        "array", {"type": "number"}, 3, 3)
    assert "(w, x, y, z)" in sample["properties"]["base_orientation"]["description"]
    assert set(sample["required"]) == set(sample["properties"]) - {"flags"}
    assert topic_schema(EmFrame)["properties"]["tools"]["items"]["properties"]["handle"]["type"] == "integer"
    assert schema_name(TOPICS["/tf"]) == "foxglove.FrameTransform"
    assert schema_name(TOPICS["/scene/backbone"]) == "foxglove.SceneUpdate"


def test_the_schema_checker_refuses_keywords_it_does_not_know() -> None:
    with pytest.raises(ValueError, match="pattern"):
        schema_problem({"type": "string", "pattern": "^a"}, "b")
    assert schema_problem({"type": "integer"}, 3.0) is None
    assert schema_problem({"type": "integer"}, True) == "message: expected integer, got bool True"
    assert schema_problem({"type": "object", "properties": {"a": {"type": "number"}}, "required": ["a"]}, {}) == \
        "message.a: required field missing"


def test_logs_of_format_1_still_read(tmp_path: Path) -> None:
    old = read_log(FORMAT_1_LOG)
    assert not old.truncated
    # Topics added since format 1 are missing from it; every other one must read the same.
    added = ADDED_SINCE_FORMAT_1
    assert old.messages == [m for m in read_log(small_log(tmp_path / "new.mcap", chunks=1)).messages
                            if m.topic not in added]
    optional = {field.name for record_type in TOPICS.values()
                for field in msgspec.inspect.type_info(record_type).fields if not field.required}
    with FORMAT_1_LOG.open("rb") as handle:
        raw = [json.loads(message.data) for _, _, message in make_reader(handle).iter_messages()]
    assert len(raw) == len(old.messages) == len(TOPICS) - len(added)
    for written, record in zip(raw, old.messages):
        # Every field of the old message means the same; new fields only where defaults fill them in.
        rewritten = json.loads(encode(record))
        assert {key: rewritten[key] for key in written} == written, record.topic
        assert set(rewritten) - set(written) <= optional, record.topic
    steps = [record for record in old.messages if isinstance(record, Step)]
    assert steps[0].time_s is None and steps[0].base_orientation is None  # optional then, None now
    assert old.on(Event)[0].level == "warning" and old.on(ImuRaw)[0].mag_ut is None


def test_replay_names_what_a_format_1_step_lacks() -> None:
    # Steps of the earliest logs carry no averaged sensor poses: nothing to replay.
    with pytest.raises(UserError, match=r"/bench/step messages are not complete settled steps "
                                        r"\(/bench/step.time_s is missing\)"):
        read_session(FORMAT_1_LOG, "sim")
