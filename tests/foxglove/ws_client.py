"""A small client of the Foxglove WebSocket protocol (``foxglove.websocket.v1``), enough to
see what a Foxglove app sees: the advertised channels, subscriptions, and each message
decoded by its channel's own schema (JSON Schema, or protobuf from the advertised
FileDescriptorSet), so a message its schema cannot read fails the test."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import struct
from collections import defaultdict
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import Any

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from websockets.asyncio.client import ClientConnection, connect
from websockets.typing import Subprotocol

SUBPROTOCOL = Subprotocol("foxglove.websocket.v1")
OP_MESSAGE_DATA = 0x01
_MESSAGE_HEAD = struct.Struct("<BIQ")


@dataclass
class Received:
    channels: dict[int, dict[str, Any]] = field(default_factory=dict)
    # topic -> decoded messages (dicts for JSON, protobuf messages otherwise)
    messages: dict[str, list[Any]] = field(default_factory=lambda: defaultdict(list))
    server_info: dict[str, Any] | None = None

    def topics(self) -> dict[str, dict[str, Any]]:
        return {channel["topic"]: channel for channel in self.channels.values()}


class FoxgloveClient:
    def __init__(self, socket: ClientConnection) -> None:
        self.socket = socket
        self.received = Received()
        self._subscriptions: dict[int, int] = {}  # subscription id -> channel id
        # the subscribe request each subscription went in (1, 2, ...), and the latest request
        # data has come for: the server takes requests in order, so those up to it are taken
        self._request_of: dict[int, int] = {}
        self._answered = 0
        self._decoders: dict[int, Callable[[bytes], Any]] = {}
        self.reader: asyncio.Task[None] | None = None

    def check(self) -> None:
        """Raise what stopped the reader (a message its schema does not describe)."""
        if self.reader is not None and self.reader.done():
            self.reader.result()
            raise AssertionError("the server closed the socket")

    async def subscribe(self, wanted: Callable[[dict[str, Any]], bool]) -> int:
        """Subscribe to every advertised channel not yet subscribed that ``wanted`` picks."""
        self.check()
        taken = set(self._subscriptions.values())
        new = [c for c in self.received.channels.values() if c["id"] not in taken and wanted(c)]
        subscriptions = []
        request = max(self._request_of.values(), default=0) + 1
        for channel in new:
            subscription_id = len(self._subscriptions) + 1
            self._subscriptions[subscription_id] = channel["id"]
            self._request_of[subscription_id] = request
            self._decoders[channel["id"]] = decoder_for(channel)
            subscriptions.append({"id": subscription_id, "channelId": channel["id"]})
        if subscriptions:
            await self.socket.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))
        return len(subscriptions)

    def taken(self, topic: str) -> bool:
        """Whether the server has taken the subscription to ``topic``: data came for one made in
        the same request or a later one (the protocol acknowledges no subscription)."""
        channel = self.received.topics().get(topic)
        made = [self._request_of[sid] for sid, cid in self._subscriptions.items()
                if channel is not None and cid == channel["id"]]
        return made != [] and self._answered >= made[0]

    async def read(self) -> None:
        async for frame in self.socket:
            if isinstance(frame, str):
                self._control(json.loads(frame))
            elif frame[0] == OP_MESSAGE_DATA:
                _, subscription_id, _ = _MESSAGE_HEAD.unpack_from(frame)
                channel_id = self._subscriptions[subscription_id]
                self._answered = max(self._answered, self._request_of[subscription_id])
                topic = self.received.channels[channel_id]["topic"]
                payload = frame[_MESSAGE_HEAD.size:]
                self.received.messages[topic].append(self._decoders[channel_id](payload))

    def _control(self, message: dict[str, Any]) -> None:
        if message["op"] == "serverInfo":
            self.received.server_info = message
        elif message["op"] == "advertise":
            for channel in message["channels"]:
                self.received.channels[channel["id"]] = channel


@contextlib.asynccontextmanager
async def foxglove_client(url: str, **headers: str) -> AsyncIterator[FoxgloveClient]:
    async with connect(url, subprotocols=[SUBPROTOCOL], additional_headers=headers,
                       max_size=None) as socket:
        assert socket.subprotocol == SUBPROTOCOL
        client = FoxgloveClient(socket)
        reader = client.reader = asyncio.create_task(client.read())
        try:
            yield client
        finally:
            reader.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await reader


def decoder_for(channel: dict[str, Any]) -> Callable[[bytes], Any]:
    if channel["encoding"] == "json":
        schema = json.loads(channel["schema"])
        check_foxglove_json_schema(schema, channel["topic"])

        def decode_json(payload: bytes) -> Any:
            value = json.loads(payload)
            check_conforms(value, schema, channel["topic"])
            return value

        return decode_json
    assert channel["encoding"] == "protobuf", channel
    assert channel["schemaEncoding"] == "protobuf", channel
    files = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for file in files.file:
        pool.Add(file)
    message_class = message_factory.GetMessageClass(
        pool.FindMessageTypeByName(channel["schemaName"])
    )
    return message_class.FromString


def check_foxglove_json_schema(schema: dict[str, Any], where: str) -> None:
    """The subset Foxglove's JSON Schema reader takes: one type per property, objects with
    properties, arrays with items, no references or alternatives."""
    kind = schema.get("type")
    assert isinstance(kind, str), f"{where}: type {kind!r}"
    assert not {"$ref", "anyOf", "oneOf", "allOf"} & schema.keys(), f"{where}: {schema}"
    if kind == "object":
        for name, sub in schema["properties"].items():
            check_foxglove_json_schema(sub, f"{where}.{name}")
    elif kind == "array":
        check_foxglove_json_schema(schema["items"], f"{where}[]")
    else:
        assert kind in ("number", "integer", "boolean", "string"), f"{where}: {kind}"


_PYTHON_TYPES: dict[str, type | tuple[type, ...]] = {
    "number": (int, float), "integer": int, "boolean": bool, "string": str,
}  # fmt: skip


def check_conforms(value: Any, schema: dict[str, Any], where: str) -> None:
    """Every field of the message is in its schema, with the schema's type (or null)."""
    if value is None:
        return
    kind = schema["type"]
    if kind == "object":
        assert isinstance(value, dict), f"{where}: {value!r}"
        properties = schema["properties"]
        if not properties:
            return  # a map (e.g. message_ages_s): keys are data
        extra = value.keys() - properties.keys()
        assert not extra, f"{where}: fields not in the schema: {extra}"
        for name, item in value.items():
            check_conforms(item, properties[name], f"{where}.{name}")
    elif kind == "array":
        assert isinstance(value, list), f"{where}: {value!r}"
        for item in value:
            check_conforms(item, schema["items"], f"{where}[]")
    else:
        assert isinstance(value, _PYTHON_TYPES[kind]), f"{where}: {value!r} is not {kind}"
