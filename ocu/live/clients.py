"""The live server's clients: each one's subscriptions, counters and bounded outbox (the
relay process's loop only, ocu.live.relay)."""

from __future__ import annotations

import asyncio
from collections import deque
from dataclasses import dataclass
from typing import Final

from websockets.asyncio.server import ServerConnection

from ocu.live import wire

# Per client: bytes of messages waiting for its socket (beside the socket's own write buffer).
DEFAULT_CLIENT_BUFFER_BYTES: Final = 4 * 1024 * 1024
# Control messages (serverInfo, advertise, status) a client has not read: more is a fault.
MAX_CONTROL_BYTES: Final = 1024 * 1024
# Mesh files on their way to one client (fetchAsset): more is answered "busy".
MAX_ASSET_BYTES: Final = 32 * 1024 * 1024
DATA, CONTROL, ASSET = 0, 1, 2  # what waits in a client's outbox


@dataclass(frozen=True)
class ClientStats:
    """One connected client."""

    address: str
    subscriptions: int
    sent: int
    dropped: int
    refused: int
    queued_bytes: int
    peak_queued_bytes: int


@dataclass(frozen=True)
class LiveStats:
    """The server's counters now."""

    clients: tuple[ClientStats, ...]
    connections: int
    unauthorized: int
    closed_for_refused: int
    queue_dropped: int
    # Connections refused because max_clients were connected.
    crowded: int


class Client:
    """One connection's subscriptions and bounded outbox (the loop thread's only)."""

    def __init__(self, connection: ServerConnection, buffer_bytes: int) -> None:
        self.connection = connection
        remote = connection.remote_address
        self.address = f"{remote[0]}:{remote[1]}" if remote else "?"
        self.buffer_bytes = buffer_bytes
        self.subscriptions: dict[int, int] = {}
        self.by_channel: dict[int, set[int]] = {}
        # (frame, size, kind): DATA may be dropped, CONTROL and ASSET are bounded apart.
        self.outbox: deque[tuple[str | bytes, int, int]] = deque()
        self.data_bytes = 0
        self.control_bytes = 0
        self.asset_bytes = 0
        self.wake = asyncio.Event()
        # Set by the send loop whenever the outbox is empty (all of it on the socket).
        self.flushed = asyncio.Event()
        self.sent = 0
        self.dropped = 0
        self.refused = 0
        self.closing = False
        self.peak_bytes = 0
        self.published: dict[int, wire.ClientChannel] = {}
        self.last_warning = ""

    def queue_data(self, frame: bytes) -> None:
        if self.data_bytes + len(frame) > self.buffer_bytes:
            self.dropped += 1
            return
        self.outbox.append((frame, len(frame), DATA))
        self.data_bytes += len(frame)
        self.peak_bytes = max(self.peak_bytes, self.data_bytes + self.control_bytes)
        self.wake.set()

    def queue_control(self, text: str | bytes) -> bool:
        """Queue a control message (a service's answer too); False when the client has left
        too many unread."""
        if self.control_bytes + len(text) > MAX_CONTROL_BYTES:
            return False
        self.outbox.append((text, len(text), CONTROL))
        self.control_bytes += len(text)
        self.wake.set()
        return True

    def queue_asset(self, frame: bytes) -> bool:
        """Queue a fetchAsset answer; False when too many bytes of them are on their way."""
        if self.asset_bytes + len(frame) > MAX_ASSET_BYTES:
            return False
        self.outbox.append((frame, len(frame), ASSET))
        self.asset_bytes += len(frame)
        self.wake.set()
        return True

    def unqueued(self, size: int, kind: int) -> None:
        """A frame of `size` bytes left the outbox for the socket."""
        if kind == CONTROL:
            self.control_bytes -= size
        elif kind == ASSET:
            self.asset_bytes -= size
        else:
            self.data_bytes -= size

    def stats(self) -> ClientStats:
        return ClientStats(
            self.address,
            len(self.subscriptions),
            self.sent,
            self.dropped,
            self.refused,
            self.data_bytes + self.control_bytes,
            self.peak_bytes,
        )
