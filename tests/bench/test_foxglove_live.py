"""`run --foxglove`: a live session over the Foxglove WebSocket protocol, as Foxglove or
Lichtblick would watch it (`foxglove_client`), and the server stopped on every way out."""

from __future__ import annotations

import contextlib
import json
import os
import selectors
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import msgspec
import pytest
from foxglove_check import json_schema_problems, message_problems
from foxglove_client import FoxgloveClient, Message
from foxglove_layout import LAYOUT, layout_references, parse_path, path_problem
from mcap.reader import make_reader

from hydrojet_bench.bench.foxglove_live import FoxgloveLive
from hydrojet_bench.cli import main
from hydrojet_bench.errors import UserError
from hydrojet_bench.logs import TOPICS, read_log
from hydrojet_bench.logs.codec import decode, encode
from hydrojet_bench.logs.schemas import schema_name, topic_schema
from hydrojet_bench.logs.topics import Event, FrameTransform

LIVE_TOPICS = {"/scene/backbone", "/tf", "/model/prediction"}


def _refused(port: int, within_s: float = 5.0) -> bool:
    """Whether connections to ``port`` are refused within ``within_s`` (the SDK's server
    stops its listener asynchronously)."""
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=2).close()
        except ConnectionRefusedError:
            return True
        except ConnectionResetError:
            pass  # accepted as the listener closed: ask again
        time.sleep(0.05)
    return False


def _line_starting(process: subprocess.Popen, prefix: str, timeout_s: float) -> str:
    deadline = time.monotonic() + timeout_s
    seen = []
    with selectors.DefaultSelector() as selector:
        selector.register(process.stdout, selectors.EVENT_READ)
        while time.monotonic() < deadline:
            if selector.select(timeout=deadline - time.monotonic()):
                line = process.stdout.readline()
                if not line:
                    break
                seen.append(line)
                if line.startswith(prefix):
                    return line
    raise AssertionError(f"no line starting {prefix!r} in {''.join(seen)!r}")


@dataclass(frozen=True)
class LiveSession:
    log_path: Path
    port: int
    returncode: int
    output: str
    advertised: dict[str, dict]  # topic -> the server's advertisement
    received: dict[str, list[Message]]  # topic -> what the client received


@pytest.fixture(scope="module")
def live_session(tmp_path_factory: pytest.TempPathFactory) -> LiveSession:
    """A simulated session run with ``--foxglove 0``, watched by a client until the
    backbone and tip topics came, then stopped with Ctrl-C."""
    log_path = tmp_path_factory.mktemp("live") / "run.mcap"
    process = subprocess.Popen([sys.executable, "-m", "hydrojet_bench.cli", "run", "--plan", "sweeps", "--no-live",
                                "--time-scale", "5", "--log", str(log_path), "--foxglove", "0"],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                               env={**os.environ, "PYTHONUNBUFFERED": "1"})
    received: dict[str, list[Message]] = {topic: [] for topic in LIVE_TOPICS}
    try:
        url = _line_starting(process, "Foxglove: open a connection to ws://127.0.0.1:", 120).split()[5]
        port = int(url.rsplit(":", 1)[1])
        with FoxgloveClient("127.0.0.1", port) as client:
            client.subscribe(LIVE_TOPICS)
            advertised = {channel["topic"]: channel for channel in client.channels.values()}
            while not all(received.values()):
                message = client.receive(timeout_s=120)
                received[message.topic].append(message)
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    return LiveSession(log_path, port, process.returncode, output, advertised, received)


def test_run_streams_the_live_session_to_a_foxglove_client(live_session: LiveSession) -> None:
    assert live_session.returncode == 130 and "Traceback" not in live_session.output, live_session.output
    assert _refused(live_session.port)
    # Every log topic is advertised with the log's own schema.
    assert set(live_session.advertised) == set(TOPICS)
    for topic, channel in live_session.advertised.items():
        assert channel["schemaName"] == schema_name(TOPICS[topic]) and channel["encoding"] == "json"
        assert msgspec.json.decode(channel["schema"]) == topic_schema(TOPICS[topic])
    # What the client saw is what the log holds, at the log's times (session start + t_s).
    logged = read_log(live_session.log_path, topics=sorted(LIVE_TOPICS)).messages
    offsets_ns = set()
    for topic, messages in live_session.received.items():
        for message in messages:
            record = decode(topic, msgspec.json.encode(message.data))
            assert record in logged
            offsets_ns.add(message.log_time_ns - round(record.t_s * 1e9))
    assert max(offsets_ns) - min(offsets_ns) <= 1
    backbone = live_session.received["/scene/backbone"][0].data["entities"][0]
    assert backbone["id"] == "backbone" and len(backbone["lines"][0]["points"]) > 2
    assert {m.data["child_frame_id"] for m in live_session.received["/tf"]} <= {"tip_model", "tip_measured"}


def test_a_session_log_s_foxglove_channels_match_foxglove_s_definitions(live_session: LiveSession) -> None:
    with live_session.log_path.open("rb") as handle:
        checked = set()
        for schema, _, message in make_reader(handle).iter_messages():
            if schema.name.startswith("foxglove."):
                assert json_schema_problems(schema.name, json.loads(schema.data)) == []
                assert message_problems(schema.name, json.loads(message.data)) == []
                checked.add(schema.name)
    assert checked == {"foxglove.FrameTransform", "foxglove.SceneUpdate"}


def test_the_shipped_layout_shows_only_what_a_session_log_has(live_session: LiveSession) -> None:
    paths, frames = layout_references(json.loads(LAYOUT.read_text()))
    contents = read_log(live_session.log_path)
    topics = {message.topic for message in contents.messages}
    assert {path.topic for path in paths} <= topics
    assert {"/scene/backbone", "/model/prediction", "/estimate/disturbance"} <= {path.topic for path in paths}
    logged_frames = {frame for transform in contents.on(FrameTransform)
                     for frame in (transform.parent_frame_id, transform.child_frame_id)}
    assert frames <= logged_frames and {"base", "tip_model"} <= frames


def test_the_server_stops_when_the_session_fails() -> None:
    with pytest.raises(RuntimeError, match="device fell over"):
        with FoxgloveLive(0) as live:
            port = live.port
            with FoxgloveClient("127.0.0.1", port) as client:
                client.subscribe({"/events"})
                event = Event(t_s=1.5, level="error", source="test", message="device fell over")
                for _ in range(100):  # until the server has taken the subscription in
                    live.publish("/events", 1_500_000_000, encode(event))
                    with contextlib.suppress(TimeoutError):
                        message = client.receive(timeout_s=0.1)
                        break
                else:
                    pytest.fail("the client never received a message on /events")
            raise RuntimeError(message.data["message"])
    assert (message.topic, message.log_time_ns, decode("/events", encode(event))) == ("/events", 1_500_000_000, event)
    assert _refused(port)


def test_a_taken_port_or_a_bad_address_is_one_line_and_no_log(tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "run.mcap"
    with FoxgloveLive(0) as live:
        port = live.port
        with pytest.raises(UserError, match=f"--foxglove 127.0.0.1:{port}: cannot listen: .*in use"):
            FoxgloveLive(port).__enter__()
        assert main(["run", "--plan", "hold:1", "--no-live", "--log", str(log), "--foxglove", str(port)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: --foxglove 127.0.0.1:{port}: cannot listen") and err.count("\n") == 1, err
    for address in ("70000", "localhost", "127.0.0.1:port"):
        assert main(["run", "--plan", "hold:1", "--no-live", "--log", str(log), "--foxglove", address]) == 2
        err = capsys.readouterr().err
        assert err == f"error: --foxglove {address}: expected [HOST:]PORT, a port 0 to 65535\n", err
    assert not log.exists()


def test_the_layout_plots_numbers_the_topics_have() -> None:
    paths, _ = layout_references(json.loads(LAYOUT.read_text()))
    assert len(paths) >= 8 and [path_problem(path) for path in paths] == [None] * len(paths)
    wrong = ['/model/prediction{method=="offline"}.orientation_error_deg', "/model/prediction.orientation_error",
             "/estimate/disturbance.moment_nm[3]", "/estimate/disturbance.moment_nm", "/estimate/disturbances.index"]
    assert [path_problem(parse_path(text)) for text in wrong] == [
        f"{wrong[0]}: method is never 'offline'", f"{wrong[1]}: no field orientation_error",
        f"{wrong[2]}: [3] beyond 3 items", f"{wrong[3]}: ends at a VarTupleType, not a number",
        f"{wrong[4]}: no topic /estimate/disturbances"]
