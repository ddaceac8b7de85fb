"""The console's live server and its relay process (ocu.live.relay) over a socket pair.

Each message is a 4-byte big-endian length and a pickle of a tuple whose first item is its
kind. Both ends are this program (the relay is started by the console on its own socket
pair), so pickle carries nothing from outside: the relay parses what clients send
(ocu.live.wire) and forwards the checked dataclasses.

Console -> relay:
- (LISTEN, Listen): the robot, then bind and serve (what comes before it is applied first);
- (HELLO, server_info, services): the serverInfo text each new client gets, and the
  advertiseServices text (or None);
- (ITEMS, [Item], dropped): the link's items (ocu.record.convert), encoded in the relay
  (ocu.live.encoding); `dropped`: items the console's queue lost so far;
- (PUBLISH, mono, topic, message dict): one of the console's own messages (odometry, the
  scene), encoded in the relay;
- (ENCODED, topic, log ns, payload): one message encoded already (the map);
- (TO, client id, text): a control message for one client (0: every client);
- (REFUSED, client id, count): frames the console refused (the relay closes the client at
  MAX_REFUSED);
- (STATS, request id): the relay answers with its counters;
- (STOP,): close every client and end.

Relay -> console:
- (READY, port) or (FAILED, reason) once, after the bind;
- (JOINED, client id, address, subprotocol), (LEFT, client id, sent, dropped, refused);
- (SUBSCRIBED, frozenset of topics): the topics someone subscribes to, on change;
- (INPUT, client id, message): a ClientAdvertise, ClientUnadvertise or ClientPublish;
- (CALL, client id, ServiceCallRequest);
- (STATS, request id, LiveStats) (its queue_dropped the relay's own drops).
"""

from __future__ import annotations

import asyncio
import pickle
import struct
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

if TYPE_CHECKING:
    from ocu.live.robot import RobotFrames
    from ocu.profile import RobotProfile

LISTEN: Final = "listen"
HELLO: Final = "hello"
ITEMS: Final = "items"
PUBLISH: Final = "publish"
ENCODED: Final = "encoded"
TO: Final = "to"
REFUSED: Final = "refused"
STATS: Final = "stats"
STOP: Final = "stop"
READY: Final = "ready"
FAILED: Final = "failed"
JOINED: Final = "joined"
LEFT: Final = "left"
SUBSCRIBED: Final = "subscribed"
INPUT: Final = "input"
CALL: Final = "call"

EVERYONE: Final = 0
HEADER: Final = struct.Struct(">I")
# A camera frame is well under this; more is a fault of the other end.
MAX_MESSAGE_BYTES: Final = 64 * 1024 * 1024


@dataclass(frozen=True)
class Listen:
    """The robot, and where and how the relay serves."""

    profile: RobotProfile
    frames: RobotFrames | None
    # The console's mapping of its monotonic clock to the wall clock, and its clock now.
    mono0: float
    wall0_ns: int
    now: float
    host: str
    port: int
    token: str | None
    client_buffer_bytes: int
    max_clients: int
    assets: dict[str, str]  # URI -> file: the robot's own meshes, nothing else


class PipeError(RuntimeError):
    """The other end sent something that is not a message of this pipe."""


def pack(message: tuple[Any, ...]) -> bytes:
    """One message as it goes on the pipe."""
    body = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    return HEADER.pack(len(body)) + body


async def receive(reader: asyncio.StreamReader) -> tuple[Any, ...] | None:
    """The next message; None when the other end has closed."""
    try:
        head = await reader.readexactly(HEADER.size)
        (size,) = HEADER.unpack(head)
        if size > MAX_MESSAGE_BYTES:
            raise PipeError(f"a message of {size} bytes")
        body = await reader.readexactly(size)
    except (asyncio.IncompleteReadError, ConnectionError):
        return None
    message = pickle.loads(body)
    if not isinstance(message, tuple) or not message or not isinstance(message[0], str):
        raise PipeError(f"not a message: {type(message).__name__}")
    return message
