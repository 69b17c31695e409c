"""A Foxglove WebSocket client for the tests: the SDK's subprotocol, spoken by hand (not coassist).

``foxglove.sdk.v1``: the server sends JSON text frames (``serverInfo``, ``advertise`` with each
channel's id, topic, encoding, schema name, schema encoding and schema) and binary frames of
data, ``0x01 | u32 LE subscription id | u64 LE log time [ns] | payload``; the client sends
``{"op": "subscribe", "subscriptions": [{"id", "channelId"}]}``. Received messages are
collected on a thread as (topic, log time, payload).
"""

from __future__ import annotations

import base64
import json
import struct
import threading
import time
from typing import Any

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01


class FoxgloveClient:
    """Connect to ``url``, read the server's channels; :meth:`subscribe`, then :attr:`messages`."""

    def __init__(self, url: str, timeout: float = 10.0) -> None:
        self._connection = connect(url, subprotocols=[SUBPROTOCOL], open_timeout=timeout, max_size=None)
        self.ws = self._connection.__enter__()
        assert self.ws.subprotocol == SUBPROTOCOL
        self.server_info: dict[str, Any] = {}
        self.channels: dict[str, dict[str, Any]] = {}  # topic -> the advertised channel
        end = time.monotonic() + timeout
        while not (self.server_info and self.channels):
            if time.monotonic() > end:
                raise TimeoutError(f"no serverInfo/advertise from {url}")
            self._control(json.loads(self.ws.recv(timeout=timeout)))
        self._by_subscription: dict[int, str] = {}
        self.messages: list[tuple[str, int, bytes]] = []
        self.bad_frames: list[bytes] = []
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None

    def _control(self, msg: dict[str, Any]) -> None:
        if msg.get("op") == "serverInfo":
            self.server_info = msg
        elif msg.get("op") == "advertise":
            for ch in msg["channels"]:
                self.channels[ch["topic"]] = ch

    def schema(self, topic: str) -> bytes:
        """The advertised schema's bytes (base64 for a binary schema encoding such as protobuf)."""
        ch = self.channels[topic]
        text = ch["schema"]
        return base64.b64decode(text) if ch["schemaEncoding"] in ("protobuf", "flatbuffer") else text.encode()

    def subscribe(self, topics: list[str]) -> None:
        subs = []
        for i, topic in enumerate(topics, start=1):
            self._by_subscription[i] = topic
            subs.append({"id": i, "channelId": self.channels[topic]["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        while True:
            try:
                frame = self.ws.recv()
            except (ConnectionClosed, OSError):
                return
            if isinstance(frame, str):
                self._control(json.loads(frame))
                continue
            if frame[0] != MESSAGE_DATA or len(frame) < 13:
                self.bad_frames.append(frame)
                continue
            sub, log_time = struct.unpack_from("<IQ", frame, 1)
            with self._lock:
                self.messages.append((self._by_subscription.get(sub, f"?{sub}"), log_time, frame[13:]))

    def of(self, topic: str) -> list[tuple[int, bytes]]:
        """(log time, payload) of every message received on ``topic`` so far."""
        with self._lock:
            return [(t, p) for top, t, p in self.messages if top == topic]

    def close(self) -> None:
        self._connection.__exit__(None, None, None)
        if self._thread is not None:
            self._thread.join(5)
