"""Session logs: everything a bench session does, in one MCAP file.

* `LogWriter` records typed messages, one record type per topic (`TOPICS`, in
  `hydrojet_bench.logs.topics`; `/tf` and `/scene/backbone` carry Foxglove's messages),
  as JSON with a JSON schema generated from the type, chunked and flushed every
  ``flush_interval_s`` of wall time (a session: 0.25 s of session time) so that a killed
  session loses that much at most; a session's writer adds to the chunks on a thread of its own.
* `read_log` and `read_metadata` read complete, truncated and damaged logs alike: a
  damaged chunk or an unreadable message is skipped, and `LogContents.damage` says what
  was lost; a topic none of whose messages its type can read raises `LogError` naming
  the topic and field.
* `recover_log` rewrites a truncated or damaged log into a valid, finished MCAP file.
* `dataset_from_log` turns the ``/bench/sample`` messages into a `Dataset` for analysis.
"""

from .codec import LogError
from .dataset import SAMPLE_TOPIC, dataset_from_log
from .log_record import LogRecord, floats
from .reader import LogContents, LogDamage, read_log, read_metadata
from .recovery import RecoveryReport, recover_log, recovered_path
from .topics import TOPICS
from .writer import LogWriter

__all__ = [
    "SAMPLE_TOPIC", "TOPICS", "LogContents", "LogDamage", "LogError", "LogRecord", "LogWriter", "RecoveryReport",
    "dataset_from_log", "floats", "read_log", "read_metadata", "recover_log", "recovered_path",
]
