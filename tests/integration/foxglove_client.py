"""A minimal Foxglove WebSocket client (subprotocol ``foxglove.sdk.v1``, or another one asked
for) on tornado's client, written from the protocol's documented messages, not from our server
code: it reads ``serverInfo`` and ``advertise`` (JSON text), subscribes to every advertised
channel and keeps each binary ``messageData`` frame (opcode 1, u32 subscription id, u64 log
time, payload). :meth:`FoxgloveClient.decode` reads a protobuf payload with the channel's
advertised schema (a base64 FileDescriptorSet) through ``mcap-protobuf-support``.

Runs its own asyncio loop in a thread; used by tests/integration/test_live_view.py and
benchmarks/live_view_jitter.py. Connects to 127.0.0.1 only.
"""

from __future__ import annotations

import asyncio
import json
import struct
import threading
import time

_MESSAGE_DATA = 1
_HEADER = struct.Struct("<BIQ")


class FoxgloveClient:
    """Collect the messages of every channel of ``ws://127.0.0.1:<port>``."""

    def __init__(self, port: int, *, connect_timeout_s: float = 10.0,
                 subprotocol: str = "foxglove.sdk.v1") -> None:
        self.url = f"ws://127.0.0.1:{port}"
        self.subprotocol = subprotocol
        self.connect_timeout_s = connect_timeout_s
        self.channels: dict[int, dict] = {}          # channel id → advertised channel
        self.messages: list[tuple[str, int, bytes]] = []   # (topic, log time ns, payload)
        self.subscribed = threading.Event()
        self.error: BaseException | None = None
        self._topics_by_sub: dict[int, str] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fg-client", daemon=True)

    def start(self) -> FoxgloveClient:
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)

    def __enter__(self) -> FoxgloveClient:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    def topic_messages(self, topic: str) -> list[tuple[int, bytes]]:
        return [(t, data) for top, t, data in list(self.messages) if top == topic]

    def decode(self, topic: str, data: bytes):
        """A protobuf message of ``topic`` decoded with its advertised schema."""
        import base64

        from mcap.records import Schema
        from mcap_protobuf.decoder import DecoderFactory

        (channel,) = [c for c in self.channels.values() if c["topic"] == topic]
        assert channel["encoding"] == "protobuf", channel
        schema = Schema(id=1, name=channel["schemaName"], encoding="protobuf",
                        data=base64.b64decode(channel["schema"]))
        return DecoderFactory().decoder_for("protobuf", schema)(data)

    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as exc:  # noqa: BLE001 - reported to the test
            self.error = exc
            self.subscribed.set()

    async def _connect(self):
        from tornado.websocket import websocket_connect

        deadline = time.monotonic() + self.connect_timeout_s
        while True:   # the server may not be up yet (a subprocess starting)
            try:
                return await websocket_connect(self.url, subprotocols=[self.subprotocol])
            except OSError:
                if time.monotonic() > deadline or self._stop.is_set():
                    raise
                await asyncio.sleep(0.05)

    async def _main(self) -> None:
        ws = await self._connect()
        try:
            while not self._stop.is_set():
                try:
                    msg = await asyncio.wait_for(ws.read_message(), 0.2)
                except asyncio.TimeoutError:
                    continue
                if msg is None:
                    return
                if isinstance(msg, str):
                    await self._control(ws, json.loads(msg))
                elif msg[0] == _MESSAGE_DATA:
                    _, sub_id, log_time = _HEADER.unpack_from(msg, 0)
                    self.messages.append((self._topics_by_sub.get(sub_id, "?"), log_time,
                                          bytes(msg[_HEADER.size:])))
        finally:
            ws.close()

    async def _control(self, ws, op: dict) -> None:
        if op.get("op") != "advertise":
            return
        subs = []
        for channel in op["channels"]:
            self.channels[channel["id"]] = channel
            sub_id = len(self._topics_by_sub) + 1
            self._topics_by_sub[sub_id] = channel["topic"]
            subs.append({"id": sub_id, "channelId": channel["id"]})
        await ws.write_message(json.dumps({"op": "subscribe", "subscriptions": subs}))
        self.subscribed.set()
