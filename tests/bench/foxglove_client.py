"""A minimal client of the Foxglove WebSocket protocol, standard library only: what
Foxglove or Lichtblick does to watch a live session, enough for the tests.

RFC 6455 framing (client frames masked, no fragmentation or extensions) and of the
protocol: the server's JSON ``serverInfo`` and ``advertise`` operations, the client's
``subscribe``, and the binary ``messageData`` (opcode 1, subscription id u32, log time
u64 ns, payload), all little-endian.
"""

from __future__ import annotations

import base64
import json
import os
import socket
import struct
import time
from dataclasses import dataclass
from typing import Any

SUBPROTOCOL = "foxglove.sdk.v1"  # the one the Foxglove SDK's server speaks
_TEXT, _BINARY, _CLOSE, _PING = 0x1, 0x2, 0x8, 0x9
_MESSAGE_DATA = 0x01


@dataclass(frozen=True)
class Message:
    topic: str
    log_time_ns: int
    data: dict[str, Any]


class FoxgloveClient:
    """A connection to ``ws://host:port``; a context manager."""

    def __init__(self, host: str, port: int, timeout_s: float = 10.0) -> None:
        self.timeout_s = timeout_s
        self.socket = socket.create_connection((host, port), timeout=timeout_s)
        key = base64.b64encode(os.urandom(16)).decode()
        self.socket.sendall((f"GET / HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
                             f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                             f"Sec-WebSocket-Protocol: {SUBPROTOCOL}\r\n\r\n").encode())
        response = b""
        while not response.endswith(b"\r\n\r\n"):
            response += self._exactly(1)
        status = response.split(b"\r\n", 1)[0]
        if b" 101 " not in status:
            raise ConnectionError(f"handshake refused: {status.decode()}")
        self.channels: dict[int, dict[str, Any]] = {}  # channel id -> its advertisement
        self._subscriptions: dict[int, str] = {}  # subscription id -> topic

    def subscribe(self, topics: set[str], timeout_s: float = 10.0) -> None:
        """Subscribe to ``topics`` once the server has advertised them all."""
        deadline = time.monotonic() + timeout_s
        while not topics <= {channel["topic"] for channel in self.channels.values()}:
            if time.monotonic() > deadline:
                raise TimeoutError(f"never advertised: {sorted(topics - {c['topic'] for c in self.channels.values()})}")
            self._next()
        subscriptions = []
        for channel_id, channel in self.channels.items():
            if channel["topic"] in topics:
                subscription = len(self._subscriptions) + 1
                self._subscriptions[subscription] = channel["topic"]
                subscriptions.append({"id": subscription, "channelId": channel_id})
        self._send_text(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))

    def receive(self, timeout_s: float) -> Message:
        """The next message on a subscribed topic."""
        deadline = time.monotonic() + timeout_s
        try:
            while (remaining_s := deadline - time.monotonic()) > 0:
                self.socket.settimeout(remaining_s)
                message = self._next()
                if message is not None:
                    return message
        except TimeoutError:
            pass
        raise TimeoutError(f"no message within {timeout_s} s")

    def _next(self) -> Message | None:
        opcode, payload = self._frame()
        if opcode == _TEXT:
            operation = json.loads(payload)
            if operation["op"] == "advertise":
                self.channels.update({channel["id"]: channel for channel in operation["channels"]})
        elif opcode == _BINARY and payload[0] == _MESSAGE_DATA:
            subscription, log_time_ns = struct.unpack_from("<IQ", payload, 1)
            return Message(self._subscriptions[subscription], log_time_ns, json.loads(payload[13:]))
        elif opcode == _CLOSE:
            raise ConnectionError("the server closed the connection")
        return None

    def _frame(self) -> tuple[int, bytes]:
        (first,) = self._exactly(1)
        # A frame begun is read whole: a short wait for the next frame must not cut one.
        self.socket.settimeout(self.timeout_s)
        (second,) = self._exactly(1)
        length = second & 0x7F
        if length == 126:
            (length,) = struct.unpack(">H", self._exactly(2))
        elif length == 127:
            (length,) = struct.unpack(">Q", self._exactly(8))
        payload = self._exactly(length)
        if first & 0x0F == _PING:
            self._send(0xA, payload)  # pong
        return first & 0x0F, payload

    def _send_text(self, text: str) -> None:
        self._send(_TEXT, text.encode())

    def _send(self, opcode: int, data: bytes) -> None:
        mask = os.urandom(4)
        if len(data) < 126:
            header = struct.pack(">BB", 0x80 | opcode, 0x80 | len(data))
        else:
            header = struct.pack(">BBH", 0x80 | opcode, 0x80 | 126, len(data))
        self.socket.sendall(header + mask + bytes(byte ^ mask[index % 4] for index, byte in enumerate(data)))

    def _exactly(self, size: int) -> bytes:
        data = b""
        while len(data) < size:
            chunk = self.socket.recv(size - len(data))
            if not chunk:
                raise ConnectionError("the server closed the connection")
            data += chunk
        return data

    def __enter__(self) -> FoxgloveClient:
        return self

    def __exit__(self, *exc_info: object) -> None:
        try:
            self._send(_CLOSE, struct.pack(">H", 1000))  # normal closure
        except OSError:
            pass  # the server is gone already
        self.socket.close()
