"""`LogWriter`: one bench session into one MCAP file that survives being killed.

The file is chunked. The open chunk is closed and handed to the operating system
whenever ``flush_interval_s`` of wall time has passed since the last flush (checked on
each write) and on `LogWriter.flush`; a chunk is all-or-nothing, so a SIGKILL loses at
most the data of the last ``flush_interval_s`` (plus one message interval). No fsync:
data handed to the OS outlives the process; only a power cut can lose more.

With ``background=True`` (a live session) the MCAP work itself (adding each message to
the chunk, compressing and indexing it) runs on a writer thread: at the simulated rig's
rates it took a tenth of the event loop's time, and a chunk's flush held the loop for
4-6 ms, as long as the IMU FIFOs last. The caller's thread still checks, encodes and
orders every record and calls the listener; a kill then also loses what the thread had
not yet taken (about 5 ms of wall time more).

Layout: header, `LOG_METADATA_NAME` (format version, wall time of ``t_s = 0``), the
caller's metadata records, then chunks holding each topic's schema and channel (written
with its first message) and the messages. `close` adds the summary and footer.
"""

from __future__ import annotations

import heapq
import itertools
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from pathlib import Path
from types import TracebackType
from typing import Any

import msgspec
import numpy as np
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer
from numpy.typing import ArrayLike

from .. import __version__
from ..files import create_new
from ..params import RodParameters
from .codec import LogError, decode, encode
from .format import FORMAT_VERSION, LOG_METADATA_NAME, MESSAGE_ENCODING, SCHEMA_ENCODING, START_TIME_KEY
from .foxglove import (LINE_STRIP, Color, Duration, FrameTransform, LinePrimitive, Point3, Pose, Quaternion,
                       SceneEntity, SceneUpdate, Time, Vector3)
from .log_record import LogRecord
from .schemas import schema_name, topic_schema_json
from .topics import TOPICS

LIBRARY = f"hydrojet-bench {__version__}; {LIBRARY_IDENTIFIER}"
_NS_PER_S = 1_000_000_000
# The HydroJet sleeve's diameter: drawn at true width, the backbone looks like the rod.
DEFAULT_BACKBONE_THICKNESS_M = 2 * RodParameters().radius_m
DEFAULT_BACKBONE_COLOR = (0.95, 0.55, 0.1, 1.0)
_IDENTITY_POSE = Pose(position=Vector3(0.0, 0.0, 0.0), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))


class LogWriter:
    """Writes a session log (see the module docstring); a context manager.

    path: the .mcap file, created exclusively: an existing file raises `UserError` (two
        writers can never share a log) unless ``overwrite``.
    metadata: named records of string keys and values, e.g. ``{"bench": {"profile_name":
        "sim", "profile_toml": "..."}}``; written right after the header, so they survive
        any crash. The name ``"hydrojet_bench.log"`` is reserved.
    start_time_unix_s: wall-clock time of session time 0, s since the Unix epoch
        (default: now). Message times in the file are this plus ``t_s``, in ns.
    flush_interval_s: wall time between automatic flushes, s.
    overwrite: replace an existing file (the user's ``--overwrite``, or a file this
        process reserved with `hydrojet_bench.files.create_numbered`).
    listener: called with (topic, log time in ns since the Unix epoch, JSON bytes) for
        every message written (in the order written), e.g. to stream the session live.
    reorder_window_s: session time a record is held back, s, so that records written
        late (a sample stamped when it was measured, a prediction stamped with its step's
        end) still go into the file in time order: every channel's log time then never
        runs backwards and chunks do not overlap. A record later than the window is
        logged at the newest time already written (its ``t_s`` keeps the true time).
        0: written as it comes. Held records are written on `close`; a kill loses them.
    background: do the MCAP work on a writer thread (see the module docstring). An
        error there (a full disk) is raised by every later `write`, `flush` and `close`.

    `write` raises ValueError for a record that is not of a topic's type or that its
    topic's reader would refuse (e.g. NaN where null is not allowed), naming the field.
    """

    def __init__(self, path: str | Path, metadata: Mapping[str, Mapping[str, str]] | None = None,
                 start_time_unix_s: float | None = None, flush_interval_s: float = 1.0, *,
                 overwrite: bool = False, listener: Callable[[str, int, bytes], None] | None = None,
                 reorder_window_s: float = 0.0, background: bool = False) -> None:
        if not flush_interval_s > 0:
            raise ValueError(f"flush_interval_s must be > 0 s, got {flush_interval_s!r}")
        records = _checked_metadata(metadata or {})
        start_s = time.time() if start_time_unix_s is None else float(start_time_unix_s)
        if not (np.isfinite(start_s) and start_s >= 0):
            raise ValueError(f"start_time_unix_s must be a finite time >= 0 s, got {start_time_unix_s!r}")
        self.path = Path(path)
        whole_s = int(start_s)  # split: start_s * 1e9 alone would round to 256 ns
        self.start_time_ns = whole_s * _NS_PER_S + round((start_s - whole_s) * _NS_PER_S)
        self.flush_interval_s = float(flush_interval_s)
        if not reorder_window_s >= 0:
            raise ValueError(f"reorder_window_s must be >= 0 s, got {reorder_window_s!r}")
        self._reorder_window_ns = round(reorder_window_s * _NS_PER_S)
        self._held: list[tuple[int, int, str, bytes]] = []  # a heap: (log_time, arrival, topic, data)
        self._arrivals = itertools.count()
        self._newest_ns = 0
        self._written_ns = 0  # the newest log time in the file
        self.late_records = 0  # records later than the reorder window
        self._stream = create_new(self.path, "session log", overwrite=overwrite)
        self._listener = listener
        self._closed = False
        chunks = _Chunks(self._stream, self.flush_interval_s)
        chunks.start(records, self.start_time_ns)
        self._chunks: _Chunks | _BackgroundChunks = _BackgroundChunks(chunks, self.path) if background else chunks

    # --- writing ------------------------------------------------------------------------

    def write(self, record: LogRecord) -> None:
        """Log one record (a type of `TOPICS`) on its topic at its session time ``t_s``."""
        topic = getattr(record, "topic", None)
        if TOPICS.get(topic) is not type(record):
            raise ValueError(f"not a log record: {type(record).__name__}; records: "
                             f"{', '.join(record_type.__name__ for record_type in TOPICS.values())}")
        log_time = self._log_time(topic, record.t_s)
        try:
            data = encode(record)
            decode(topic, data)  # what the reader would refuse is a bug here, not a log to find out later
        except (LogError, TypeError, msgspec.EncodeError) as error:
            raise ValueError(str(error) if isinstance(error, LogError) else f"{topic}: {error}") from None
        self._add(topic, log_time, data)

    def write_transform(self, t_s: float, parent: str, child: str, rotation: ArrayLike,
                        translation_m: ArrayLike) -> None:
        """Log the pose of frame ``child`` in frame ``parent`` on ``/tf``
        (foxglove.FrameTransform): ``rotation`` a unit quaternion (w, x, y, z) mapping
        child-frame vectors into the parent frame, ``translation_m`` the child origin in
        the parent frame, m."""
        w, x, y, z = _finite("/tf rotation", rotation, (4,))
        self.write(FrameTransform(t_s=t_s, timestamp=self._timestamp(FrameTransform.topic, t_s),
                                  parent_frame_id=parent, child_frame_id=child,
                                  translation=Vector3(*_finite("/tf translation_m", translation_m, (3,))),
                                  rotation=Quaternion(x=x, y=y, z=z, w=w)))

    def write_backbone(self, t_s: float, positions_in_base_m: ArrayLike, frame: str = "base", *,
                       thickness_m: float = DEFAULT_BACKBONE_THICKNESS_M,
                       color: tuple[float, float, float, float] = DEFAULT_BACKBONE_COLOR) -> None:
        """Log the rod's backbone, (n, 3) points in ``frame`` in m, on ``/scene/backbone``
        (foxglove.SceneUpdate): one entity ``"backbone"`` holding one LINE_STRIP drawn
        ``thickness_m`` wide, replacing the previous one."""
        points = _finite("/scene/backbone positions_in_base_m", positions_in_base_m, (None, 3))
        line = LinePrimitive(type=LINE_STRIP, pose=_IDENTITY_POSE, thickness=thickness_m, scale_invariant=False,
                             points=tuple(Point3(*point) for point in points), color=Color(*color),
                             colors=(), indices=())
        entity = SceneEntity(timestamp=self._timestamp(SceneUpdate.topic, t_s), frame_id=frame, id="backbone",
                             lifetime=Duration(0, 0), frame_locked=True, lines=(line,))
        self.write(SceneUpdate(t_s=t_s, entities=(entity,)))

    def flush(self) -> None:
        """Close the open chunk and hand everything written so far to the operating system."""
        self._check_open()
        self._chunks.flush()

    def close(self) -> None:
        """Finish the file (summary, footer) and close it; closing twice is harmless."""
        if self._closed:
            return
        try:
            self._release(None)
        finally:
            self._closed = True
            try:
                self._chunks.finish()
            finally:
                self._stream.close()

    def __enter__(self) -> LogWriter:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 traceback: TracebackType | None) -> None:
        # Finish the file even when the session failed: the log is most wanted then.
        self.close()

    # --- internals ----------------------------------------------------------------------

    def _check_open(self) -> None:
        if self._closed:
            raise ValueError(f"{self.path}: the log is closed")

    def _log_time(self, topic: str, t_s: float) -> int:
        # math, not numpy: asked for every record, thousands a second (np.isfinite of a
        # scalar costs 15x as much).
        if isinstance(t_s, bool) or not isinstance(t_s, (int, float, np.number)) or not math.isfinite(t_s):
            raise ValueError(f"{topic}: t_s must be a finite number of seconds, got {t_s!r}")
        log_time = self.start_time_ns + round(float(t_s) * _NS_PER_S)
        if log_time < 0:
            raise ValueError(f"{topic}: t_s={t_s!r} s falls before the Unix epoch")
        return log_time

    def _timestamp(self, topic: str, t_s: float) -> Time:
        return Time(*divmod(self._log_time(topic, t_s), _NS_PER_S))

    def _add(self, topic: str, log_time: int, data: bytes) -> None:
        self._check_open()
        heapq.heappush(self._held, (log_time, next(self._arrivals), topic, data))
        self._newest_ns = max(self._newest_ns, log_time)
        self._release(self._newest_ns - self._reorder_window_ns)

    def _release(self, up_to_ns: int | None) -> None:
        """Write the held records stamped up to ``up_to_ns`` (None: all), oldest first."""
        held = self._held
        while held and (up_to_ns is None or held[0][0] <= up_to_ns):
            log_time, _, topic, data = heapq.heappop(held)
            written_ns = log_time
            if self._reorder_window_ns and log_time < self._written_ns:
                self.late_records += 1
                written_ns = self._written_ns
            self._written_ns = max(self._written_ns, written_ns)
            self._write_message(topic, written_ns, log_time, data)

    def _write_message(self, topic: str, log_time: int, publish_time: int, data: bytes) -> None:
        self._chunks.add(topic, log_time, publish_time, data)
        if self._listener is not None:
            self._listener(topic, log_time, data)


class _Chunks:
    """The MCAP side of a log: channels, sequence numbers, chunks flushed by wall time."""

    def __init__(self, stream: Any, flush_interval_s: float) -> None:
        # Chunks are closed by time (flush_interval_s); the size limit only caps memory.
        self._writer = Writer(stream, chunk_size=4 * 1024 * 1024, compression=CompressionType.ZSTD)
        self._flush_interval_s = flush_interval_s
        self._channels: dict[str, int] = {}
        self._sequence: dict[int, int] = {}

    def start(self, metadata: Mapping[str, Mapping[str, str]], start_time_ns: int) -> None:
        self._writer.start(library=LIBRARY)
        self._writer.add_metadata(LOG_METADATA_NAME, {"format_version": FORMAT_VERSION,
                                                      START_TIME_KEY: str(start_time_ns)})
        for name, values in metadata.items():
            self._writer.add_metadata(name, values)
        self.flush()

    def add(self, topic: str, log_time: int, publish_time: int, data: bytes) -> None:
        channel = self._channels.get(topic)
        if channel is None:
            record_type = TOPICS[topic]
            schema_id = self._writer.register_schema(schema_name(record_type), SCHEMA_ENCODING,
                                                     topic_schema_json(record_type))
            channel = self._channels[topic] = self._writer.register_channel(topic, MESSAGE_ENCODING, schema_id)
            self._sequence[channel] = 0
        sequence = self._sequence[channel]
        self._sequence[channel] = (sequence + 1) & 0xFFFFFFFF
        self._writer.add_message(channel, log_time=log_time, data=data, publish_time=publish_time, sequence=sequence)
        if time.monotonic() - self._last_flush >= self._flush_interval_s:
            self.flush()

    def flush(self) -> None:
        self._writer.flush()
        self._last_flush = time.monotonic()

    def finish(self) -> None:
        self._writer.finish()


# How often the writer thread takes the messages queued since its last look, s of wall
# time; and how many it adds before letting other threads have the interpreter (about
# 0.5 ms of work: the event loop must not wait for the lock longer than that).
_BACKGROUND_POLL_S = 0.005
_BACKGROUND_BATCH = 40


class _BackgroundChunks:
    """`_Chunks` on a thread of its own: `add` only queues. `flush` and `finish` wait
    for the queue to be written; an error on the thread is raised by every later call."""

    def __init__(self, chunks: _Chunks, path: Path) -> None:
        self._chunks = chunks
        self._queue: deque[tuple[str, int, int, bytes] | threading.Event] = deque()
        self._stop = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name=f"log writer {path.name}", daemon=True)
        self._thread.start()

    def add(self, topic: str, log_time: int, publish_time: int, data: bytes) -> None:
        self._raise_error()
        self._queue.append((topic, log_time, publish_time, data))

    def flush(self) -> None:
        self._raise_error()
        done = threading.Event()
        self._queue.append(done)
        while not done.wait(_BACKGROUND_POLL_S) and self._thread.is_alive():
            pass  # a thread that failed before taking ``done`` will never set it
        self._raise_error()

    def finish(self) -> None:
        self._stop.set()
        self._thread.join()
        self._raise_error()
        self._chunks.finish()

    def _raise_error(self) -> None:
        # Raised again by every later call: nothing more can reach the file.
        if self._error is not None:
            raise self._error

    def _run(self) -> None:
        queue, chunks = self._queue, self._chunks
        while True:
            stopping = self._stop.wait(_BACKGROUND_POLL_S)
            try:
                added = 0
                while queue:
                    item = queue.popleft()
                    if isinstance(item, threading.Event):
                        chunks.flush()
                        item.set()
                        continue
                    chunks.add(*item)
                    added += 1
                    if added % _BACKGROUND_BATCH == 0:
                        time.sleep(0)  # a turn for the event loop's thread
            except BaseException as error:  # noqa: BLE001 - handed to the caller's thread
                self._error = error
                while queue:  # nobody may wait for a flush that will never come
                    item = queue.popleft()
                    if isinstance(item, threading.Event):
                        item.set()
                return
            if stopping:
                return


def _checked_metadata(metadata: Mapping[str, Mapping[str, str]]) -> dict[str, dict[str, str]]:
    records: dict[str, dict[str, str]] = {}
    for name, values in metadata.items():
        if not isinstance(name, str) or not isinstance(values, Mapping):
            raise ValueError(f"metadata: expected {{name: {{key: value}}}} of strings, got {name!r}: {values!r}")
        if name == LOG_METADATA_NAME:
            raise ValueError(f"metadata: the name {LOG_METADATA_NAME!r} is reserved for the log format")
        for key, value in values.items():
            if not isinstance(key, str) or not isinstance(value, str):
                raise ValueError(f"metadata {name}.{key}: keys and values must be strings, got {value!r}")
        records[name] = dict(values)
    return records


def _finite(what: str, value: ArrayLike, shape: tuple[int | None, ...]) -> list[Any]:
    array = np.asarray(value, dtype=float)
    if array.ndim != len(shape) or any(size is not None and size != actual for size, actual in zip(shape, array.shape)):
        expected = str(tuple("n" if size is None else size for size in shape)).replace("'", "")
        raise ValueError(f"{what}: expected shape {expected}, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{what}: not finite")
    return array.tolist()
