"""The live server: a session served over the Foxglove WebSocket protocol (docs/live.md).

The server is one more subscriber of a Link (attach()). Its callback runs on the link's
threads and only appends a small item to a bounded queue (dropped and counted when full; the
link never waits, and with no client connected it keeps only the link's state changes).
Everything else runs on the server's own thread, "ocu-live", in one asyncio loop: the items
become the recorder's ROS 2 messages (ocu.record.convert, the same CDR bytes a recording
holds) plus the robot's /tf, /tf_static, /robot_description, /scan and /diagnostics
(ocu.live.robot) and the navigator's /odom and /map (ocu.live.navigation); a message is
encoded only when some client subscribed to its channel.

Each client has its own outbox bounded in bytes: a message that does not fit is dropped for
that client alone and counted, so a slow client loses frames, never grows the server's
memory and never delays another client or the operator. A client whose frames the server
refuses (not JSON, unknown operations, bad ids) gets a status message per frame and is
closed after MAX_REFUSED of them.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import logging
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from http import HTTPStatus
from pathlib import Path
from typing import Any, Final
from urllib.parse import parse_qs, urlsplit

from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from ocu.link.base import Link
from ocu.link.diagnostics import link_report
from ocu.live import navigation as nv
from ocu.live import robot as rb
from ocu.live import scene as sc
from ocu.live import wire
from ocu.live.clients import (
    ASSET,
    CONTROL,
    DEFAULT_CLIENT_BUFFER_BYTES,
    Client,
    LiveStats,
)
from ocu.live.control import Core, LiveControl
from ocu.live.goals import GoalCore, LiveGoals
from ocu.live.inputs import ClientInputs
from ocu.live.messages import ENCODINGS
from ocu.live.options import DEFAULT_HOST, LiveError
from ocu.live.services import Services
from ocu.profile import RobotProfile
from ocu.record import schemas as s
from ocu.record.convert import (
    DECODED_TOPICS,
    EVENT,
    STATS,
    TELEMETRY,
    Item,
    MessageConverter,
    item_of,
    topic_type,
)
from ocu.record.session import clock_pair
from ocu.records import (
    ExtensionChanged,
    LinkEvent,
    LinkState,
    LinkStateChanged,
    ScanFrame,
    TelemetryFrame,
)

log = logging.getLogger("ocu.live")

DEFAULT_PORT: Final = 8765
# Items waiting between the link's threads and the server's loop.
DEFAULT_MAX_QUEUE_BYTES: Final = 16 * 1024 * 1024
# Refused frames before a client is closed.
MAX_REFUSED: Final = 10
# A client only subscribes: no frame of its needs more.
MAX_CLIENT_FRAME_BYTES: Final = 64 * 1024
# The socket's own write buffer (websockets' high-water mark).
WRITE_LIMIT_BYTES: Final = 64 * 1024
# Clients at once: with their outboxes, the memory the server may take (64 x 4 MB).
DEFAULT_MAX_CLIENTS: Final = 64
START_TIMEOUT_S: Final = 10.0
# How often the remote drive's timeout is checked (its shortest is 0.15 s).
CONTROL_PERIOD_S: Final = 0.02
STOP_TIMEOUT_S: Final = 5.0
ITEM_OVERHEAD_BYTES: Final = 200
TOKEN_PARAMETER: Final = "token"
CLOSE_POLICY: Final = 1008
_SCAN: Final = -1  # the queue kind of a range scan (the recorder keeps only its datagram)


@dataclass
class _Channel:
    info: wire.ChannelInfo
    encoder: s.Encoder
    latched: tuple[int, bytes] | None = None
    keeps_last: bool = False


class LiveServer:
    """Serves what attached links send and receive to Foxglove WebSocket clients.

    start() binds (LiveError if it cannot), stop() closes every client and the thread
    (idempotent). `token`: clients must give it (`?token=` in the URL or an
    `Authorization: Bearer` header); the caller checks exposure (ocu.live.options).
    """

    def __init__(
        self,
        profile: RobotProfile,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        *,
        token: str | None = None,
        client_buffer_bytes: int = DEFAULT_CLIENT_BUFFER_BYTES,
        max_queue_bytes: int = DEFAULT_MAX_QUEUE_BYTES,
        clock: Callable[[], float] = time.monotonic,
        frames: rb.RobotFrames | None = None,
        control: bool = False,
        max_clients: int = DEFAULT_MAX_CLIENTS,
    ) -> None:
        self.profile = profile
        self.host = host
        self.port = port
        self.token = token
        self.client_buffer_bytes = client_buffer_bytes
        self.max_queue_bytes = max_queue_bytes
        self.clock = clock
        self.frames = frames if frames is not None else rb.RobotFrames.load(profile)
        self.mono0, self.wall0_ns = clock_pair(clock)
        self.session_id = uuid.uuid4().hex
        self._lock = threading.Lock()
        self._queue: deque[Item] = deque()
        self._queued_bytes = 0
        self._pump_scheduled = False
        self._queue_dropped = 0
        self._client_count = 0
        self._clients: set[Client] = set()
        self._connections = 0
        self._unauthorized = 0
        self._closed_for_refused = 0
        self._channels: dict[str, _Channel] = {}
        self._by_id: dict[int, _Channel] = {}
        self._closing: set[asyncio.Future[None]] = set()
        self._navigator: nv.NavigationSource | None = None
        self._scene: sc.SceneSource | None = None
        self._link_state = LinkState.CONNECTING
        # --live-control: clients may publish /cmd_vel (ocu.live.control) once a core is served.
        self.allow_control = control
        self.max_clients = max_clients
        self._crowded = 0
        self._inputs = ClientInputs(control, self._control)
        self._services = Services()
        self._converter = MessageConverter(profile, self.wall_ns, self._publish)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop_event: asyncio.Event | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._start_error: str | None = None
        self._bound_port: int | None = None
        self._declare_channels()

    # ---- channels (the loop thread's once started) -----------------------------------------

    def _declare_channels(self) -> None:
        for topic in s.RAW_TOPICS:
            self._channel(topic, s.RAW_PACKET)
        for topic, message_type in DECODED_TOPICS:
            self._channel(topic, message_type)
        for name in self.profile.link.camera_names:
            self._channel(s.camera_topic(name), s.COMPRESSED_IMAGE)
        self._channel(rb.SCAN, rb.LASER_SCAN)
        self._channel(rb.DIAGNOSTICS, rb.DIAGNOSTIC_ARRAY)
        if self.profile.drive_channels is not None:  # a chassis: odometry and a map
            self._channel(nv.ODOM, nv.ODOMETRY)
            self._channel(nv.MAP, nv.OCCUPANCY_GRID)
            self._channel(nv.PLAN, nv.PATH)
            footprint = self.profile.navigation.footprint
            if footprint is not None:
                outline = self._channel(nv.FOOTPRINT, nv.POLYGON_STAMPED, keeps_last=True)
                now = self.wall_ns(self.clock())
                message = nv.footprint_message(footprint.corners_m, s.stamp(now))
                outline.latched = (now, outline.encoder(message))
        for topic in sc.topics_of(self.profile):
            self._channel(topic, sc.SCENE_UPDATE, keeps_last=True)
        self._channel(rb.TF, rb.TF_MESSAGE)
        frames = self.frames
        if frames is not None:
            static = self._channel(rb.TF_STATIC, rb.TF_MESSAGE, keeps_last=True)
            description = self._channel(rb.ROBOT_DESCRIPTION, rb.STRING, keeps_last=True)
            now = self.wall_ns(self.clock())
            stamp = s.stamp(now)
            static.latched = (now, static.encoder(frames.static_message(stamp)))
            description.latched = (now, description.encoder(frames.description_message()))

    def _channel(
        self, topic: str, message_type: s.MessageType, *, keeps_last: bool = False
    ) -> _Channel:
        channel_id = len(self._by_id) + 1
        info = wire.ChannelInfo(channel_id, topic, message_type.name, message_type.definition)
        channel = _Channel(info, s.make_encoder(message_type), keeps_last=keeps_last)
        self._channels[topic] = channel
        self._by_id[channel_id] = channel
        return channel

    def topics(self) -> list[str]:
        """The topics advertised now."""
        return list(self._channels)

    def wall_ns(self, mono: float) -> int:
        """Wall-clock nanoseconds of a monotonic time (the recorder's mapping)."""
        return self.wall0_ns + round((mono - self.mono0) * 1e9)

    # ---- the link side (any thread) --------------------------------------------------------

    def attach(self, link: Link) -> None:
        """Serve what this link sends and receives."""
        link.subscribe(self.on_event)

    def detach(self, link: Link) -> None:
        """Stop serving this link."""
        link.unsubscribe(self.on_event)

    def on_event(self, event: LinkEvent) -> None:
        """One link event into the queue (the link's threads; never blocks)."""
        if not self._client_count and not isinstance(event, LinkStateChanged | ExtensionChanged):
            return  # nobody watching: the states the statistics carry are kept, nothing else
        if isinstance(event, ScanFrame):
            kept: tuple[Item, int] | None = (
                (_SCAN, event.received_at, event),
                8 * len(event.ranges_m),
            )
        else:
            kept = item_of(event, self.clock)
        loop = self._loop
        if kept is None or loop is None:
            return
        item, size = kept
        cost = size + ITEM_OVERHEAD_BYTES
        with self._lock:
            if self._queued_bytes + cost > self.max_queue_bytes:
                self._queue_dropped += 1
                return
            self._queue.append(item)
            self._queued_bytes += cost
            if self._pump_scheduled:
                return
            self._pump_scheduled = True
        with contextlib.suppress(RuntimeError):  # the loop has closed: the server is stopping
            loop.call_soon_threadsafe(self._pump)

    # ---- the loop thread -------------------------------------------------------------------

    def _pump(self) -> None:
        with self._lock:
            items = self._queue
            self._queue = deque()
            self._queued_bytes = 0
            self._pump_scheduled = False
            dropped = self._queue_dropped
        for item in items:
            try:
                self._serve_item(item, dropped)
            except Exception:
                # One item the conversion cannot take must not end the server for the rest.
                log.exception("live: cannot serve a %s item", item[0])

    def _serve_item(self, item: Item, dropped: int) -> None:
        kind, mono = item[0], item[1]
        if kind == _SCAN:
            self._publish(mono, rb.SCAN, rb.scan_message(item[2], s.stamp(self.wall_ns(mono))))
            return
        self._converter.convert(item, dropped)
        if kind == TELEMETRY and self.frames is not None:
            self._publish_tf(mono, item[2])
        elif kind == EVENT and item[2] == s.EVENT_LINK_STATE:
            self._link_state = LinkState(item[3])
        elif kind == STATS:
            report = link_report(self._link_state, item[2], self.profile.name)
            message = rb.diagnostics_message(report, s.stamp(self.wall_ns(mono)))
            self._publish(mono, rb.DIAGNOSTICS, message)

    def _publish_tf(self, mono: float, frame: TelemetryFrame) -> None:
        channel = self._channels[rb.TF]
        if not self._subscribed(channel.info.id):
            return
        assert self.frames is not None
        positions = {
            name: reading.angle_rad
            for name, reading in frame.readings.items()
            if reading.angle_rad is not None
        }
        self._publish(
            mono, rb.TF, self.frames.moving_message(positions, s.stamp(self.wall_ns(mono)))
        )

    def _subscribed(self, channel_id: int) -> bool:
        return any(channel_id in client.by_channel for client in self._clients)

    def _publish(
        self, mono: float, topic: str, message: dict[str, Any], publish_ns: int | None = None
    ) -> None:
        channel = self._channels.get(topic)
        if channel is None:
            channel = self._channel(topic, topic_type(topic))
            self._broadcast(wire.advertise([channel.info]))
        if not channel.keeps_last and not self._subscribed(channel.info.id):
            return
        self._fan_out(channel, self.wall_ns(mono), channel.encoder(message))

    def _fan_out(self, channel: _Channel, log_ns: int, payload: bytes) -> None:
        if channel.keeps_last:
            channel.latched = (log_ns, payload)
        channel_id = channel.info.id
        for client in self._clients:
            for subscription in client.by_channel.get(channel_id, ()):
                client.queue_data(wire.message_data(subscription, log_ns, payload))

    def serve_navigation(self, navigator: nv.NavigationSource) -> None:
        """Serve this navigator's odometry (/odom, odom -> base_link on /tf) and grid (/map)."""
        self._navigator = navigator

    async def _navigation_loop(self) -> None:
        if nv.ODOM not in self._channels:
            return
        odom, tf, grid, plan = (self._channels[t] for t in (nv.ODOM, rb.TF, nv.MAP, nv.PLAN))
        next_map = 0.0
        while True:
            await asyncio.sleep(nv.ODOM_PERIOD_S)
            navigator = self._navigator
            if navigator is None:
                continue
            try:
                now = self.clock()
                log_ns = self.wall_ns(now)
                stamp = s.stamp(log_ns)
                if self._subscribed(odom.info.id) or self._subscribed(tf.info.id):
                    estimate = navigator.estimate(now)
                    message = nv.odometry_message(estimate, stamp)
                    self._fan_out(odom, log_ns, odom.encoder(message))
                    transform = nv.odometry_transform(estimate, stamp)
                    self._fan_out(tf, log_ns, tf.encoder(transform))
                if now < next_map:
                    continue
                next_map = now + nv.MAP_PERIOD_S
                if self._subscribed(plan.info.id):
                    path = nv.path_message(navigator.planned_path(), stamp)
                    self._fan_out(plan, log_ns, plan.encoder(path))
                occupancy = navigator.grid
                if occupancy is not None and self._subscribed(grid.info.id):
                    self._fan_out(grid, log_ns, nv.encode_grid(grid.encoder, occupancy, stamp))
            except Exception:
                log.exception("live: cannot serve the navigator's state")
                await asyncio.sleep(nv.MAP_PERIOD_S)

    def serve_scene(self, model: sc.SceneModel) -> None:
        """Serve this console model's zones, planned path and arm goal (ocu.live.scene)."""
        self._scene = sc.SceneSource(model)

    async def _scene_loop(self) -> None:
        while True:
            await asyncio.sleep(sc.SCENE_PERIOD_S)
            source = self._scene
            if source is None:
                continue
            try:
                log_ns = self.wall_ns(self.clock())
                for topic, message in source.changed(s.stamp(log_ns)):
                    channel = self._channels.get(topic)
                    if channel is not None:
                        self._fan_out(channel, log_ns, channel.encoder(message))
            except Exception:
                log.exception("live: cannot serve the scene")
                await asyncio.sleep(nv.MAP_PERIOD_S)

    def _broadcast(self, text: str) -> None:
        for client in list(self._clients):
            self._control(client, text)

    def _control(self, client: Client, text: str | bytes) -> None:
        if not client.queue_control(text) and not client.closing:
            client.closing = True
            task = asyncio.ensure_future(client.connection.close(CLOSE_POLICY, "not reading"))
            self._closing.add(task)
            task.add_done_callback(self._closing.discard)

    def _process_request(self, connection: ServerConnection, request: Request) -> Response | None:
        if len(self._clients) >= self.max_clients:  # each costs up to its outbox
            self._crowded += 1
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
        self._unauthorized += 1
        log.warning("live: refused %s: no valid token", connection.remote_address)
        return connection.respond(HTTPStatus.UNAUTHORIZED, "a valid token is needed\n")

    async def _handle(self, connection: ServerConnection) -> None:
        client = Client(connection, self.client_buffer_bytes)
        self._clients.add(client)
        self._client_count = len(self._clients)
        self._connections += 1
        log.info("live: %s connected (%s)", client.address, connection.subprotocol)
        metadata = {"profile": self.profile.name}
        capabilities = ["assets"] if self.frames is not None and self.frames.assets else []
        services = self._services.advertisement()
        capabilities += ["clientPublish"] if self.allow_control else []
        capabilities += ["services"] if services is not None else []
        encodings = list(ENCODINGS) if self.allow_control or services is not None else []
        name = f"ocu {self.profile.name}"
        info = wire.server_info(name, self.session_id, metadata, capabilities, encodings)
        self._control(client, info)
        self._control(client, wire.advertise([c.info for c in self._channels.values()]))
        if services is not None:
            self._control(client, services)
        sender = asyncio.create_task(self._send_loop(client), name="ocu-live-send")
        try:
            async for frame in connection:
                self._on_frame(client, frame)
                if client.refused >= MAX_REFUSED and not client.closing:
                    client.closing = True
                    self._closed_for_refused += 1
                    # The reasons queued for it go out before the close, within a second.
                    client.flushed.clear()
                    client.wake.set()
                    with contextlib.suppress(TimeoutError):
                        await asyncio.wait_for(client.flushed.wait(), 1.0)
                    await connection.close(CLOSE_POLICY, "too many refused messages")
                    break
        except ConnectionClosed:
            pass
        finally:
            self._clients.discard(client)
            self._client_count = len(self._clients)
            sender.cancel()
            self._inputs.left(client)
            log.info(
                "live: %s left (%d sent, %d dropped, %d refused)",
                client.address,
                client.sent,
                client.dropped,
                client.refused,
            )

    def _on_frame(self, client: Client, frame: str | bytes) -> None:
        try:
            message = wire.parse_client_message(frame)
        except wire.ClientMessageError as err:
            client.refused += 1
            self._control(client, wire.status(wire.StatusLevel.ERROR, str(err)))
            return
        if isinstance(message, wire.Subscribe):
            for subscription, channel_id in message.subscriptions:
                self._subscribe(client, subscription, channel_id)
        elif isinstance(message, wire.FetchAsset):
            self._fetch_asset(client, message)
        elif isinstance(message, wire.ServiceCallRequest):
            self._control(client, self._services.call(client.address, message))
        elif isinstance(
            message, wire.ClientAdvertise | wire.ClientUnadvertise | wire.ClientPublish
        ):
            self._inputs.on_message(client, message)
        else:
            for subscription in message.subscription_ids:
                taken = client.subscriptions.pop(subscription, None)
                if taken is None:
                    continue
                ids = client.by_channel.get(taken, set())
                ids.discard(subscription)
                if not ids:
                    client.by_channel.pop(taken, None)

    @property
    def control(self) -> LiveControl | None:
        """The remote drive (with --live-control, once a console serves it), else None."""
        return self._inputs.teleop

    def serve_control(self, core: Core, goals: GoalCore | None = None) -> None:
        """With `control`: clients' /cmd_vel and (given a goal core) the arm's topics drive
        this core's model (ocu.live.control, ocu.live.goals)."""
        if self.allow_control:
            arm = LiveGoals(core, goals) if goals is not None else None
            self._inputs.teleop = LiveControl(core, self.clock, arm)
        self._services.serve(core, self._inputs.teleop)

    async def _control_loop(self) -> None:
        while True:
            await asyncio.sleep(CONTROL_PERIOD_S)
            teleop = self._inputs.teleop
            if teleop is not None:
                try:
                    teleop.step()
                except Exception:
                    log.exception("live: cannot step the remote drive")

    def _fetch_asset(self, client: Client, request: wire.FetchAsset) -> None:
        assets = self.frames.assets if self.frames is not None else {}
        file = assets.get(request.uri)
        if file is None:
            client.refused += 1  # only the URDF's own meshes are served: a probe is a fault
            answer = wire.fetch_asset_response(
                request.request_id, None, f"{request.uri[:200]}: not a mesh of this robot"
            )
            if not client.queue_asset(answer):
                self._control(client, wire.status(wire.StatusLevel.ERROR, "fetchAsset: busy"))
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

    def _subscribe(self, client: Client, subscription: int, channel_id: int) -> None:
        channel = self._by_id.get(channel_id)
        problem = None
        if channel is None:
            problem = f"no channel {channel_id}"
        elif subscription in client.subscriptions:
            problem = f"subscription {subscription} is taken"
        elif len(client.subscriptions) >= wire.MAX_SUBSCRIPTIONS:
            problem = f"more than {wire.MAX_SUBSCRIPTIONS} subscriptions"
        if problem is not None or channel is None:
            client.refused += 1
            self._control(client, wire.status(wire.StatusLevel.ERROR, f"subscribe: {problem}"))
            return
        client.subscriptions[subscription] = channel_id
        client.by_channel.setdefault(channel_id, set()).add(subscription)
        if channel.latched is not None:
            log_ns, payload = channel.latched
            client.queue_data(wire.message_data(subscription, log_ns, payload))

    async def _send_loop(self, client: Client) -> None:
        try:
            while True:
                await client.wake.wait()
                client.wake.clear()
                while client.outbox:
                    frame, size, kind = client.outbox.popleft()
                    if kind == CONTROL:
                        client.control_bytes -= size
                    elif kind == ASSET:
                        client.asset_bytes -= size
                    else:
                        client.data_bytes -= size
                    await client.connection.send(frame)
                    client.sent += 1
                client.flushed.set()
        except ConnectionClosed:
            pass

    # ---- start and stop --------------------------------------------------------------------

    @property
    def address(self) -> tuple[str, int]:
        """Where it listens (the port bound when 0 was asked)."""
        return self.host, self._bound_port if self._bound_port is not None else self.port

    def start(self) -> None:
        """Bind and serve on the thread "ocu-live"; LiveError with the reason if it cannot."""
        if self._thread is not None:
            return
        self._thread = threading.Thread(target=self._run, name="ocu-live", daemon=True)
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT_S):
            raise LiveError(f"live server did not start within {START_TIMEOUT_S:.0f} s")
        if self._start_error is not None:
            self._thread.join(STOP_TIMEOUT_S)
            self._thread = None
            raise LiveError(self._start_error)
        log.info("live: serving on ws://%s:%d", *self.address)

    def _run(self) -> None:
        asyncio.run(self._main())

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop_event = asyncio.Event()
        try:
            server: Server = await serve(
                self._handle,
                self.host,
                self.port,
                subprotocols=[wire.SUBPROTOCOLS[0], wire.SUBPROTOCOLS[1]],  # type: ignore[list-item]
                process_request=self._process_request,
                compression=None,
                max_size=MAX_CLIENT_FRAME_BYTES,
                write_limit=WRITE_LIMIT_BYTES,
            )
        except OSError as err:
            self._start_error = (
                f"cannot serve live on {self.host}:{self.port}: {err.strerror or err}"
            )
            self._loop = None
            self._ready.set()
            return
        self._bound_port = int(server.sockets[0].getsockname()[1])
        navigation = asyncio.create_task(self._navigation_loop(), name="ocu-live-navigation")
        teleop = asyncio.create_task(self._control_loop(), name="ocu-live-control")
        scene = asyncio.create_task(self._scene_loop(), name="ocu-live-scene")
        self._ready.set()
        await self._stop_event.wait()
        self._loop = None
        for task in (navigation, teleop, scene):
            task.cancel()
        remote = self._inputs.teleop
        if remote is not None:
            owner = remote.owner
            if owner is not None:
                remote.release(owner, "the live server stopped")
        server.close(close_connections=True)
        await server.wait_closed()

    def stop(self) -> None:
        """Close every client and the server; idempotent."""
        thread = self._thread
        loop, stop_event = self._loop, self._stop_event
        if thread is None:
            return
        if loop is not None and stop_event is not None:
            with contextlib.suppress(RuntimeError):  # the loop has ended already
                loop.call_soon_threadsafe(stop_event.set)
        thread.join(STOP_TIMEOUT_S)
        if thread.is_alive():
            log.error("live server did not stop within %.1f s", STOP_TIMEOUT_S)
        self._thread = None

    def stats(self) -> LiveStats:
        """Counters now (any thread; the client list is a snapshot)."""
        clients = tuple(client.stats() for client in list(self._clients))
        with self._lock:
            dropped = self._queue_dropped
        return LiveStats(
            clients,
            self._connections,
            self._unauthorized,
            self._closed_for_refused,
            dropped,
            self._crowded,
        )
