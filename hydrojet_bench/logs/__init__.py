"""Session logs: everything a bench session does, in one MCAP file.

* `LogWriter` records messages on the topics of `TOPICS` (JSON, one JSON schema per
  topic; `/tf` and `/scene/backbone` in Foxglove's schemas), chunked and flushed once a
  second so that a killed session loses about a second at most.
* `read_log` and `read_metadata` read complete and truncated logs alike.
* `recover_log` rewrites a truncated log into a valid, finished MCAP file.
* `dataset_from_log` turns the ``/bench/sample`` messages into a `Dataset` for analysis.

The topics and their fields are documented in `hydrojet_bench.logs.schemas`.
"""

from .dataset import SAMPLE_TOPIC, dataset_from_log
from .reader import LogContents, LogMessage, read_log, read_metadata
from .recovery import RecoveryReport, recover_log, recovered_path
from .schemas import TOPICS, schema_problem
from .writer import LogWriter

__all__ = [
    "SAMPLE_TOPIC", "TOPICS", "LogContents", "LogMessage", "LogWriter", "RecoveryReport", "dataset_from_log",
    "read_log", "read_metadata", "recover_log", "recovered_path", "schema_problem",
]
