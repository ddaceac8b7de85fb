"""The live server: a session served over the Foxglove WebSocket protocol (docs/live.md).

The server is one more subscriber of a Link (attach()). Its callback runs on the link's
threads and only appends a small item to a bounded queue (dropped and counted when full; the
link never waits, and with no client connected it keeps only the link's state changes).
The rest of the console's part runs on the server's own thread, "ocu-live", in one asyncio
loop: it hands the items, as they are, to the relay; polls the navigator (/odom, /map) and
the scene; and takes what clients publish and the services they call (the robot is here).

Serving is a process of its own, the relay (ocu.live.relay, over a socket pair:
ocu.live.pipe): it encodes the items into the recorder's ROS 2 messages plus the robot's
/tf, /tf_static, /robot_description, /scan and /diagnostics (ocu.live.encoding), once per
message and only for channels someone subscribed to, and fans each out to its subscribers.
Each client there has its own outbox bounded in bytes: a message that does not fit is
dropped for that client alone and counted, so a slow client loses frames, never grows the
server's memory and never delays another client or the operator. Neither the encoding nor
any client costs this interpreter anything but the items' pickling: the operator's key path
shares its GIL. A client whose frames are refused (not JSON, unknown operations, bad ids)
gets a status message per frame and is closed after MAX_REFUSED of them.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import subprocess
import sys
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable
from concurrent.futures import TimeoutError as FutureTimeout
from typing import Any, Final

from ocu.link.base import Link
from ocu.live import navigation as nv
from ocu.live import pipe, wire
from ocu.live import robot as rb
from ocu.live import scene as sc
from ocu.live.clients import DEFAULT_CLIENT_BUFFER_BYTES, LiveStats
from ocu.live.control import Core, LiveControl
from ocu.live.encoding import SCAN
from ocu.live.goals import GoalCore, LiveGoals
from ocu.live.inputs import ClientInputs, RemoteClient
from ocu.live.messages import ARM_TWIST, ENCODINGS
from ocu.live.options import DEFAULT_HOST, LiveError
from ocu.live.services import Services
from ocu.priority import behind, current_nice
from ocu.profile import RobotProfile
from ocu.record import schemas as s
from ocu.record.convert import (
    COMMAND,
    RECEIVED,
    RECEIVED_TOPICS,
    SENT,
    SENT_TOPICS,
    STATUS,
    TELEMETRY,
    VIDEO,
    Item,
    item_of,
)
from ocu.record.session import clock_pair
from ocu.records import (
    ExtensionChanged,
    LinkEvent,
    LinkStateChanged,
    ScanFrame,
)

log = logging.getLogger("ocu.live")

DEFAULT_PORT: Final = 8765
# Items waiting between the link's threads and the server's loop.
DEFAULT_MAX_QUEUE_BYTES: Final = 16 * 1024 * 1024
# Messages on their way to the relay: a relay that cannot keep up loses data, never control
# messages, and never holds this process up.
MAX_RELAY_BUFFER_BYTES: Final = 16 * 1024 * 1024
# The relay runs at the default priority and at least this many nice values behind the
# console: observers come after the operator. (At nice -5 behind a console at -10, 20 clients
# on the same two cores moved key -> datagram p50 from 1.4 to 1.9 ms; at 0, 1.2 -> 1.2.)
RELAY_NICE_STEPS: Final = 5
# How often the relay's counters are fetched for the console's indicator.
STATS_PERIOD_S: Final = 0.5
STATS_TIMEOUT_S: Final = 2.0
# Clients at once: with their outboxes, the memory the server may take (64 x 4 MB).
DEFAULT_MAX_CLIENTS: Final = 64
START_TIMEOUT_S: Final = 10.0
# How often the remote drive's timeout is checked (its shortest is 0.15 s).
CONTROL_PERIOD_S: Final = 0.02
STOP_TIMEOUT_S: Final = 5.0
ITEM_OVERHEAD_BYTES: Final = 200


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
        self._remote: dict[int, RemoteClient] = {}
        self._subscribed_topics: frozenset[str] = frozenset()
        self._relay: subprocess.Popen[bytes] | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._relay_dropped = 0
        self._stats = LiveStats((), 0, 0, 0, 0, 0)
        self._stats_asked: dict[int, asyncio.Future[LiveStats]] = {}
        self._stats_ids = 0
        self._navigator: nv.NavigationSource | None = None
        self._scene: sc.SceneSource | None = None
        # --live-control: clients may publish /cmd_vel (ocu.live.control) once a core is served.
        self.allow_control = control
        self.max_clients = max_clients
        self._inputs = ClientInputs(control, self._control)
        self._inputs.taken = self._taken
        self._services = Services()
        self._grid_encoder = s.make_encoder(nv.OCCUPANCY_GRID)
        self._camera_topics = frozenset(s.camera_topic(n) for n in profile.link.camera_names)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop_event: asyncio.Event | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._start_error: str | None = None
        self._bound_port: int | None = None

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
                (SCAN, event.received_at, event),
                8 * len(event.ranges_m),
            )
        else:
            kept = item_of(event, self.clock)
        loop = self._loop
        if kept is None or loop is None:
            return
        item, size = kept
        if not self._wanted(item):
            return
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

    def _wanted(self, item: Item) -> bool:
        """Whether anyone subscribes to what the relay makes of this item: nothing else is
        handed over (a raw video fragment nobody watches costs a pickle and a copy each).
        The link's threads; the loop thread swaps the set of topics whole."""
        topics = self._subscribed_topics
        kind = item[0]
        if kind == SENT:
            return SENT_TOPICS.get(item[2].kind, s.RAW_OTHER) in topics
        if kind == RECEIVED:
            return RECEIVED_TOPICS.get(item[2].kind, s.RAW_OTHER) in topics
        if kind == TELEMETRY:
            return s.JOINT_STATES in topics or rb.TF in topics
        if kind == VIDEO:
            return not topics.isdisjoint(self._camera_topics)
        if kind == COMMAND:
            return s.CMD_VEL in topics or s.CMD_JOINTS in topics
        if kind == STATUS:
            return s.ROBOT_STATUS in topics
        if kind == SCAN:
            return rb.SCAN in topics
        return True  # the statistics and the events: the state /diagnostics carries

    # ---- the loop thread -------------------------------------------------------------------

    def _pump(self) -> None:
        with self._lock:
            items = list(self._queue)
            self._queue = deque()
            self._queued_bytes = 0
            self._pump_scheduled = False
            dropped = self._queue_dropped
        # To the relay as they are, in one message: it encodes them (ocu.live.encoding).
        self._send_data((pipe.ITEMS, items, dropped))

    def _subscribed(self, topic: str) -> bool:
        return topic in self._subscribed_topics

    def _send_data(self, message: tuple[Any, ...]) -> None:
        """Data for the relay (the loop thread): dropped and counted when the relay cannot
        keep up, so that it never holds this process up nor grows its memory."""
        writer = self._writer
        if writer is None:
            return
        if writer.transport.get_write_buffer_size() > MAX_RELAY_BUFFER_BYTES:
            self._relay_dropped += 1
            return
        writer.write(pipe.pack(message))

    def _publish(self, mono: float, topic: str, message: dict[str, Any]) -> None:
        """One of the console's own messages, encoded in the relay."""
        self._send_data((pipe.PUBLISH, mono, topic, message))

    def _tell(self, *message: Any) -> None:
        """A control message to the relay (the loop thread; never dropped)."""
        writer = self._writer
        if writer is not None:
            writer.write(pipe.pack(message))

    def serve_navigation(self, navigator: nv.NavigationSource) -> None:
        """Serve this navigator's odometry (/odom, odom -> base_link on /tf) and grid (/map)."""
        self._navigator = navigator

    async def _navigation_loop(self) -> None:
        if self.profile.drive_channels is None:  # no chassis: no odometry, no map
            return
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
                if self._subscribed(nv.ODOM) or self._subscribed(rb.TF):
                    estimate = navigator.estimate(now)
                    self._publish(now, nv.ODOM, nv.odometry_message(estimate, stamp))
                    self._publish(now, rb.TF, nv.odometry_transform(estimate, stamp))
                if now < next_map:
                    continue
                next_map = now + nv.MAP_PERIOD_S
                if self._subscribed(nv.PLAN):
                    path = nv.path_message(navigator.planned_path(), stamp)
                    self._publish(now, nv.PLAN, path)
                occupancy = navigator.grid
                if occupancy is not None and self._subscribed(nv.MAP):
                    # Encoded here, by the grid's own fast path: its cells are a copy taken
                    # now (scans go on meanwhile), smaller than the model's array.
                    payload = nv.encode_grid(self._grid_encoder, occupancy, stamp)
                    self._send_data((pipe.ENCODED, nv.MAP, log_ns, payload))
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
                now = self.clock()
                for topic, message in source.changed(s.stamp(self.wall_ns(now))):
                    self._tell(pipe.PUBLISH, now, topic, message)  # kept for late subscribers
            except Exception:
                log.exception("live: cannot serve the scene")
                await asyncio.sleep(nv.MAP_PERIOD_S)

    def _taken(self, topic: str, decoded: Any) -> None:
        """A client's arm twist the live source took, on /arm/twist_cmd for every viewer."""
        if topic != ARM_TWIST or not self._subscribed(ARM_TWIST):
            return
        now = self.clock()
        header = {"stamp": s.stamp(self.wall_ns(now)), "frame_id": decoded.frame_id}
        twist = {
            "linear": dict(zip("xyz", decoded.linear, strict=True)),
            "angular": dict(zip("xyz", decoded.angular, strict=True)),
        }
        self._publish(now, ARM_TWIST, {"header": header, "twist": twist})

    def _control(self, client: RemoteClient, text: str | bytes) -> None:
        self._tell(pipe.TO, client.id, text)

    def _hello(self) -> tuple[str, str, str | None]:
        """What each new client gets first: serverInfo, and the services if any."""
        metadata = {"profile": self.profile.name}
        capabilities = ["assets"] if self.frames is not None and self.frames.assets else []
        services = self._services.advertisement()
        capabilities += ["clientPublish"] if self.allow_control else []
        capabilities += ["services"] if services is not None else []
        encodings = list(ENCODINGS) if self.allow_control or services is not None else []
        name = f"ocu {self.profile.name}"
        info = wire.server_info(name, self.session_id, metadata, capabilities, encodings)
        return pipe.HELLO, info, services

    def _on_relay(self, message: tuple[Any, ...]) -> None:
        """One message from the relay (the loop thread)."""
        kind = message[0]
        if kind == pipe.INPUT:
            client = self._remote.get(message[1])
            if client is not None:
                refused = client.refused
                self._inputs.on_message(client, message[2])
                if client.refused > refused:
                    self._tell(pipe.REFUSED, client.id, client.refused - refused)
        elif kind == pipe.CALL:
            client = self._remote.get(message[1])
            if client is not None:
                self._control(client, self._services.call(client.address, message[2]))
        elif kind == pipe.SUBSCRIBED:
            self._subscribed_topics = message[1]
        elif kind == pipe.JOINED:
            _, client_id, address, subprotocol = message
            self._remote[client_id] = RemoteClient(client_id, address)
            self._client_count = len(self._remote)
            log.info("live: %s connected (%s)", address, subprotocol)
        elif kind == pipe.LEFT:
            _, client_id, sent, dropped, refused = message
            gone = self._remote.pop(client_id, None)
            self._client_count = len(self._remote)
            if gone is not None:
                self._inputs.left(gone)
                log.info(
                    "live: %s left (%d sent, %d dropped, %d refused)",
                    gone.address,
                    sent,
                    dropped,
                    refused,
                )
        elif kind == pipe.STATS:
            asked = self._stats_asked.pop(message[1], None)
            self._stats = message[2]
            if asked is not None and not asked.done():
                asked.set_result(message[2])
        else:
            log.error("live: unknown message from the relay: %r", kind)

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
        loop = self._loop
        if loop is not None:  # the clients that come from now on are told of the services
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(lambda: self._tell(*self._hello()))

    async def _control_loop(self) -> None:
        while True:
            await asyncio.sleep(CONTROL_PERIOD_S)
            teleop = self._inputs.teleop
            if teleop is not None:
                try:
                    teleop.step()
                except Exception:
                    log.exception("live: cannot step the remote drive")

    # ---- start and stop --------------------------------------------------------------------

    @property
    def address(self) -> tuple[str, int]:
        """Where it listens (the port bound when 0 was asked)."""
        return self.host, self._bound_port if self._bound_port is not None else self.port

    def start(self) -> None:
        """Start the relay process and the thread "ocu-live"; LiveError with the reason if the
        relay cannot bind."""
        if self._thread is not None:
            return
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        steps = max(RELAY_NICE_STEPS, -current_nice())  # nice 0 behind a console at -10
        command = behind([sys.executable, "-m", "ocu.live.relay", str(theirs.fileno())], steps)
        try:
            self._relay = subprocess.Popen(
                command, pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL
            )
        except OSError as err:
            ours.close()
            raise LiveError(f"cannot start the live relay: {err}") from err
        finally:
            theirs.close()
        self._thread = threading.Thread(
            target=self._run, args=(ours,), name="ocu-live", daemon=True
        )
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT_S):
            self._relay.kill()  # its pipe closes: the thread's wait for it ends
            self.stop()
            raise LiveError(f"live server did not start within {START_TIMEOUT_S:.0f} s")
        if self._start_error is not None:
            self.stop()
            raise LiveError(self._start_error)
        log.info("live: serving on ws://%s:%d", *self.address)

    def _run(self, sock: socket.socket) -> None:
        asyncio.run(self._main(sock))

    async def _main(self, sock: socket.socket) -> None:
        self._stop_event = asyncio.Event()
        self._loop = asyncio.get_running_loop()
        reader, writer = await asyncio.open_unix_connection(sock=sock)
        writer.transport.set_write_buffer_limits(high=MAX_RELAY_BUFFER_BYTES)
        self._writer = writer
        self._tell(*self._hello())
        assets = self.frames.assets if self.frames is not None else {}
        listen = pipe.Listen(
            self.profile,
            self.frames,
            self.mono0,
            self.wall0_ns,
            self.clock(),
            self.host,
            self.port,
            self.token,
            self.client_buffer_bytes,
            self.max_clients,
            {uri: str(file) for uri, file in assets.items()},
        )
        self._tell(pipe.LISTEN, listen)
        first = await pipe.receive(reader)
        if first is None or first[0] != pipe.READY:
            self._start_error = first[1] if first is not None else "the live relay ended"
            self._loop = None
            self._writer = None
            writer.close()
            self._ready.set()
            return
        self._bound_port = int(first[1])
        tasks = [
            asyncio.create_task(self._navigation_loop(), name="ocu-live-navigation"),
            asyncio.create_task(self._control_loop(), name="ocu-live-control"),
            asyncio.create_task(self._scene_loop(), name="ocu-live-scene"),
            asyncio.create_task(self._stats_loop(), name="ocu-live-stats"),
        ]
        relay = asyncio.create_task(self._relay_loop(reader), name="ocu-live-relay")
        self._ready.set()
        stopped = asyncio.create_task(self._stop_event.wait())
        await asyncio.wait((stopped, relay), return_when=asyncio.FIRST_COMPLETED)
        self._loop = None
        for task in (*tasks, stopped):
            task.cancel()
        self._all_left("the live server stopped")
        self._tell(pipe.STOP)
        with contextlib.suppress(ConnectionError):
            await writer.drain()
        self._writer = None
        writer.close()
        with contextlib.suppress(TimeoutError, asyncio.CancelledError):
            await asyncio.wait_for(relay, STOP_TIMEOUT_S)

    async def _relay_loop(self, reader: asyncio.StreamReader) -> None:
        while True:
            message = await pipe.receive(reader)
            if message is None:
                if self._stop_event is not None and not self._stop_event.is_set():
                    log.error("live: the relay process ended; nobody is served any more")
                self._all_left("the live relay ended")
                return
            try:
                self._on_relay(message)
            except Exception:  # one message must not end the serving of the rest
                log.exception("live: cannot take the relay's %s message", message[0])

    def _all_left(self, reason: str) -> None:
        """Every client counts as gone: what a remote client drove stops, for `reason`."""
        remote = self._inputs.teleop
        if remote is not None:
            owner = remote.owner
            if owner is not None:
                remote.release(owner, reason)
        for client in list(self._remote.values()):
            self._inputs.left(client)
        self._remote.clear()
        self._client_count = 0
        self._subscribed_topics = frozenset()

    async def _stats_loop(self) -> None:
        while True:
            await asyncio.sleep(STATS_PERIOD_S)
            self._ask_stats()

    def _ask_stats(self) -> asyncio.Future[LiveStats]:
        self._stats_ids += 1
        asked: asyncio.Future[LiveStats] = asyncio.get_running_loop().create_future()
        self._stats_asked[self._stats_ids] = asked
        self._tell(pipe.STATS, self._stats_ids)
        return asked

    @property
    def relay_pid(self) -> int | None:
        """The relay process's id while it runs (ocu.live.relay)."""
        relay = self._relay
        return relay.pid if relay is not None and relay.poll() is None else None

    def stop(self) -> None:
        """Close every client, the relay and the thread; idempotent."""
        thread = self._thread
        stop_event = self._stop_event
        if thread is not None:
            loop = self._loop
            if loop is not None and stop_event is not None:
                with contextlib.suppress(RuntimeError):  # the loop has ended already
                    loop.call_soon_threadsafe(stop_event.set)
            thread.join(STOP_TIMEOUT_S)
            if thread.is_alive():
                log.error("live server did not stop within %.1f s", STOP_TIMEOUT_S)
            self._thread = None
        relay, self._relay = self._relay, None
        if relay is not None:
            try:
                relay.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                log.error("the live relay did not stop within %.1f s: killed", STOP_TIMEOUT_S)
                relay.kill()
                relay.wait()

    def stats(self, *, fresh: bool = True) -> LiveStats:
        """Counters (any thread). `fresh`: asked of the relay now (waits for its answer, up
        to STATS_TIMEOUT_S); else the last ones fetched (every STATS_PERIOD_S; never waits:
        the GUI's indicator)."""
        stats = self._stats
        loop = self._loop
        if fresh and loop is not None and threading.current_thread() is not self._thread:

            async def ask() -> LiveStats:
                return await self._ask_stats()

            with contextlib.suppress(FutureTimeout, RuntimeError):
                stats = asyncio.run_coroutine_threadsafe(ask(), loop).result(STATS_TIMEOUT_S)
        with self._lock:
            dropped = self._queue_dropped
        return LiveStats(
            stats.clients,
            stats.connections,
            stats.unauthorized,
            stats.closed_for_refused,
            dropped + self._relay_dropped,
            stats.crowded,
        )
