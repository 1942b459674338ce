"""Constants of the session log's MCAP layout, shared by writer, reader and recovery.

Every topic is one channel with ``message_encoding = "json"`` and a schema with
``encoding = "jsonschema"``. The file also holds one metadata record of its own,
`LOG_METADATA_NAME`, written right after the header: the format version and the
wall-clock time of ``t_s = 0`` in ns since the Unix epoch (`START_TIME_KEY`).
"""

SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "json"
LOG_METADATA_NAME = "hydrojet_bench.log"
# Written by `recover_log` at the end of a recovered copy: what its source had lost
# (``source``, ``truncated`` "true"/"false", ``damage``: one line, empty when none), so
# that every later analysis of the copy still says it.
RECOVERY_METADATA_NAME = "hydrojet_bench.recovery"
FORMAT_VERSION = "1"
START_TIME_KEY = "start_time_unix_ns"
