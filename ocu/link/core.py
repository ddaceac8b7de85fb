"""The UDP link to the robot: a plain Python network loop, testable without Qt.

One loop thread owns the periodic work: the RCP tick, e-stop repeats, the watchdogs and the
receive path. Command changes and the first e-stop datagram are sent from the caller's thread
at once, so a busy loop (or Python's GIL switch interval) cannot delay them.
"""

from __future__ import annotations

import contextlib
import ipaddress
import logging
import selectors
import socket
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from enum import Enum

from ocu.control.commands import (
    Command,
    CommandMapper,
    JointReading,
    VelocityLimits,
    commanded_motor_speeds,
    make_codec,
    read_telemetry,
)
from ocu.control.plausibility import PlausibilityChecker
from ocu.link.delay import DelayEstimator
from ocu.link.reassembly import Reassembler, ReassemblyStats
from ocu.link.stats import LinkStats, LossEstimator, RateMeter
from ocu.profile import RobotProfile
from ocu.protocol import (
    ProtocolError,
    RemoteControlPacket,
    TelemetryPacket,
    VideoFramePacket,
)
from ocu.protocol.extended import (
    CameraRequest,
    ExtendedCodec,
    HelloPacket,
    StatusPacket,
    VideoFragment,
)

log = logging.getLogger("ocu.link")

RECV_BUFFER_BYTES = 65536
RECV_SOCKET_BYTES = 4 * 1024 * 1024
MAX_DATAGRAMS_PER_WAKE = 256
STATS_PERIOD_S = 0.5
# A telemetry tick this far (in seconds of ticks) below the newest one is a robot that
# restarted, not a late packet.
TICK_RESTART_S = 10.0


class LinkError(OSError):
    """The link cannot be set up (unresolvable host, address in use)."""


class LinkState(Enum):
    """Whether valid packets are arriving from the robot."""

    CONNECTING = "connecting"
    CONNECTED = "connected"
    LOST = "LINK LOST"
    CLOSED = "closed"


@dataclass(frozen=True)
class TelemetryFrame:
    """One decoded telemetry packet with its SI readings and arrival times.

    Readings the OCU does not believe carry their `fault`. `delay_s` is the round trip this
    packet took by the link's measurement (ocu.link.delay): the reading was taken when the
    commands sent `delay_s` before `received_at` had reached the robot. None: not known.
    """

    packet: TelemetryPacket
    readings: dict[str, JointReading]
    received_at: float
    wall_time: float
    delay_s: float | None = None

    @property
    def faults(self) -> dict[str, str]:
        """Joint name to why its reading is implausible."""
        return {name: r.fault for name, r in self.readings.items() if r.fault is not None}


@dataclass(frozen=True)
class VideoFrame:
    """One JPEG frame from the robot and when it arrived.

    A vendor frame carries no camera id: `camera` is the camera the OCU last selected (None
    before any selection). An extension frame carries its camera, sequence number and the
    robot's capture time (microseconds of the robot's monotonic clock).
    """

    jpeg: bytes
    camera: int | None
    received_at: float
    wall_time: float
    sequence: int | None = None
    capture_time_us: int | None = None


@dataclass(frozen=True)
class StatusFrame:
    """One extension status packet in SI units (None = the robot did not measure it)."""

    packet: StatusPacket
    received_at: float
    wall_time: float

    @property
    def voltage_v(self) -> float | None:
        """Battery voltage in volts."""
        mv = self.packet.voltage_mv
        return None if mv is None else mv / 1000.0

    @property
    def charge_percent(self) -> float | None:
        """Battery charge in percent."""
        permille = self.packet.charge_permille
        return None if permille is None else permille / 10.0

    @property
    def headlight_on(self) -> bool | None:
        """Headlight state as the robot reports it."""
        return self.packet.headlight_on

    @property
    def roll_rad(self) -> float | None:
        """Roll angle in radians."""
        mrad = self.packet.roll_mrad
        return None if mrad is None else mrad / 1000.0

    @property
    def pitch_rad(self) -> float | None:
        """Pitch angle in radians."""
        mrad = self.packet.pitch_mrad
        return None if mrad is None else mrad / 1000.0


class LinkListener:
    """Receives the link's events on the loop thread; override what you need."""

    def telemetry_received(self, frame: TelemetryFrame) -> None:
        """A valid telemetry packet arrived."""

    def video_frame_received(self, frame: VideoFrame) -> None:
        """A valid video frame arrived (vendor packet, or extension frame reassembled)."""

    def status_received(self, frame: StatusFrame) -> None:
        """An extension status packet arrived."""

    def extension_changed(self, active: bool, reason: str) -> None:
        """The robot started or stopped speaking the protocol extension."""

    def link_state_changed(self, state: LinkState, reason: str) -> None:
        """The link changed state."""

    def stats_updated(self, stats: LinkStats) -> None:
        """Periodic counters and rates."""

    def safety_event(self, message: str) -> None:
        """The link stopped the robot by itself or on request (e-stop, watchdogs)."""

    def datagram_sent(self, data: bytes, sent_at: float) -> None:
        """A datagram went on the wire (for recording)."""

    def datagram_received(self, data: bytes, received_at: float) -> None:
        """A datagram from the robot arrived, valid or not (for recording)."""


def is_loopback(host: str) -> bool:
    """Whether a host string names a loopback address."""
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


class LinkCore:
    """Sends RCPs to the robot and turns what comes back into events."""

    def __init__(
        self,
        profile: RobotProfile,
        robot_address: tuple[str, int],
        *,
        listener: LinkListener | None = None,
        bind_address: tuple[str, int] | None = None,
        link_lost_after_s: float | None = None,
        gui_alive_timeout_s: float | None = -1.0,
        send_rate_hz: float | None = None,
        send_on_change: bool = True,
        extension: bool = False,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.profile = profile
        self.listener = listener or LinkListener()
        self.clock = clock
        self.limits = VelocityLimits(profile)
        # False leaves changes to the periodic tick, as the vendor client does (benchmarks).
        self.send_on_change = send_on_change
        self._mapper = CommandMapper(profile)
        self._codec = make_codec(profile)
        settings = profile.link
        self.link_lost_after_s = (
            settings.link_lost_after_s if link_lost_after_s is None else link_lost_after_s
        )
        # None disables the GUI-alive watchdog (a caller with its own timeout, e.g. ROS).
        self.gui_alive_timeout_s = (
            settings.gui_alive_timeout_s
            if gui_alive_timeout_s is not None and gui_alive_timeout_s < 0
            else gui_alive_timeout_s
        )

        try:
            robot_host = socket.gethostbyname(robot_address[0])
        except OSError as err:
            raise LinkError(f"cannot resolve robot host {robot_address[0]!r}: {err}") from err
        self.robot_address = (robot_host, robot_address[1])
        if bind_address is None:
            bind_address = ("127.0.0.1" if is_loopback(robot_host) else "0.0.0.0", 0)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind(bind_address)
        except OSError as err:
            self._sock.close()
            raise LinkError(f"cannot bind {bind_address[0]}:{bind_address[1]}: {err}") from err
        # Room for a burst of video frames; the kernel caps this at net.core.rmem_max.
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECV_SOCKET_BYTES)
        self._sock.setblocking(False)
        self.address: tuple[str, int] = self._sock.getsockname()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)

        self._lock = threading.RLock()
        # Re-entrant: a signal handler or listener that sends while this thread is already
        # inside a send must not deadlock the link.
        self._send_lock = threading.RLock()
        self._command = Command(video_bitrate=settings.default_video_bitrate)
        self._rate_hz = settings.send_rate_hz if send_rate_hz is None else send_rate_hz
        self._check_rate(self._rate_hz)
        self._estop_due: list[float] = []
        self._estop_latched = False
        self._gui_alive_at = clock()
        self._gui_tripped = False
        # The thread that calls heartbeat() owns the commands; until one does, whoever sets
        # commands counts as alive by doing so.
        self._owner_thread: int | None = None
        self._stop_requested = threading.Event()
        self._loop_exited = threading.Event()
        self._loop_exited.set()
        self._closed = False
        self._thread: threading.Thread | None = None

        self._state = LinkState.CONNECTING
        self._started_at = clock()
        self._last_valid_at: float | None = None
        self._sent = 0
        self._send_errors = 0
        self._received = 0
        self._telemetry = 0
        self._video = 0
        self._malformed = 0
        self._foreign = 0
        self._rcp_rate = RateMeter()
        self._telemetry_rate = RateMeter()
        self._video_rate = RateMeter(window_s=1.0)
        self._loss = LossEstimator()
        self._delay = DelayEstimator()
        self._plausibility = PlausibilityChecker(profile)
        self._last_tick: int | None = None
        self._stale_telemetry = 0

        # The protocol extension: probe with a hello on every tick when asked to and the
        # profile defines it (and does not switch probing off).
        ext = profile.extension
        self.extension_enabled = extension and ext is not None and ext.probe
        self._ext_codec: ExtendedCodec | None = None
        self._hello = HelloPacket()
        if ext is not None:
            types = ext.frame_types
            self._ext_codec = ExtendedCodec(types.hello, types.video_fragment, types.status)
            self._hello = HelloPacket(
                cameras=tuple(
                    CameraRequest(
                        camera=index,
                        width_px=ext.stream_width_px,
                        height_px=ext.stream_height_px,
                        fps=ext.stream_fps,
                    )
                    for index in range(len(settings.camera_names))
                ),
                max_datagram_bytes=ext.max_datagram_bytes,
            )
        video = profile.video
        self._reassembler = Reassembler(
            video.reassembly_max_frames, video.reassembly_max_bytes, video.reassembly_timeout_s
        )
        self._ext_active = False
        self._ext_last_at: float | None = None
        self._ext_received = 0
        self._ext_malformed = 0
        self._hellos_sent = 0

    # ---- commands (any thread) -------------------------------------------------------------

    @property
    def command(self) -> Command:
        """The command currently being sent."""
        with self._lock:
            return self._command

    @property
    def state(self) -> LinkState:
        """The current link state."""
        with self._lock:
            return self._state

    def set_command(self, command: Command) -> None:
        """Replace the command; sends it at once when it differs from the current one."""
        with self._lock:
            changed = self._replace_command(command)
        if changed and self.send_on_change:
            self._send_current()

    def set_velocities(self, **velocities: float) -> None:
        """Change some channels of the current command (SI units), atomically."""
        with self._lock:
            changed = self._replace_command(self._command.with_velocities(velocities))
        if changed and self.send_on_change:
            self._send_current()

    def _replace_command(self, command: Command) -> bool:
        """Install a new command (lock held); whether it differs from the old one."""
        if self._owner_thread in (None, threading.get_ident()):
            self._gui_alive_at = self.clock()
            self._gui_tripped = False
        elif self._owner_silent():
            # Commands from another thread (a ROS bridge hosted by the GUI) must neither
            # hide a stalled owner nor move the robot while it is stalled.
            command = command.stopped()
        if self._state is LinkState.LOST:
            # A robot the OCU cannot hear may still hear the OCU: it would drive blind.
            command = command.stopped()
        if command.is_motion:
            self._estop_latched = False
        if command == self._command:
            return False
        self._command = command
        return True

    def set_max_velocity(self, channel: str, value: float) -> float:
        """Change a channel's maximum (clipped to the hard maximum); resends if that matters."""
        with self._lock:
            kept = self.limits.set(channel, value)
        self._send_current()
        return kept

    def emergency_stop(self, reason: str = "operator") -> None:
        """Zero every velocity now and repeat the zero command within the e-stop window."""
        settings = self.profile.link
        with self._lock:
            self._command = self._command.stopped()
            self._estop_latched = True
            now = self.clock()
            repeats = settings.estop_repeats - 1
            step = settings.estop_window_s / repeats if repeats > 0 else 0.0
            self._estop_due = [now + step * (k + 1) for k in range(repeats)]
        self._send_current()
        self._wake()
        self._notify_safety(f"EMERGENCY STOP ({reason})")

    def _owner_silent(self) -> bool:
        timeout = self.gui_alive_timeout_s
        return timeout is not None and self.clock() - self._gui_alive_at > timeout

    def heartbeat(self) -> None:
        """Confirm that the thread owning the commands is alive (it becomes the owner)."""
        with self._lock:
            self._owner_thread = threading.get_ident()
            self._gui_alive_at = self.clock()
            self._gui_tripped = False

    def set_rate_hz(self, rate_hz: float) -> None:
        """Change the periodic send rate (bounded by the profile, 1-50 Hz for the Engineer)."""
        self._check_rate(rate_hz)
        with self._lock:
            self._rate_hz = rate_hz
        self._wake()

    @property
    def rate_hz(self) -> float:
        """The periodic send rate."""
        with self._lock:
            return self._rate_hz

    @property
    def extension_active(self) -> bool:
        """Whether the robot speaks the protocol extension (valid packets lately)."""
        with self._lock:
            return self._ext_active

    @property
    def stream_request(self) -> HelloPacket:
        """The hello sent to probe for the extension, with the per-camera stream request."""
        with self._lock:
            return self._hello

    def set_stream_request(self, cameras: Sequence[CameraRequest]) -> None:
        """Ask an extended robot for these per-camera streams; sent at once if it changed."""
        hello = HelloPacket(
            cameras=tuple(cameras), max_datagram_bytes=self._hello.max_datagram_bytes
        )
        hello.check()
        with self._lock:
            if hello == self._hello:
                return
            self._hello = hello
        self._send_hello()

    def video_stats(self) -> ReassemblyStats:
        """Counters of the extension's fragment reassembly."""
        with self._lock:
            return self._reassembler.stats()

    def _check_rate(self, rate_hz: float) -> None:
        low, high = self.profile.link.send_rate_min_hz, self.profile.link.send_rate_max_hz
        if not low <= rate_hz <= high:
            raise ValueError(f"send rate must be within {low:g}-{high:g} Hz, got {rate_hz!r}")

    # ---- loop ------------------------------------------------------------------------------

    def start(self) -> None:
        """Run the loop in a named daemon thread (for users without Qt)."""
        if self._thread is not None:
            return
        self._loop_exited.clear()
        self._thread = threading.Thread(target=self._run_loop, name="ocu-link", daemon=True)
        self._thread.start()

    def run(self) -> None:
        """Run the loop in the calling thread until shutdown() (the QThread adapter's body)."""
        self._loop_exited.clear()
        self._run_loop()

    def _run_loop(self) -> None:
        selector = selectors.DefaultSelector()
        selector.register(self._sock, selectors.EVENT_READ, "sock")
        selector.register(self._wake_r, selectors.EVENT_READ, "wake")
        buffer = bytearray(RECV_BUFFER_BYTES)
        now = self.clock()
        next_tick = now
        next_stats = now + STATS_PERIOD_S
        try:
            while not self._stop_requested.is_set():
                now = self.clock()
                if now >= next_tick:
                    self._send_current()
                    self._send_hello()
                    next_tick = max(next_tick + 1.0 / self.rate_hz, now)
                if now >= next_stats:
                    self._emit_stats(now)
                    next_stats = now + STATS_PERIOD_S
                self._check_watchdogs(now)
                due = self._send_due_estops(now)
                deadline = min(next_tick, next_stats, due) if due else min(next_tick, next_stats)
                timeout = max(deadline - self.clock(), 0.0)
                for key, _ in selector.select(min(timeout, 0.1)):
                    if key.data == "wake":
                        self._drain_wake()
                    else:
                        self._receive_all(buffer)
                with self._lock:
                    # A rate change takes effect at once rather than after the old period.
                    next_tick = min(next_tick, self.clock() + 1.0 / self._rate_hz)
        except Exception:
            log.exception("link loop failed; sending zeros")
            self._send_zeros()
            raise
        finally:
            selector.close()
            self._loop_exited.set()

    def _send_due_estops(self, now: float) -> float | None:
        with self._lock:
            due = [t for t in self._estop_due if t <= now]
            self._estop_due = [t for t in self._estop_due if t > now]
            next_due = min(self._estop_due) if self._estop_due else None
        for _ in due:
            self._send_current()
        return next_due

    def _check_watchdogs(self, now: float) -> None:
        message = None
        with self._lock:
            timeout = self.gui_alive_timeout_s
            stalled_s = now - self._gui_alive_at
            if (
                timeout is not None
                and self._command.is_motion
                and not self._gui_tripped
                and stalled_s > timeout
            ):
                self._gui_tripped = True
                self._command = self._command.stopped()
                message = f"control thread silent for {stalled_s:.2f} s: motion commands zeroed"
            last = self._last_valid_at if self._last_valid_at is not None else self._started_at
            lost = self._state in (LinkState.CONNECTED, LinkState.CONNECTING) and (
                now - last > self.link_lost_after_s
            )
        ext_lost_reason = None
        with self._lock:
            self._reassembler.expire(now)
            if (
                self._ext_active
                and self._ext_last_at is not None
                and now - self._ext_last_at > self.link_lost_after_s
            ):
                self._ext_active = False
                ext_lost_reason = (
                    f"no extension packet for {now - self._ext_last_at:.1f} s: vendor protocol"
                )
        if ext_lost_reason is not None:
            log.info("extension lost: %s", ext_lost_reason)
            self._call(self.listener.extension_changed, False, ext_lost_reason)
        if message:
            self._send_current()
            self._notify_safety(message)
        if lost:
            silence = now - last
            reason = f"no valid packet from the robot for {silence:.1f} s"
            with self._lock:
                had_motion = self._command.is_motion
                self._command = self._command.stopped()
            with self._lock:
                # The robot may restart while the OCU cannot hear it.
                self._last_tick = None
                self._plausibility.reset()
            self._set_state(LinkState.LOST, reason)
            if had_motion:
                self._send_current()
                self._notify_safety("link lost: motion commands zeroed")

    def _drain_wake(self) -> None:
        try:
            while self._wake_r.recv(4096):
                pass
        except BlockingIOError:
            pass

    def _wake(self) -> None:
        # A full wake pipe already guarantees a wake-up; a closed one means shutdown.
        with contextlib.suppress(OSError):
            self._wake_w.send(b"\0")

    # ---- receive ---------------------------------------------------------------------------

    def _receive_all(self, buffer: bytearray) -> None:
        view = memoryview(buffer)
        for _ in range(MAX_DATAGRAMS_PER_WAKE):
            try:
                size, source = self._sock.recvfrom_into(buffer)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as err:
                # ICMP port-unreachable from a closed robot port surfaces here on Linux.
                log.debug("receive error: %s", err)
                continue
            self.handle_datagram(bytes(view[:size]), source)

    def handle_datagram(self, data: bytes, source: tuple[str, int]) -> None:
        """Count, decode and dispatch one datagram; never raises on bad input."""
        now = self.clock()
        if source[:2] != self.robot_address:
            with self._lock:
                self._foreign += 1
            return
        self._call(self.listener.datagram_received, data, now)
        # Without probing, extension types stay unknown: malformed, exactly as before.
        if (
            self.extension_enabled
            and self._ext_codec is not None
            and self._ext_codec.handles(data[0] if data else -1)
        ):
            self._handle_extended(data, source, now)
            return
        try:
            packet = self._codec.decode(data)
        except ProtocolError as err:
            with self._lock:
                self._malformed += 1
            log.debug("malformed datagram (%d bytes): %s", len(data), err)
            return
        if isinstance(packet, RemoteControlPacket):
            with self._lock:
                self._foreign += 1  # an RCP never comes from the robot
            return
        frame: TelemetryFrame | None = None
        with self._lock:
            self._received += 1
            self._last_valid_at = now
            if isinstance(packet, TelemetryPacket):
                self._telemetry += 1
                self._telemetry_rate.add(now)
                self._loss.add(packet.tick, now)
                frame = self._telemetry_frame(packet, now)
            else:
                self._video += 1
                self._video_rate.add(now)
            became_connected = self._state != LinkState.CONNECTED
            camera = self._command.camera
        if became_connected:
            self._set_state(LinkState.CONNECTED, f"packets from {source[0]}:{source[1]}")
        wall = time.time()
        if isinstance(packet, TelemetryPacket):
            if frame is not None:
                self._call(self.listener.telemetry_received, replace(frame, wall_time=wall))
        elif isinstance(packet, VideoFramePacket):
            self._call(
                self.listener.video_frame_received, VideoFrame(packet.jpeg, camera, now, wall)
            )

    def _telemetry_frame(self, packet: TelemetryPacket, now: float) -> TelemetryFrame | None:
        """Readings judged and the delay measured; None for an old packet (lock held).

        A packet whose tick is not newer than the newest seen is a duplicate or came late
        (reordered): its readings are older than what the OCU already knows, so it is counted
        and goes no further.
        """
        last = self._last_tick
        restart = self.profile.link.telemetry_tick_hz * TICK_RESTART_S
        if last is not None and packet.tick <= last and last - packet.tick < restart:
            self._stale_telemetry += 1
            return None
        if last is not None and packet.tick < last:
            log.info("telemetry tick went back from %d to %d: robot restarted", last, packet.tick)
            self._plausibility.reset()
        self._last_tick = packet.tick
        readings = read_telemetry(self.profile, packet)
        faults = self._plausibility.check(packet, readings)
        for name, fault in faults.items():
            readings[name] = replace(readings[name], fault=fault)
        echoes = {record.device_id: record.speed_command for record in packet.motors}
        delay_s = self._delay.on_telemetry(now, echoes)
        return TelemetryFrame(packet, readings, now, 0.0, delay_s)

    def _handle_extended(self, data: bytes, source: tuple[str, int], now: float) -> None:
        assert self._ext_codec is not None
        try:
            packet = self._ext_codec.decode(data)
        except ProtocolError as err:
            with self._lock:
                self._malformed += 1
                self._ext_malformed += 1
            log.debug("malformed extension datagram (%d bytes): %s", len(data), err)
            return
        if isinstance(packet, HelloPacket):
            with self._lock:
                self._foreign += 1  # a hello never comes from the robot
            return
        complete = None
        with self._lock:
            self._received += 1
            self._ext_received += 1
            self._last_valid_at = now
            self._ext_last_at = now
            became_active = not self._ext_active
            self._ext_active = True
            became_connected = self._state != LinkState.CONNECTED
            if isinstance(packet, VideoFragment):
                complete = self._reassembler.add(packet, now)
                if complete is not None:
                    self._video += 1
                    self._video_rate.add(now)
        if became_connected:
            self._set_state(LinkState.CONNECTED, f"packets from {source[0]}:{source[1]}")
        if became_active:
            log.info("robot speaks the protocol extension")
            self._call(self.listener.extension_changed, True, "extension packets from the robot")
        wall = time.time()
        if isinstance(packet, StatusPacket):
            self._call(self.listener.status_received, StatusFrame(packet, now, wall))
        elif complete is not None:
            frame = VideoFrame(
                complete.jpeg,
                complete.camera,
                now,
                wall,
                sequence=complete.sequence,
                capture_time_us=complete.capture_time_us,
            )
            self._call(self.listener.video_frame_received, frame)

    # ---- send ------------------------------------------------------------------------------

    def current_packet(self) -> RemoteControlPacket:
        """The RCP for the current command under the current limits."""
        with self._lock:
            return self._mapper.to_packet(self._command, self.limits)

    def _send_current(self) -> None:
        # Built and sent under one lock: a tick that read the command just before the
        # operator stopped must not put its stale motion on the wire after the stop.
        with self._send_lock:
            self._send_packet(self.current_packet())

    def _send_hello(self) -> None:
        if not self.extension_enabled or self._ext_codec is None:
            return
        with self._lock:
            hello = self._hello
        data = self._ext_codec.encode(hello)
        if self._send_datagram(data) is not None:
            with self._lock:
                self._hellos_sent += 1

    def _send_zeros(self) -> None:
        with self._lock:
            zero = self._mapper.to_packet(self._command.stopped(), self.limits)
        self._send_packet(zero)

    def _send_packet(self, packet: RemoteControlPacket) -> None:
        sent_at = self._send_datagram(self._codec.encode(packet))
        if sent_at is not None:
            echoes = commanded_motor_speeds(self.profile, self._mapper.to_command(packet))
            with self._lock:
                self._sent += 1
                self._rcp_rate.add(sent_at)
                self._delay.on_sent(sent_at, echoes)

    def _send_datagram(self, data: bytes) -> float | None:
        """Put one datagram on the wire; its send time, or None if closed or it failed."""
        with self._send_lock:
            if self._closed:
                return None
            try:
                self._sock.sendto(data, self.robot_address)
            except OSError as err:
                with self._lock:
                    self._send_errors += 1
                log.debug("send failed: %s", err)
                return None
            sent_at = self.clock()
        self._call(self.listener.datagram_sent, data, sent_at)
        return sent_at

    # ---- state and stats -------------------------------------------------------------------

    def _set_state(self, state: LinkState, reason: str) -> None:
        with self._lock:
            if self._state == state:
                return
            self._state = state
        log.info("link %s: %s", state.value, reason)
        self._call(self.listener.link_state_changed, state, reason)

    def stats(self) -> LinkStats:
        """Counters and rates now."""
        now = self.clock()
        with self._lock:
            return LinkStats(
                sent=self._sent,
                received=self._received,
                telemetry=self._telemetry,
                video=self._video,
                malformed=self._malformed,
                foreign=self._foreign,
                send_errors=self._send_errors,
                rcp_rate_hz=self._rcp_rate.rate(now),
                telemetry_rate_hz=self._telemetry_rate.rate(now),
                video_rate_hz=self._video_rate.rate(now),
                loss_estimate=self._loss.loss(now),
                duplicates=self._loss.duplicates,
                reordered=self._loss.reordered,
                last_valid_age_s=None if self._last_valid_at is None else now - self._last_valid_at,
                send_rate_hz=self._rate_hz,
                estop_latched=self._estop_latched,
                delay_s=self._delay.estimate_s,
                stale_telemetry=self._stale_telemetry,
            )

    def _emit_stats(self, now: float) -> None:
        self._call(self.listener.stats_updated, self.stats())

    def _notify_safety(self, message: str) -> None:
        log.warning("%s", message)
        self._call(self.listener.safety_event, message)

    def _call(self, callback: Callable[..., None], *args: object) -> None:
        # A faulty listener must not take the link (and with it the robot's safety) down.
        try:
            callback(*args)
        except Exception:
            log.exception("link listener %s failed", getattr(callback, "__name__", callback))

    # ---- shutdown --------------------------------------------------------------------------

    def shutdown(self, timeout_s: float = 2.0) -> None:
        """Stop the loop, send zeros last and close the socket; safe to call twice."""
        with self._send_lock:
            if self._closed:
                return
        self._stop_requested.set()
        self._wake()
        if not self._loop_exited.wait(timeout_s):
            log.error("link loop did not stop within %.1f s", timeout_s)
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout_s)
        with self._lock:
            self._command = self._command.stopped()
            self._estop_due = []
        for _ in range(self.profile.link.estop_repeats):
            self._send_zeros()
        with self._send_lock:
            self._closed = True
            self._sock.close()
        self._wake_r.close()
        self._wake_w.close()
        self._set_state(LinkState.CLOSED, "shut down")

    def __enter__(self) -> LinkCore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.shutdown()
