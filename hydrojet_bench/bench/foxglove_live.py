"""`FoxgloveLive`: a running session's log, streamed to Foxglove or Lichtblick over the
Foxglove WebSocket protocol, by the Foxglove SDK's server.

Every log topic is a channel, advertised as the server starts, with the schema the log
writes for it, and carries the log's own JSON messages at their log times (ns since the
Unix epoch): a layout made for a session log (docs/foxglove/hydrojet.json) shows the live
session too. The server listens on loopback by default: it has no authentication.
"""

from __future__ import annotations

from types import TracebackType

import foxglove

from ..errors import UserError
from ..logs import TOPICS
from ..logs.format import MESSAGE_ENCODING, SCHEMA_ENCODING
from ..logs.schemas import schema_name, topic_schema_json

LOOPBACK = "127.0.0.1"


class FoxgloveLive:
    """The server, a context manager: started on entering, stopped on leaving by any path.

    port: TCP port to listen on, 0 for any free one (then read `port`).
    host: address to listen on.
    """

    def __init__(self, port: int, host: str = LOOPBACK) -> None:
        self.host = host
        self._requested_port = port
        self._server: foxglove.WebSocketServer | None = None
        self._context: foxglove.Context | None = None
        self._channels: dict[str, foxglove.Channel] = {}

    @property
    def port(self) -> int:
        """The port the server listens on."""
        if self._server is None:
            raise ValueError("the Foxglove server is not running")
        return self._server.port

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def publish(self, topic: str, log_time_ns: int, data: bytes) -> None:
        """Send one log message (JSON bytes of ``topic``'s record) to subscribed clients."""
        self._channels[topic].log(data, log_time=log_time_ns)

    def __enter__(self) -> FoxgloveLive:
        # Kept: the SDK forgets a context's channels once the Python object is collected.
        self._context = context = foxglove.Context()
        try:
            self._server = foxglove.start_server(name="HydroJet Bench", host=self.host, port=self._requested_port,
                                                 context=context)
        except RuntimeError as error:  # the SDK's FoxgloveError, e.g. the port taken
            raise UserError(f"--foxglove {self.host}:{self._requested_port}: cannot listen: {error}") from None
        try:
            self._channels = {
                topic: foxglove.Channel(topic, message_encoding=MESSAGE_ENCODING, context=context,
                                        schema=foxglove.Schema(name=schema_name(record), encoding=SCHEMA_ENCODING,
                                                               data=topic_schema_json(record)))
                for topic, record in TOPICS.items()}
        except BaseException:
            self._server.stop()
            raise
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 traceback: TracebackType | None) -> None:
        server, self._server = self._server, None
        for channel in self._channels.values():
            channel.close()
        self._channels = {}
        self._context = None
        if server is not None:
            server.stop()
