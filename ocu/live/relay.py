"""The live server's relay: the WebSocket side, in a process of its own (docs/live.md).

`python -m ocu.live.relay FD` is started by the console's LiveServer on one end of a socket
pair (ocu.live.pipe). It binds the address, checks tokens, holds every client's subscriptions
and bounded outbox, answers fetchAsset from the robot's own meshes, encodes what the console
hands it (the link's items, the console's message dicts: ocu.live.encoding) once per message
and fans each out to the clients subscribed to its channel. What a client publishes and the
services it calls go to the console, which owns the robot.

Why a process: the encoding (CDR, the URDF tree's transforms at the telemetry rate) and the
per-client work (framing, the socket writes, a client's frames parsed) are Python; in the
console's interpreter they took the GIL from the operator's key path (bench/bench_live.py
--keys). Here the console only pickles the items, and the relay runs at the default
priority, behind the console's.

The relay ends when the console says STOP or when the pipe closes (the console has gone):
an orphan must not keep serving a robot nobody drives.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import hmac
import logging
import socket
import sys
from collections.abc import Sequence
from http import HTTPStatus
from pathlib import Path
from typing import Any, Final
from urllib.parse import parse_qs, urlsplit

from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from ocu.live import pipe, wire
from ocu.live.clients import Client, LiveStats
from ocu.live.encoding import Channel, Encoding

log = logging.getLogger("ocu.live.relay")

# Refused frames before a client is closed.
MAX_REFUSED: Final = 10
# A client only subscribes and publishes small messages: no frame of its needs more.
MAX_CLIENT_FRAME_BYTES: Final = 64 * 1024
# The socket's own write buffer (websockets' high-water mark).
WRITE_LIMIT_BYTES: Final = 64 * 1024
TOKEN_PARAMETER: Final = "token"
CLOSE_POLICY: Final = 1008


class Relay:
    """The WebSocket side of one live server (the relay process's loop only)."""

    def __init__(self, writer: asyncio.StreamWriter, listen: pipe.Listen) -> None:
        self.writer = writer
        self.token = listen.token
        self.client_buffer_bytes = listen.client_buffer_bytes
        self.max_clients = listen.max_clients
        self.assets = {uri: Path(file) for uri, file in listen.assets.items()}
        self.info = ""
        self.services: str | None = None
        self.clients: dict[int, Client] = {}
        self._ids: dict[Client, int] = {}
        self._next_id = 1
        self._subscribed: frozenset[int] = frozenset()
        self._closing: set[asyncio.Future[None]] = set()
        self.connections = 0
        self.unauthorized = 0
        self.closed_for_refused = 0
        self.crowded = 0
        mono0, wall0_ns = listen.mono0, listen.wall0_ns
        self.encoding = Encoding(
            listen.profile,
            listen.frames,
            lambda mono: wall0_ns + round((mono - mono0) * 1e9),
            listen.now,
            fan_out=self.fan_out,
            subscribed=lambda channel_id: channel_id in self._subscribed,
            advertise=self._advertise,
        )

    def tell(self, *message: Any) -> None:
        """A message to the console (never waits: the pipe's buffer takes it)."""
        self.writer.write(pipe.pack(message))

    # ---- the console's messages ------------------------------------------------------------

    def on_console(self, message: tuple[Any, ...]) -> None:
        kind = message[0]
        if kind == pipe.ITEMS:
            self.encoding.serve(message[1], message[2])
        elif kind == pipe.PUBLISH:
            _, mono, topic, body = message
            self.encoding.publish(mono, topic, body)
        elif kind == pipe.ENCODED:
            _, topic, log_ns, payload = message
            channel = self.encoding.channels.get(topic)
            if channel is not None:
                self.encoding.encoded(channel, log_ns, payload)
        elif kind == pipe.TO:
            _, client_id, text = message
            if client_id == pipe.EVERYONE:
                for client in list(self.clients.values()):
                    self.control(client, text)
            else:
                one = self.clients.get(client_id)
                if one is not None:
                    self.control(one, text)
        elif kind == pipe.REFUSED:
            _, client_id, count = message
            refusing = self.clients.get(client_id)
            if refusing is not None:
                refusing.refused += count
                self._close_if_refused(refusing)
        elif kind == pipe.HELLO:
            _, self.info, self.services = message
        elif kind == pipe.STATS:
            self.tell(pipe.STATS, message[1], self.stats())
        else:
            log.error("relay: unknown message from the console: %r", kind)

    def fan_out(self, channel: Channel, log_ns: int, payload: bytes) -> None:
        channel_id = channel.info.id
        for client in self.clients.values():
            for subscription in client.by_channel.get(channel_id, ()):
                client.queue_data(wire.message_data(subscription, log_ns, payload))

    def _advertise(self, info: wire.ChannelInfo) -> None:
        text = wire.advertise([info])
        for client in list(self.clients.values()):
            self.control(client, text)

    def stats(self) -> LiveStats:
        return LiveStats(
            tuple(client.stats() for client in self.clients.values()),
            self.connections,
            self.unauthorized,
            self.closed_for_refused,
            0,
            self.crowded,
        )

    # ---- clients -----------------------------------------------------------------------------

    def control(self, client: Client, text: str | bytes) -> None:
        if not client.queue_control(text) and not client.closing:
            client.closing = True
            task = asyncio.ensure_future(client.connection.close(CLOSE_POLICY, "not reading"))
            self._closing.add(task)
            task.add_done_callback(self._closing.discard)

    def _close_if_refused(self, client: Client) -> None:
        if client.refused >= MAX_REFUSED and not client.closing:
            client.closing = True
            self.closed_for_refused += 1
            task = asyncio.ensure_future(self._close_refused(client))
            self._closing.add(task)
            task.add_done_callback(self._closing.discard)

    async def _close_refused(self, client: Client) -> None:
        # The reasons queued for it go out before the close, within a second.
        client.flushed.clear()
        client.wake.set()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(client.flushed.wait(), 1.0)
        await client.connection.close(CLOSE_POLICY, "too many refused messages")

    def process_request(self, connection: ServerConnection, request: Request) -> Response | None:
        if len(self.clients) >= self.max_clients:  # each costs up to its outbox
            self.crowded += 1
            text = f"{self.max_clients} clients are watching already\n"
            return connection.respond(HTTPStatus.SERVICE_UNAVAILABLE, text)
        if self.token is None:
            return None
        query = parse_qs(urlsplit(request.path).query)
        given = query.get(TOKEN_PARAMETER, [""])[0]
        header = request.headers.get("Authorization", "")
        if header.startswith("Bearer "):
            given = given or header[len("Bearer ") :]
        if given and hmac.compare_digest(given.encode(), self.token.encode()):
            return None
        self.unauthorized += 1
        log.warning("live: refused %s: no valid token", connection.remote_address)
        return connection.respond(HTTPStatus.UNAUTHORIZED, "a valid token is needed\n")

    async def handle(self, connection: ServerConnection) -> None:
        client = Client(connection, self.client_buffer_bytes)
        client_id = self._next_id
        self._next_id += 1
        self.clients[client_id] = client
        self._ids[client] = client_id
        self.connections += 1
        self.tell(pipe.JOINED, client_id, client.address, connection.subprotocol)
        self.control(client, self.info)
        channels = self.encoding.channels.values()
        self.control(client, wire.advertise([channel.info for channel in channels]))
        if self.services is not None:
            self.control(client, self.services)
        sender = asyncio.create_task(self._send_loop(client), name="ocu-live-send")
        try:
            async for frame in connection:
                self._on_frame(client_id, client, frame)
                if client.refused >= MAX_REFUSED and not client.closing:
                    client.closing = True
                    self.closed_for_refused += 1
                    await self._close_refused(client)
                    break
        except ConnectionClosed:
            pass
        finally:
            del self.clients[client_id]
            del self._ids[client]
            sender.cancel()
            self._update_subscribed()
            self.tell(pipe.LEFT, client_id, client.sent, client.dropped, client.refused)

    async def _send_loop(self, client: Client) -> None:
        try:
            while True:
                await client.wake.wait()
                client.wake.clear()
                while client.outbox:
                    frame, size, kind = client.outbox.popleft()
                    client.unqueued(size, kind)
                    await client.connection.send(frame)
                    client.sent += 1
                client.flushed.set()
        except ConnectionClosed:
            pass

    def _on_frame(self, client_id: int, client: Client, frame: str | bytes) -> None:
        try:
            message = wire.parse_client_message(frame)
        except wire.ClientMessageError as err:
            client.refused += 1
            self.control(client, wire.status(wire.StatusLevel.ERROR, str(err)))
            return
        if isinstance(message, wire.Subscribe):
            for subscription, channel_id in message.subscriptions:
                self._subscribe(client, subscription, channel_id)
            self._update_subscribed()
        elif isinstance(message, wire.FetchAsset):
            self._fetch_asset(client, message)
        elif isinstance(message, wire.ServiceCallRequest):
            self.tell(pipe.CALL, client_id, message)
        elif isinstance(
            message, wire.ClientAdvertise | wire.ClientUnadvertise | wire.ClientPublish
        ):
            self.tell(pipe.INPUT, client_id, message)
        else:
            for subscription in message.subscription_ids:
                taken = client.subscriptions.pop(subscription, None)
                if taken is None:
                    continue
                ids = client.by_channel.get(taken, set())
                ids.discard(subscription)
                if not ids:
                    client.by_channel.pop(taken, None)
            self._update_subscribed()

    def _update_subscribed(self) -> None:
        subscribed = frozenset(
            channel_id for client in self.clients.values() for channel_id in client.by_channel
        )
        if subscribed != self._subscribed:
            self._subscribed = subscribed
            by_id = self.encoding.by_id
            self.tell(pipe.SUBSCRIBED, frozenset(by_id[i].info.topic for i in subscribed))

    def _subscribe(self, client: Client, subscription: int, channel_id: int) -> None:
        problem = None
        channel = self.encoding.by_id.get(channel_id)
        if channel is None:
            problem = f"no channel {channel_id}"
        elif subscription in client.subscriptions:
            problem = f"subscription {subscription} is taken"
        elif len(client.subscriptions) >= wire.MAX_SUBSCRIPTIONS:
            problem = f"more than {wire.MAX_SUBSCRIPTIONS} subscriptions"
        if problem is not None or channel is None:
            client.refused += 1
            self.control(client, wire.status(wire.StatusLevel.ERROR, f"subscribe: {problem}"))
            return
        client.subscriptions[subscription] = channel_id
        client.by_channel.setdefault(channel_id, set()).add(subscription)
        latched = channel.latched
        if latched is not None:
            log_ns, payload = latched
            client.queue_data(wire.message_data(subscription, log_ns, payload))

    def _fetch_asset(self, client: Client, request: wire.FetchAsset) -> None:
        file = self.assets.get(request.uri)
        if file is None:
            client.refused += 1  # only the URDF's own meshes are served: a probe is a fault
            answer = wire.fetch_asset_response(
                request.request_id, None, f"{request.uri[:200]}: not a mesh of this robot"
            )
            if not client.queue_asset(answer):
                self.control(client, wire.status(wire.StatusLevel.ERROR, "fetchAsset: busy"))
            return
        task = asyncio.ensure_future(self._send_asset(client, request.request_id, file))
        self._closing.add(task)
        task.add_done_callback(self._closing.discard)

    async def _send_asset(self, client: Client, request_id: int, file: Path) -> None:
        try:
            data: bytes | None = await asyncio.to_thread(file.read_bytes)
            error = ""
        except OSError as err:
            data, error = None, f"cannot read the mesh: {err.strerror or err}"
        if not client.queue_asset(wire.fetch_asset_response(request_id, data, error)):
            busy = "busy: too many meshes on their way, ask again"
            client.queue_asset(wire.fetch_asset_response(request_id, None, busy))


async def run(sock: socket.socket) -> int:
    """Serve until the console says STOP or goes away; the exit status.

    What each client gets when it connects (HELLO, ADVERTISE) comes before LISTEN, so the
    first client already finds it.
    """
    reader, writer = await asyncio.open_unix_connection(sock=sock)
    early: list[tuple[Any, ...]] = []
    while True:
        message = await pipe.receive(reader)
        if message is None or message[0] == pipe.STOP:
            writer.close()
            return 0
        if message[0] == pipe.LISTEN:
            break
        early.append(message)
    listen: pipe.Listen = message[1]
    relay = Relay(writer, listen)
    for message in early:
        relay.on_console(message)
    host, port = listen.host, listen.port
    try:
        server: Server = await serve(
            relay.handle,
            host,
            port,
            subprotocols=[wire.SUBPROTOCOLS[0], wire.SUBPROTOCOLS[1]],  # type: ignore[list-item]
            process_request=relay.process_request,
            compression=None,
            max_size=MAX_CLIENT_FRAME_BYTES,
            write_limit=WRITE_LIMIT_BYTES,
        )
    except OSError as err:
        relay.tell(pipe.FAILED, f"cannot serve live on {host}:{port}: {err.strerror or err}")
        await writer.drain()
        return 2
    relay.tell(pipe.READY, int(server.sockets[0].getsockname()[1]))
    try:
        while True:
            message = await pipe.receive(reader)
            if message is None or message[0] == pipe.STOP:
                break
            try:
                relay.on_console(message)
            except Exception:  # one message must not end the serving of the rest
                log.exception("relay: cannot take a %s message", message[0])
    finally:
        server.close(close_connections=True)
        await server.wait_closed()
        with contextlib.suppress(ConnectionError):
            await writer.drain()
        writer.close()
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ocu.live.relay")
    parser.add_argument("fd", type=int, help="this end of the console's socket pair")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="ocu live relay: %(message)s")
    # Everything else (the address, the token: not on a command line any user can read)
    # comes on the pipe.
    return asyncio.run(run(socket.socket(fileno=args.fd)))


if __name__ == "__main__":
    sys.exit(main())
