"""The ``foxglove.*`` channels of a session log against Foxglove's own definitions, the
ones the Foxglove SDK ships (`foxglove_check`), and the checker's power to refuse."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest
from foxglove_check import json_schema_problems, message_problems
from log_examples import small_log
from mcap.reader import make_reader

from hydrojet_bench.logs import TOPICS
from hydrojet_bench.logs.schemas import schema_name, topic_schema

FOXGLOVE_SCHEMAS = sorted(schema_name(record) for record in TOPICS.values() if record.schema_namespace == "foxglove")


def _foxglove_channels(path: Path) -> dict[str, tuple[dict, list[dict]]]:
    """schema name -> (the schema stored in the log, the messages on its channel)."""
    found: dict[str, tuple[dict, list[dict]]] = {}
    with path.open("rb") as handle:
        for schema, channel, message in make_reader(handle).iter_messages():
            if schema.name.startswith("foxglove."):
                assert (schema.encoding, channel.message_encoding) == ("jsonschema", "json")
                found.setdefault(schema.name, (json.loads(schema.data), []))[1].append(json.loads(message.data))
    return found


def test_every_foxglove_channel_of_a_log_matches_foxglove_s_definition(tmp_path: Path) -> None:
    channels = _foxglove_channels(small_log(tmp_path / "log.mcap", chunks=2))
    assert sorted(channels) == FOXGLOVE_SCHEMAS == ["foxglove.FrameTransform", "foxglove.SceneUpdate"]
    for name, (schema, messages) in channels.items():
        assert json_schema_problems(name, schema) == []
        assert len(messages) == 2
        for message in messages:
            assert message_problems(name, message) == []


@pytest.fixture(scope="module")
def backbone(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, dict]:
    log = small_log(tmp_path_factory.mktemp("log") / "log.mcap", chunks=1)
    schema, (message,) = _foxglove_channels(log)["foxglove.SceneUpdate"]
    return schema, message


def test_the_check_refuses_a_misnamed_or_mistyped_field_in_a_message(backbone: tuple[dict, dict]) -> None:
    _, message = backbone
    broken = copy.deepcopy(message)
    entity = broken["entities"][0]
    entity["frameId"] = entity.pop("frame_id")  # protobuf's JSON name, not Foxglove's
    line = entity["lines"][0]
    line["thickness"] = "0.01"
    line["scale_invariant"] = 0
    line["type"] = 3  # no such LineType
    line["points"][1]["z"] = None
    entity["timestamp"]["nsec"] = 1_000_000_000
    where = "foxglove.SceneUpdate.entities[0]"
    assert message_problems("foxglove.SceneUpdate", broken) == [
        f"{where}.frameId: no such field in .foxglove.SceneEntity",
        f"{where}.timestamp.nsec: 1000000000 outside [0, 1e9)",
        f"{where}.frame_id: missing",
        f"{where}.lines[0].type: 3 is not a value of .foxglove.LinePrimitive.Type [0, 1, 2]",
        f"{where}.lines[0].thickness: str '0.01' where protobuf type 1 is defined",
        f"{where}.lines[0].scale_invariant: int 0 where protobuf type 8 is defined",
        f"{where}.lines[0].points[1].z: NoneType None where protobuf type 1 is defined",
    ]
    assert message_problems("foxglove.SceneUpdate", {**message, "t_s": 1.0, "extra": 1}) == [
        "foxglove.SceneUpdate.extra: no such field in .foxglove.SceneUpdate"]


def test_the_check_refuses_a_misnamed_or_mistyped_field_in_a_schema(backbone: tuple[dict, dict]) -> None:
    schema, _ = backbone
    broken = copy.deepcopy(schema)
    entity = broken["properties"]["entities"]["items"]["properties"]
    entity["frame"] = entity.pop("frame_id")
    entity["lines"]["items"]["properties"]["indices"]["items"]["type"] = "number"
    entity["lines"]["items"]["properties"]["points"] = {"type": "object", "properties": {}}
    where = "foxglove.SceneUpdate.entities"
    assert json_schema_problems("foxglove.SceneUpdate", broken) == [
        f"{where}.frame: no such field in .foxglove.SceneEntity",
        f"{where}.frame_id: missing",
        f"{where}.lines.points: type 'object' where an array is defined",
        f"{where}.lines.indices: type 'number' where 'integer' is defined",
    ]
    assert json_schema_problems("foxglove.FrameTransform", topic_schema(TOPICS["/tf"])) == []
