"""The robot simulator: a datagram server that behaves as the documents say the Engineer does.

One loop thread ("ocu-sim", an ocu.net SelectLoop) owns the transport and all robot state.
Each datagram, either way, passes the fault layer (ocu.sim.faults); the robot's protocol side
(ocu.sim.robot) turns RCPs into commands for the physics (ocu.sim.physics) and, on timers,
the physics into telemetry and video for the sender of the latest RCP. Other threads read
thread-safe snapshots (`state()`, `wait_until()`). It serves UDP by default, or any
ocu.net Transport, such as one end of a VirtualWire.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import TracebackType
from typing import NamedTuple

from ocu.model.urdf import UrdfError, load_urdf, profile_urdf_path
from ocu.nav.geometry import Pose
from ocu.nav.world import World
from ocu.net.loop import SelectLoop
from ocu.net.transport import Address, Transport, UdpTransport
from ocu.profile import RobotProfile
from ocu.protocol import RemoteControlPacket
from ocu.protocol.wire import make_extension_codec
from ocu.sim.extended import (
    DEFAULT_DRAIN_PERCENT_PER_S,
    DEFAULT_STATUS_HZ,
    ExtendedCounters,
    ExtendedServer,
)
from ocu.sim.faults import Direction, FaultConfig, FaultLayer
from ocu.sim.physics import RobotPhysics
from ocu.sim.rangefinder import DEFAULT_RANGE_SENSOR, RangeSensor, RangeSensorConfig
from ocu.sim.robot import RobotServer
from ocu.sim.scene import CameraLinks, WorldView
from ocu.sim.video import FrameRenderer

log = logging.getLogger("ocu.sim")

# The watchdog contract (stop within 1.0-1.3 s) needs physics steps of at most 10 ms.
MAX_PHYSICS_STEP_S = 0.01
RECEIVED_LOG_LENGTH = 10_000
RECEIVE_BUFFER_BYTES = 1 << 20
MAX_DATAGRAM_BYTES = 65_535
# Bounds one burst of reading so a flood cannot starve the physics timer.
MAX_DATAGRAMS_PER_WAKE = 256


class ReceivedRcp(NamedTuple):
    """One RCP applied after the faults: monotonic receive time, packet and sender, and its
    sequence number if it came sequenced (the extension)."""

    time_s: float
    packet: RemoteControlPacket
    address: Address
    sequence: int | None = None


@dataclass(frozen=True)
class SimState:
    """A consistent snapshot of the simulated robot and its link counters.

    time_s is the time.monotonic() of the last physics update, the same clock as
    ReceivedRcp.time_s; elapsed_s counts from start().
    """

    time_s: float
    elapsed_s: float
    joints_rad: dict[str, float]
    velocities: dict[str, float]
    commanded_velocities: dict[str, float]
    track_speeds_m_s: tuple[float, float]
    # Ground truth of the chassis in the world: x_m, y_m, heading_rad.
    pose: tuple[float, float, float]
    torch: bool
    camera: int
    video_quality: int
    client: Address | None
    watchdog_stopped: bool
    waist_suppressed: bool
    all_stopped: bool
    link_cut: bool
    rcp_count: int
    telemetry_sent: int
    video_sent: int
    malformed_count: int
    foreign_count: int
    # RCPs dropped as older than the newest applied (the extension's sequence numbers).
    stale_rcp_count: int
    datagrams_received: int
    datagrams_sent: int
    dropped_to_robot: int
    dropped_to_ocu: int
    dropped_by_faults: int
    duplicated: int
    send_errors: int
    internal_errors: int
    extended: ExtendedCounters | None = None
    # Times the chassis ran into a wall or a box, and whether it is pressed against one now.
    collisions: int = 0
    in_contact: bool = False


@dataclass
class _Counters:
    datagrams_received: int = 0
    datagrams_sent: int = 0
    send_errors: int = 0
    internal_errors: int = 0


class _Periodic:
    """A fixed schedule (None: never due) that skips its backlog after a stall."""

    def __init__(self, period_s: float | None) -> None:
        self.period_s = period_s
        self.next_s = math.inf

    def begin(self, now_s: float) -> None:
        if self.period_s is not None:
            self.next_s = now_s + self.period_s

    def due(self, now_s: float) -> bool:
        """Whether it is due, rescheduling when it is."""
        if self.period_s is None or now_s < self.next_s:
            return False
        # Keep a fixed schedule, but skip the backlog after a stall rather than bursting.
        self.next_s += self.period_s
        if self.next_s <= now_s:
            self.next_s = now_s + self.period_s
        return True


@dataclass
class _PlaceRequest:
    pose: Pose
    done: threading.Event = field(default_factory=threading.Event)
    error: ValueError | None = None


def _camera_links(profile: RobotProfile) -> CameraLinks | None:
    """Forward kinematics for the cameras the profile mounts on a link (the head), from the
    robot's URDF; None when every camera sits on the chassis."""
    wanted = {c.mount.link for c in profile.cameras if c.mount is not None and c.mount.link}
    if not wanted:
        return None
    try:
        model = load_urdf(profile_urdf_path(profile), meshes=False)
    except UrdfError as err:
        raise ValueError(f"cameras mounted on {', '.join(sorted(wanted))}: {err}") from err
    base_link = profile.arm.base_link if profile.arm is not None else "base_link"
    links = CameraLinks(model.tree, base_link)
    missing = sorted(link for link in wanted if not links.has(link))
    if missing:
        raise ValueError(f"cameras.*.mount_link: the robot model has no link {', '.join(missing)}")
    return links


class RobotSimulator:
    """A simulated Engineer robot server on a UDP socket (or a given transport)."""

    def __init__(
        self,
        profile: RobotProfile,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        telemetry_hz: float | None = None,
        video_fps: float = 10.0,
        video_size: tuple[int, int] = (320, 240),
        faults: FaultConfig | None = None,
        seed: int | None = None,
        physics_hz: float = 200.0,
        initial_joints: Mapping[str, float] | None = None,
        extended: bool = False,
        status_hz: float = DEFAULT_STATUS_HZ,
        battery_percent: float = 100.0,
        battery_drain_percent_per_s: float = DEFAULT_DRAIN_PERCENT_PER_S,
        noise_deg: float = 0.0,
        transport: Transport | None = None,
        world: World | None = None,
        range_sensor: RangeSensorConfig | None = DEFAULT_RANGE_SENSOR,
        turn_slip: float = 0.0,
    ) -> None:
        """Bind host:port over UDP, or serve `transport` (host and port are then ignored).

        In a `world` the robot starts at its start pose and stops against its walls and
        boxes; the cameras draw it. An extended robot also sends range scans of it
        (`range_sensor`, None: no sensor).
        """
        self.profile = profile
        rate_hz = profile.link.telemetry_rate_hz if telemetry_hz is None else telemetry_hz
        if not (math.isfinite(rate_hz) and rate_hz > 0.0):
            raise ValueError(f"telemetry_hz must be > 0, got {rate_hz!r}")
        if not (math.isfinite(video_fps) and video_fps >= 0.0):
            raise ValueError(f"video_fps must be >= 0, got {video_fps!r}")
        if not (math.isfinite(physics_hz) and physics_hz >= 1.0 / MAX_PHYSICS_STEP_S):
            raise ValueError(
                f"physics_hz must be >= {1.0 / MAX_PHYSICS_STEP_S:.0f}, got {physics_hz!r}"
            )
        self._telemetry_hz = rate_hz
        self._video_fps = video_fps
        self._physics_timer = _Periodic(1.0 / physics_hz)
        self._telemetry_timer = _Periodic(1.0 / rate_hz)
        self._video_timer = _Periodic(1.0 / video_fps if video_fps > 0.0 else None)

        self._start_s = time.monotonic()
        self._physics = RobotPhysics(
            profile, initial_joints, now_s=self._start_s, world=world, turn_slip=turn_slip
        )
        links = _camera_links(profile) if world is not None and world.obstacles else None
        view = WorldView(world, links) if world is not None and world.obstacles else None
        extension: ExtendedServer | None = None
        if extended:
            codec = make_extension_codec(profile)
            if codec is None:
                raise ValueError("extended mode needs the profile's [extension] table")
            extension = ExtendedServer(
                profile,
                codec,
                status_hz=status_hz,
                battery_percent=battery_percent,
                drain_percent_per_s=battery_drain_percent_per_s,
                seed=seed,
                world=view,
                range_sensor=(
                    RangeSensor(
                        self._physics.world,
                        range_sensor,
                        mount_xy_m=profile.navigation.scan_mount_xy_m,
                        seed=seed,
                    )
                    if range_sensor is not None
                    else None
                ),
            )
        renderer = FrameRenderer(
            profile.link.camera_names,
            video_size,
            world=view,
            mounts=tuple(camera.mount for camera in profile.cameras),
        )
        self._robot = RobotServer(
            profile, self._physics, renderer, extension, seed=seed, noise_deg=noise_deg
        )
        self._fault_layer = FaultLayer(faults or FaultConfig(), seed, self._deliver)
        self._counters = _Counters()

        self._place_lock = threading.Lock()
        self._place_requests: list[_PlaceRequest] = []
        self._received: deque[ReceivedRcp] = deque(maxlen=RECEIVED_LOG_LENGTH)
        self._received_lock = threading.Lock()
        self._condition = threading.Condition()
        self._snapshot = self._build_snapshot()
        self._life_lock = threading.Lock()
        self._started = False
        self._closed = False

        self._owns_transport = transport is None
        self._transport = (
            UdpTransport((host, port), receive_buffer_bytes=RECEIVE_BUFFER_BYTES)
            if transport is None
            else transport
        )
        self._buffer = bytearray(MAX_DATAGRAM_BYTES)
        self._loop = SelectLoop("ocu-sim", on_error=self._on_error)
        self._loop.add_reader(self._transport.socket, self._read_datagrams)
        self.address: Address = self._transport.address

    # ---- public API -------------------------------------------------------------------------

    @property
    def telemetry_hz(self) -> float:
        """Telemetry packets per second."""
        return self._telemetry_hz

    @property
    def video_fps(self) -> float:
        """Video frames per second (0 = no video)."""
        return self._video_fps

    @property
    def faults(self) -> FaultConfig:
        """The fault settings in force."""
        return self._fault_layer.config

    def start(self) -> None:
        """Start the loop thread; a simulator runs once."""
        with self._life_lock:
            if self._closed:
                raise RuntimeError("simulator already stopped")
            if self._started:
                raise RuntimeError("simulator already started")
            self._started = True
            now_s = time.monotonic()
            self._start_s = now_s
            self._physics.advance(now_s)  # nothing moves before the first RCP
            for timer in (self._physics_timer, self._telemetry_timer, self._video_timer):
                timer.begin(now_s)
            self._publish()
            self._loop.start(self._step)
        log.info("ocu-sim listening on %s:%d", *self.address)

    def stop(self) -> None:
        """Stop the loop and close what it opened; safe to call more than once."""
        with self._life_lock:
            if self._closed:
                return
            self._closed = True
        self._loop.stop()
        self._loop.close()
        # A given transport (one end of a VirtualWire) stays its owner's to close.
        if self._owns_transport:
            self._transport.close()
        with self._condition:
            self._condition.notify_all()
        log.info("simulator stopped")

    def __enter__(self) -> RobotSimulator:
        if not self._started:
            self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.stop()

    def set_faults(
        self,
        *,
        loss: float | None = None,
        latency_ms: float | None = None,
        jitter_ms: float | None = None,
        duplicate: float | None = None,
    ) -> None:
        """Change some fault settings at run time; the others keep their values."""
        changes = {
            key: value
            for key, value in (
                ("loss", loss),
                ("latency_ms", latency_ms),
                ("jitter_ms", jitter_ms),
                ("duplicate", duplicate),
            )
            if value is not None
        }
        log.info("faults set: %s", self._fault_layer.change(**changes))

    def set_raw_position(self, joint: str, raw: int | None) -> None:
        """Report this raw position for a joint (a broken encoder); None: the true one again."""
        self._robot.set_raw_position(joint, raw)

    def set_noise_deg(self, noise_deg: float) -> None:
        """Reported positions get uniform noise of ±noise_deg (the true angle is unchanged)."""
        self._robot.set_noise_deg(noise_deg)

    def place(self, pose: Pose) -> None:
        """Put the robot somewhere in its world (tests, benchmarks); ValueError if it would
        overlap an obstacle. Thread-safe: done on the simulator's loop thread."""
        request = _PlaceRequest(pose)
        with self._place_lock:
            self._place_requests.append(request)
        self._loop.wake()
        if not request.done.wait(5.0):
            raise RuntimeError("the simulator did not place the robot")
        if request.error is not None:
            raise request.error

    def cut_link(self) -> None:
        """Drop every datagram in both directions until restore_link()."""
        self._fault_layer.set_cut(True)
        log.info("link cut")

    def restore_link(self) -> None:
        """End a cut_link()."""
        self._fault_layer.set_cut(False)
        log.info("link restored")

    @property
    def extension(self) -> ExtendedServer | None:
        """The extension side (stop_camera, set_battery, set_corrupt), None in vendor mode."""
        return self._robot.extension

    def state(self) -> SimState:
        """The latest snapshot."""
        with self._condition:
            return self._snapshot

    def wait_until(self, predicate: Callable[[SimState], bool], timeout: float) -> bool:
        """Wait until a snapshot satisfies predicate; False when timeout seconds pass first."""
        deadline_s = time.monotonic() + timeout
        with self._condition:
            while True:
                if predicate(self._snapshot):
                    return True
                remaining_s = deadline_s - time.monotonic()
                if remaining_s <= 0.0:
                    return False
                self._condition.wait(remaining_s)

    def received_commands(self) -> list[ReceivedRcp]:
        """Every RCP that got through the faults, oldest first (bounded log)."""
        with self._received_lock:
            return list(self._received)

    # ---- loop thread ------------------------------------------------------------------------

    def _on_error(self, err: BaseException) -> bool:
        # Never let one bad step kill the robot; timers were already rescheduled.
        self._counters.internal_errors += 1
        log.error("simulator loop error", exc_info=err)
        return True

    def _step(self, now_s: float) -> float:
        with self._place_lock:
            requests, self._place_requests = self._place_requests, []
        for request in requests:
            self._physics.advance(now_s)
            try:
                self._physics.place(request.pose)
            except ValueError as err:
                request.error = err
            self._publish()
            request.done.set()
        self._fault_layer.release_due(now_s)
        if self._physics_timer.due(now_s):
            self._physics.advance(now_s)
            self._publish()
        if self._telemetry_timer.due(now_s):
            telemetry = self._robot.telemetry(now_s, uptime_s=now_s - self._start_s)
            if telemetry is not None:
                self._fault_layer.route(Direction.TO_OCU, *telemetry, now_s)
                self._publish()
        if self._video_timer.due(now_s):
            frame = self._robot.video_frame(now_s)
            if frame is not None:
                self._fault_layer.route(Direction.TO_OCU, *frame, now_s)
        self._robot.poll_extension(
            now_s, lambda data, to: self._fault_layer.route(Direction.TO_OCU, data, to, now_s)
        )
        return min(
            self._physics_timer.next_s,
            self._telemetry_timer.next_s,
            self._video_timer.next_s,
            self._robot.next_due_s(),
            self._fault_layer.next_due_s(),
        )

    def _read_datagrams(self) -> None:
        for _ in range(MAX_DATAGRAMS_PER_WAKE):
            try:
                received = self._transport.receive(self._buffer)
            except OSError as err:
                # An ICMP error from an earlier send can surface here; it is not fatal.
                log.debug("receive error: %s", err)
                continue
            if received is None:
                return
            size, sender = received
            self._counters.datagrams_received += 1
            data = bytes(self._buffer[:size])
            self._fault_layer.route(Direction.TO_ROBOT, data, sender, time.monotonic())

    def _deliver(self, direction: Direction, data: bytes, address: Address, now_s: float) -> None:
        if direction is Direction.TO_ROBOT:
            packet = self._robot.receive(data, address, now_s)
            if packet is not None:
                with self._received_lock:
                    sequence = self._robot.applied_sequence
                    self._received.append(ReceivedRcp(now_s, packet, address, sequence))
                self._publish()
            return
        try:
            self._transport.send(data, address)
        except OSError as err:
            self._counters.send_errors += 1
            log.debug("send to %s:%d failed: %s", address[0], address[1], err)
        else:
            self._counters.datagrams_sent += 1

    # ---- snapshots --------------------------------------------------------------------------

    def _build_snapshot(self) -> SimState:
        physics, robot, faults = self._physics, self._robot, self._fault_layer
        return SimState(
            time_s=physics.time_s,
            elapsed_s=physics.time_s - self._start_s,
            joints_rad=physics.joints_rad,
            velocities=physics.velocities,
            commanded_velocities=physics.commanded_velocities,
            track_speeds_m_s=physics.track_speeds_m_s,
            pose=physics.pose,
            torch=robot.torch,
            camera=robot.camera,
            video_quality=robot.video_quality,
            client=robot.client,
            watchdog_stopped=physics.watchdog_stopped,
            waist_suppressed=physics.waist_suppressed,
            all_stopped=physics.all_stopped,
            link_cut=faults.cut,
            rcp_count=robot.counters.rcp,
            telemetry_sent=robot.counters.telemetry_sent,
            video_sent=robot.counters.video_sent,
            malformed_count=robot.counters.malformed,
            foreign_count=robot.counters.foreign,
            stale_rcp_count=robot.counters.stale_rcp,
            datagrams_received=self._counters.datagrams_received,
            datagrams_sent=self._counters.datagrams_sent,
            dropped_to_robot=faults.dropped_to_robot,
            dropped_to_ocu=faults.dropped_to_ocu,
            dropped_by_faults=faults.dropped_to_robot + faults.dropped_to_ocu,
            duplicated=faults.duplicated,
            send_errors=self._counters.send_errors,
            internal_errors=self._counters.internal_errors,
            extended=None if robot.extension is None else robot.extension.counters(physics.time_s),
            collisions=physics.collisions,
            in_contact=physics.in_contact,
        )

    def _publish(self) -> None:
        snapshot = self._build_snapshot()
        with self._condition:
            self._snapshot = snapshot
            self._condition.notify_all()


class StateRecorder:
    """Ground truth for tests and benchmarks: every snapshot the simulator publishes.

    A thread of its own waits on the simulator's condition, so no physics step is missed.
    """

    def __init__(self, sim: RobotSimulator) -> None:
        self.sim = sim
        self.samples: list[SimState] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sim-state-recorder")
        self._thread.start()

    def _record(self, state: SimState) -> bool:
        if not self.samples or self.samples[-1] is not state:
            self.samples.append(state)
        return self._stop.is_set()

    def _run(self) -> None:
        while not self._stop.is_set():
            self.sim.wait_until(self._record, timeout=0.5)

    def stop(self) -> None:
        """Stop recording and join the thread."""
        self._stop.set()
        self._thread.join(2.0)
