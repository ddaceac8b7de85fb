"""The Foxglove WebSocket protocol's messages, without a socket: what the server sends, and
the client's messages checked (foxglove/ws-protocol, docs/spec.md; docs/live.md).

Server to client: JSON text (serverInfo, advertise, unadvertise, status) and binary frames
(opcode 1, messageData: uint32 subscription id, uint64 receive time in ns, the payload; little
endian). Client to server: JSON subscribe and unsubscribe; anything else a server without
client-publish capabilities receives is refused (`ClientMessageError`).
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from enum import IntEnum
from typing import Any, Final

# What Lichtblick and the npm FoxgloveClient offer, and what foxglove-sdk's servers accept.
SUBPROTOCOLS: Final = ("foxglove.websocket.v1", "foxglove.sdk.v1")

MESSAGE_ENCODING: Final = "cdr"
SCHEMA_ENCODING: Final = "ros2msg"

# A subscription id, a channel id: uint32 on the wire.
MAX_ID: Final = 0xFFFFFFFF
# More subscriptions than this from one client is not a viewer but a fault.
MAX_SUBSCRIPTIONS: Final = 4096


class BinaryOpcode(IntEnum):
    """Server-to-client binary frames."""

    MESSAGE_DATA = 1
    TIME = 2
    SERVICE_CALL_RESPONSE = 3
    FETCH_ASSET_RESPONSE = 4


class StatusLevel(IntEnum):
    """A status message's level."""

    INFO = 0
    WARNING = 1
    ERROR = 2


_MESSAGE_HEADER: Final = struct.Struct("<BIQ")
_ASSET_HEADER: Final = struct.Struct("<BIBI")
_CLIENT_MESSAGE_HEADER: Final = struct.Struct("<BI")
CLIENT_MESSAGE_DATA: Final = 1  # a client's binary opcode for a message it publishes
CLIENT_SERVICE_CALL: Final = 2  # ... and for a service call request
_SERVICE_HEADER: Final = struct.Struct("<BIII")
# A mesh's URI is a path: longer than this is not one.
MAX_URI_CHARS: Final = 4096


class ClientMessageError(ValueError):
    """A frame from a client that is not a message this server takes."""


@dataclass(frozen=True)
class ChannelInfo:
    """One advertised channel."""

    id: int
    topic: str
    schema_name: str
    schema: str


@dataclass(frozen=True)
class Subscribe:
    """subscribe: (subscription id, channel id) pairs."""

    subscriptions: tuple[tuple[int, int], ...]


@dataclass(frozen=True)
class Unsubscribe:
    """unsubscribe: subscription ids."""

    subscription_ids: tuple[int, ...]


@dataclass(frozen=True)
class FetchAsset:
    """fetchAsset: a file by URI, answered under the request id."""

    uri: str
    request_id: int


@dataclass(frozen=True)
class ClientChannel:
    """A channel a client advertises to publish on (client publish)."""

    id: int
    topic: str
    encoding: str
    schema_name: str


@dataclass(frozen=True)
class ClientAdvertise:
    """advertise (from a client): the channels it will publish on."""

    channels: tuple[ClientChannel, ...]


@dataclass(frozen=True)
class ClientUnadvertise:
    """unadvertise (from a client): channels it no longer publishes on."""

    channel_ids: tuple[int, ...]


@dataclass(frozen=True)
class ClientPublish:
    """A binary message from a client on one of its channels."""

    channel_id: int
    payload: bytes


@dataclass(frozen=True)
class ServiceCallRequest:
    """A binary service call from a client."""

    service_id: int
    call_id: int
    encoding: str
    payload: bytes


ClientMessage = (
    Subscribe
    | Unsubscribe
    | FetchAsset
    | ClientAdvertise
    | ClientUnadvertise
    | ClientPublish
    | ServiceCallRequest
)


def _text(message: dict[str, Any]) -> str:
    return json.dumps(message, separators=(",", ":"), allow_nan=False)


def server_info(
    name: str,
    session_id: str,
    metadata: dict[str, str],
    capabilities: list[str],
    encodings: list[str],
) -> str:
    """serverInfo: the capabilities (`assets`: the robot's meshes, `clientPublish`: teleop)
    and the encodings a client may publish in."""
    return _text(
        {
            "op": "serverInfo",
            "name": name,
            "capabilities": capabilities,
            "supportedEncodings": encodings,
            "metadata": metadata,
            "sessionId": session_id,
        }
    )


def advertise(channels: list[ChannelInfo]) -> str:
    """advertise: the channels with their ROS 2 message definitions."""
    return _text(
        {
            "op": "advertise",
            "channels": [
                {
                    "id": channel.id,
                    "topic": channel.topic,
                    "encoding": MESSAGE_ENCODING,
                    "schemaName": channel.schema_name,
                    "schema": channel.schema,
                    "schemaEncoding": SCHEMA_ENCODING,
                }
                for channel in channels
            ],
        }
    )


def unadvertise(channel_ids: list[int]) -> str:
    """unadvertise: channels gone."""
    return _text({"op": "unadvertise", "channelIds": channel_ids})


def status(level: StatusLevel, message: str) -> str:
    """status: a line for the client's problems panel."""
    return _text({"op": "status", "level": int(level), "message": message})


def message_data(subscription_id: int, receive_ns: int, payload: bytes) -> bytes:
    """messageData: one message on one of the client's subscriptions."""
    return _MESSAGE_HEADER.pack(BinaryOpcode.MESSAGE_DATA, subscription_id, receive_ns) + payload


def fetch_asset_response(request_id: int, data: bytes | None, error: str = "") -> bytes:
    """fetchAssetResponse: the file's bytes, or (data None) the reason it is refused."""
    message = error.encode()
    status = 0 if data is not None else 1
    header = _ASSET_HEADER.pack(BinaryOpcode.FETCH_ASSET_RESPONSE, request_id, status, len(message))
    return header + message + (data or b"")


def service_call_response(service_id: int, call_id: int, encoding: str, payload: bytes) -> bytes:
    """serviceCallResponse: the answer to a call, in the call's encoding."""
    name = encoding.encode()
    header = _SERVICE_HEADER.pack(
        BinaryOpcode.SERVICE_CALL_RESPONSE, service_id, call_id, len(name)
    )
    return header + name + payload


def service_call_failure(service_id: int, call_id: int, message: str) -> str:
    """serviceCallFailure: why a call was not answered."""
    return _text(
        {"op": "serviceCallFailure", "serviceId": service_id, "callId": call_id, "message": message}
    )


def _uint32(value: object, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_ID:
        raise ClientMessageError(f"{what} must be an integer 0..{MAX_ID}, not {value!r:.40}")
    return value


def _list(message: dict[str, Any], key: str) -> list[Any]:
    value = message.get(key)
    if not isinstance(value, list):
        raise ClientMessageError(f"{message.get('op')}: {key!r} must be a list")
    if len(value) > MAX_SUBSCRIPTIONS:
        raise ClientMessageError(f"{message.get('op')}: more than {MAX_SUBSCRIPTIONS} {key}")
    return value


def _service_call(frame: bytes) -> ServiceCallRequest:
    if len(frame) < _SERVICE_HEADER.size:
        raise ClientMessageError("service call: shorter than its header")
    _, service_id, call_id, length = _SERVICE_HEADER.unpack_from(frame)
    end = _SERVICE_HEADER.size + length
    if length > 64 or end > len(frame):
        raise ClientMessageError("service call: a bad encoding length")
    try:
        encoding = frame[_SERVICE_HEADER.size : end].decode("ascii")
    except UnicodeDecodeError as err:
        raise ClientMessageError("service call: the encoding is not ASCII") from err
    return ServiceCallRequest(service_id, call_id, encoding, frame[end:])


def parse_client_message(frame: str | bytes) -> ClientMessage:
    """One frame from a client; ClientMessageError says why it is refused."""
    if isinstance(frame, bytes):
        if frame[:1] == bytes([CLIENT_SERVICE_CALL]):
            return _service_call(frame)
        if len(frame) < _CLIENT_MESSAGE_HEADER.size or frame[0] != CLIENT_MESSAGE_DATA:
            raise ClientMessageError("binary frame: not a message (opcode 1, channel id)")
        _, channel_id = _CLIENT_MESSAGE_HEADER.unpack_from(frame)
        return ClientPublish(channel_id, frame[_CLIENT_MESSAGE_HEADER.size :])
    try:
        message = json.loads(frame)
    except (json.JSONDecodeError, RecursionError) as err:
        raise ClientMessageError(f"not JSON: {err}") from err
    if not isinstance(message, dict):
        raise ClientMessageError("not a JSON object")
    op = message.get("op")
    if op == "subscribe":
        pairs = []
        for entry in _list(message, "subscriptions"):
            if not isinstance(entry, dict):
                raise ClientMessageError("subscribe: each subscription must be an object")
            pairs.append(
                (
                    _uint32(entry.get("id"), "subscription id"),
                    _uint32(entry.get("channelId"), "channel id"),
                )
            )
        return Subscribe(tuple(pairs))
    if op == "unsubscribe":
        ids = tuple(
            _uint32(value, "subscription id") for value in _list(message, "subscriptionIds")
        )
        return Unsubscribe(ids)
    if op == "fetchAsset":
        uri = message.get("uri")
        if not isinstance(uri, str) or len(uri) > MAX_URI_CHARS:
            raise ClientMessageError(f"fetchAsset: 'uri' must be a string of <= {MAX_URI_CHARS}")
        return FetchAsset(uri, _uint32(message.get("requestId"), "request id"))
    if op == "advertise":
        channels = []
        for entry in _list(message, "channels"):
            if not isinstance(entry, dict):
                raise ClientMessageError("advertise: each channel must be an object")
            texts = [entry.get(key) for key in ("topic", "encoding", "schemaName")]
            if not all(isinstance(text, str) and len(text) <= MAX_URI_CHARS for text in texts):
                raise ClientMessageError("advertise: topic, encoding and schemaName are strings")
            topic, encoding, schema_name = (str(text) for text in texts)
            channels.append(
                ClientChannel(_uint32(entry.get("id"), "channel id"), topic, encoding, schema_name)
            )
        return ClientAdvertise(tuple(channels))
    if op == "unadvertise":
        ids = tuple(_uint32(value, "channel id") for value in _list(message, "channelIds"))
        return ClientUnadvertise(ids)
    raise ClientMessageError(f"operation {op!r:.40} is not supported by this server")
