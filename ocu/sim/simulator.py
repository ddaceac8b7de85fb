"""The robot simulator: a UDP server that behaves as the documents say the Engineer does.

One loop thread ("ocu-sim") owns the socket and all robot state. It answers the sender of the
latest valid RCP with telemetry and video, integrates joint velocities within the profile's
limits, stops every motor when RCPs stop for the watchdog time, and keeps a ground-truth pose
of the chassis. Other threads read thread-safe snapshots (`state()`, `wait_until()`).

Telemetry motor records (raw units use the profile's telemetry scales):

- device state 1 = operational; operation mode 2 = velocity mode.
- position: the joint angle in ticks (`rad_to_ticks`); position command: the same value,
  as the robot runs in velocity mode. Tracks report no position: both fields are 0.
- speed: the effective speed (joints in rad/s, tracks their belt speed in m/s) times
  `telemetry_speed_per_rad_s`; speed command: the speed the latest RCP asks for (zero after
  a watchdog stop) in the same units.
- current: idle + k*|speed| amperes times `telemetry_current_per_amp`; current command: the
  same model applied to the commanded speed.
- status bits:
  bit0 (0x1) at the lower limit,
  bit1 (0x2) at the upper limit,
  bit2 (0x4) stopped by the watchdog,
  bit3 (0x8) motion suppressed (waist commanded while the chassis moves).
"""

from __future__ import annotations

import contextlib
import logging
import math
import random
import selectors
import socket
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from types import TracebackType
from typing import NamedTuple

from ocu.control.commands import CommandMapper, rad_to_ticks, track_speeds
from ocu.profile import Motor, RobotProfile
from ocu.protocol import (
    MotorRecord,
    ProtocolError,
    RemoteControlPacket,
    TelemetryPacket,
    VideoFramePacket,
)
from ocu.protocol.extended import ExtendedCodec, HelloPacket
from ocu.protocol.wire import make_codec
from ocu.records import Command
from ocu.sim.extended import (
    DEFAULT_DRAIN_PERCENT_PER_S,
    DEFAULT_STATUS_HZ,
    ExtendedCounters,
    ExtendedServer,
)
from ocu.sim.faults import DelayLine, Direction, FaultConfig, make_injectors
from ocu.sim.video import DEFAULT_QUALITY, FrameRenderer, quality_for_bitrate

log = logging.getLogger("ocu.sim")

STATUS_AT_LOWER_LIMIT = 0x1
STATUS_AT_UPPER_LIMIT = 0x2
STATUS_WATCHDOG_STOP = 0x4
STATUS_SUPPRESSED = 0x8
DEVICE_STATE_OPERATIONAL = 1
OPERATION_MODE_VELOCITY = 2

# Simulator model constants, not robot facts: currents of the right order for small servos.
JOINT_IDLE_CURRENT_A = 0.3
JOINT_CURRENT_A_PER_RAD_S = 2.0
TRACK_IDLE_CURRENT_A = 0.5
TRACK_CURRENT_A_PER_M_S = 8.0

# The watchdog contract (stop within 1.0-1.3 s) needs physics steps of at most 10 ms.
MAX_PHYSICS_STEP_S = 0.01
RECEIVED_LOG_LENGTH = 10_000
RECEIVE_BUFFER_BYTES = 1 << 20
MAX_DATAGRAM_BYTES = 65_535
# Bounds one burst of reading so a flood cannot starve the physics timer.
MAX_DATAGRAMS_PER_WAKE = 256
STOP_JOIN_TIMEOUT_S = 5.0


_I16_MIN = -32768
_I16_MAX = 32767


class ReceivedRcp(NamedTuple):
    """One RCP that got through the faults: monotonic receive time, packet and sender."""

    time_s: float
    packet: RemoteControlPacket
    address: tuple[str, int]


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
    pose: tuple[float, float, float]
    torch: bool
    camera: int
    video_quality: int
    client: tuple[str, int] | None
    watchdog_stopped: bool
    waist_suppressed: bool
    all_stopped: bool
    link_cut: bool
    rcp_count: int
    telemetry_sent: int
    video_sent: int
    malformed_count: int
    foreign_count: int
    datagrams_received: int
    datagrams_sent: int
    dropped_to_robot: int
    dropped_to_ocu: int
    dropped_by_faults: int
    duplicated: int
    send_errors: int
    internal_errors: int
    extended: ExtendedCounters | None = None


@dataclass
class _Counters:
    rcp: int = 0
    telemetry_sent: int = 0
    video_sent: int = 0
    malformed: int = 0
    foreign: int = 0
    datagrams_received: int = 0
    datagrams_sent: int = 0
    dropped_to_robot: int = 0
    dropped_to_ocu: int = 0
    duplicated: int = 0
    send_errors: int = 0
    internal_errors: int = 0


def _limits_rad(motor: Motor) -> tuple[float, float]:
    return motor.limits_rad if motor.limits_rad is not None else (-math.inf, math.inf)


def _raw_i16(value: float) -> int:
    return int(min(max(round(value), _I16_MIN), _I16_MAX))


def _next_due(due_s: float, period_s: float, now_s: float) -> float:
    # Keep a fixed schedule, but skip the backlog after a stall rather than bursting.
    due_s += period_s
    return due_s if due_s > now_s else now_s + period_s


class RobotSimulator:
    """A simulated Engineer robot server on a UDP socket."""

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
    ) -> None:
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
        if not (math.isfinite(noise_deg) and noise_deg >= 0.0):
            raise ValueError(f"noise_deg must be >= 0, got {noise_deg!r}")
        self._noise_rad = math.radians(noise_deg)
        self._noise_rng = random.Random(seed)
        self._raw_faults: dict[str, int] = {}
        self._telemetry_hz = rate_hz
        self._video_fps = video_fps
        self._physics_period_s = 1.0 / physics_hz
        self._telemetry_period_s = 1.0 / rate_hz
        self._video_period_s = 1.0 / video_fps if video_fps > 0.0 else None
        self._codec = make_codec(profile)
        self._mapper = CommandMapper(profile)
        self._renderer = FrameRenderer(profile.link.camera_names, video_size)
        # The protocol extension (ocu.sim.extended): a vendor-mode simulator still knows its
        # frame types, to count such packets as foreign rather than as malformed.
        self._ext_codec: ExtendedCodec | None = None
        self._ext: ExtendedServer | None = None
        ext_settings = profile.extension
        if ext_settings is not None:
            types = ext_settings.frame_types
            self._ext_codec = ExtendedCodec(types.hello, types.video_fragment, types.status)
        if extended:
            if self._ext_codec is None:
                raise ValueError("extended mode needs the profile's [extension] table")
            self._ext = ExtendedServer(
                profile,
                self._ext_codec,
                status_hz=status_hz,
                battery_percent=battery_percent,
                drain_percent_per_s=battery_drain_percent_per_s,
                seed=seed,
            )

        self._fault_lock = threading.Lock()
        self._faults = faults if faults is not None else FaultConfig()
        self._link_cut = False
        self._injectors = make_injectors(seed)
        self._delay_line = DelayLine()

        self._channel_motors = {
            motor.channel: motor for motor in profile.positioned_motors if motor.channel
        }
        self._angles_rad = self._initial_angles(initial_joints or {})
        self._velocities = dict.fromkeys(profile.channels, 0.0)
        self._commanded = dict.fromkeys(profile.channels, 0.0)
        self._track_speeds_m_s = (0.0, 0.0)
        self._commanded_tracks_m_s = (0.0, 0.0)
        self._pose = (0.0, 0.0, 0.0)
        self._waist_suppressed = False
        self._command: Command | None = None
        self._last_rcp_s = 0.0
        self._watchdog_stopped = False
        self._torch = False
        self._camera = 0
        self._bad_camera: int | None = None
        self._quality = DEFAULT_QUALITY
        self._frame_number = 0
        self._client: tuple[str, int] | None = None
        self._counters = _Counters()

        self._start_s = time.monotonic()
        self._time_s = self._start_s
        self._next_physics_s = self._next_telemetry_s = self._next_video_s = math.inf

        self._received: deque[ReceivedRcp] = deque(maxlen=RECEIVED_LOG_LENGTH)
        self._received_lock = threading.Lock()
        self._condition = threading.Condition()
        self._snapshot = self._build_snapshot()
        self._life_lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._stop_requested = False
        self._closed = False

        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
            self._sock.bind((host, port))
            self._sock.setblocking(False)
            self._wake_reader, self._wake_writer = socket.socketpair()
        except OSError:
            self._sock.close()
            raise
        self._wake_reader.setblocking(False)
        self._wake_writer.setblocking(False)
        bound_host, bound_port = self._sock.getsockname()[:2]
        self.address: tuple[str, int] = (str(bound_host), int(bound_port))

    def _initial_angles(self, initial: Mapping[str, float]) -> dict[str, float]:
        angles: dict[str, float] = {}
        for motor in self.profile.motors.values():
            if not motor.has_position:
                continue
            low, high = _limits_rad(motor)
            angles[motor.name] = min(max(0.0, low), high)
        for name, angle_rad in initial.items():
            if name not in angles:
                raise ValueError(f"initial_joints: {name!r} is not a motor with a position")
            low, high = _limits_rad(self.profile.motors[name])
            if not (math.isfinite(angle_rad) and low <= angle_rad <= high):
                raise ValueError(
                    f"initial_joints: {name}={angle_rad!r} rad outside [{low:.4f}, {high:.4f}]"
                )
            angles[name] = float(angle_rad)
        return angles

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
        with self._fault_lock:
            return self._faults

    def start(self) -> None:
        """Start the loop thread; a simulator runs once."""
        with self._life_lock:
            if self._closed:
                raise RuntimeError("simulator already stopped")
            if self._thread is not None:
                raise RuntimeError("simulator already started")
            now_s = time.monotonic()
            self._start_s = self._time_s = now_s
            self._next_physics_s = now_s + self._physics_period_s
            self._next_telemetry_s = now_s + self._telemetry_period_s
            if self._video_period_s is not None:
                self._next_video_s = now_s + self._video_period_s
            self._publish()
            self._thread = threading.Thread(target=self._run, name="ocu-sim", daemon=True)
            self._thread.start()
        log.info("ocu-sim listening on %s:%d", *self.address)

    def stop(self) -> None:
        """Stop the loop and close the sockets; safe to call more than once."""
        with self._life_lock:
            if self._closed:
                return
            self._closed = True
            thread = self._thread
        self._stop_requested = True
        # A full wake-up buffer already wakes the loop, so a failed send is harmless.
        with contextlib.suppress(OSError):
            self._wake_writer.send(b"\0")
        if thread is not None:
            thread.join(STOP_JOIN_TIMEOUT_S)
            if thread.is_alive():
                log.warning("simulator thread did not stop within %.1f s", STOP_JOIN_TIMEOUT_S)
        self._sock.close()
        self._wake_reader.close()
        self._wake_writer.close()
        with self._condition:
            self._condition.notify_all()
        log.info("simulator stopped")

    def __enter__(self) -> RobotSimulator:
        if self._thread is None:
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
        with self._fault_lock:
            self._faults = replace(self._faults, **changes)
            faults = self._faults
        log.info("faults set: %s", faults)

    def set_raw_position(self, joint: str, raw: int | None) -> None:
        """Report this raw position for a joint (a broken encoder); None: the true one again."""
        motor = self.profile.motors.get(joint)
        if motor is None or not motor.has_position:
            raise ValueError(f"{joint!r} is not a motor with a position")
        if raw is not None and not 0 <= raw <= 0xFFFFFFFF:
            raise ValueError(f"raw position must be a u32, got {raw!r}")
        with self._fault_lock:
            if raw is None:
                self._raw_faults.pop(joint, None)
            else:
                self._raw_faults[joint] = raw
        log.info("%s reports raw position %s", joint, "truly" if raw is None else f"0x{raw:08x}")

    def set_noise_deg(self, noise_deg: float) -> None:
        """Reported positions get uniform noise of ±noise_deg (the true angle is unchanged)."""
        if not (math.isfinite(noise_deg) and noise_deg >= 0.0):
            raise ValueError(f"noise_deg must be >= 0, got {noise_deg!r}")
        with self._fault_lock:
            self._noise_rad = math.radians(noise_deg)

    def cut_link(self) -> None:
        """Drop every datagram in both directions until restore_link()."""
        with self._fault_lock:
            self._link_cut = True
        log.info("link cut")

    def restore_link(self) -> None:
        """End a cut_link()."""
        with self._fault_lock:
            self._link_cut = False
        log.info("link restored")

    @property
    def extension(self) -> ExtendedServer | None:
        """The extension side (stop_camera, set_battery, set_corrupt), None in vendor mode."""
        return self._ext

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

    def _run(self) -> None:
        selector = selectors.DefaultSelector()
        selector.register(self._sock, selectors.EVENT_READ)
        selector.register(self._wake_reader, selectors.EVENT_READ)
        try:
            while not self._stop_requested:
                try:
                    self._run_timers(time.monotonic())
                    timeout_s = max(0.0, self._next_deadline_s() - time.monotonic())
                    for key, _ in selector.select(timeout_s):
                        if key.fileobj is self._wake_reader:
                            self._drain_wake()
                        else:
                            self._read_datagrams()
                except Exception:
                    if self._stop_requested:
                        break
                    # Never let one bad step kill the robot; timers were already rescheduled.
                    self._counters.internal_errors += 1
                    log.exception("simulator loop error")
        finally:
            selector.close()

    def _next_deadline_s(self) -> float:
        deadline_s = min(self._next_physics_s, self._next_telemetry_s, self._next_video_s)
        if self._ext is not None:
            deadline_s = min(deadline_s, self._ext.next_due_s())
        delayed_s = self._delay_line.next_due_s()
        return deadline_s if delayed_s is None else min(deadline_s, delayed_s)

    def _drain_wake(self) -> None:
        try:
            while self._wake_reader.recv(64):
                pass
        except BlockingIOError:
            pass

    def _run_timers(self, now_s: float) -> None:
        for delayed in self._delay_line.pop_due(now_s):
            self._deliver(delayed.direction, delayed.data, delayed.address, now_s)
        if now_s >= self._next_physics_s:
            self._next_physics_s = _next_due(self._next_physics_s, self._physics_period_s, now_s)
            self._advance(now_s)
            self._publish()
        if now_s >= self._next_telemetry_s:
            self._next_telemetry_s = _next_due(
                self._next_telemetry_s, self._telemetry_period_s, now_s
            )
            self._send_telemetry(now_s)
        if self._video_period_s is not None and now_s >= self._next_video_s:
            self._next_video_s = _next_due(self._next_video_s, self._video_period_s, now_s)
            self._send_video(now_s)
        if self._ext is not None:
            self._ext.poll(
                now_s,
                lambda data, address: self._route(Direction.TO_OCU, data, address, now_s),
                torch=self._torch,
                pose=self._pose,
                moving=not all(speed == 0.0 for speed in self._velocities.values()),
                rcp_quality=self._quality,
            )

    def _read_datagrams(self) -> None:
        for _ in range(MAX_DATAGRAMS_PER_WAKE):
            try:
                data, address = self._sock.recvfrom(MAX_DATAGRAM_BYTES)
            except BlockingIOError:
                return
            except OSError as err:
                # An ICMP error from an earlier send can surface here; it is not fatal.
                log.debug("receive error: %s", err)
                continue
            self._counters.datagrams_received += 1
            sender = (str(address[0]), int(address[1]))
            self._route(Direction.TO_ROBOT, data, sender, time.monotonic())

    def _route(
        self, direction: Direction, data: bytes, address: tuple[str, int], now_s: float
    ) -> None:
        with self._fault_lock:
            cut = self._link_cut
            faults = self._faults
        delays_s = [] if cut else self._injectors[direction].plan(faults)
        if not delays_s:
            self._count_drop(direction)
            return
        if len(delays_s) > 1:
            self._counters.duplicated += 1
        for delay_s in delays_s:
            if delay_s > 0.0:
                self._delay_line.push(now_s + delay_s, direction, data, address)
            else:
                self._deliver(direction, data, address, now_s)

    def _count_drop(self, direction: Direction) -> None:
        if direction is Direction.TO_ROBOT:
            self._counters.dropped_to_robot += 1
        else:
            self._counters.dropped_to_ocu += 1

    def _deliver(
        self, direction: Direction, data: bytes, address: tuple[str, int], now_s: float
    ) -> None:
        # A cut also catches datagrams that were already in flight (delayed) when it began.
        with self._fault_lock:
            cut = self._link_cut
        if cut:
            self._count_drop(direction)
            return
        if direction is Direction.TO_ROBOT:
            self._handle_datagram(data, address, now_s)
            return
        try:
            self._sock.sendto(data, address)
        except OSError as err:
            self._counters.send_errors += 1
            log.debug("send to %s:%d failed: %s", address[0], address[1], err)
        else:
            self._counters.datagrams_sent += 1

    def _handle_datagram(self, data: bytes, address: tuple[str, int], now_s: float) -> None:
        if data and self._ext_codec is not None and self._ext_codec.handles(data[0]):
            self._handle_extended(data, address, now_s)
            return
        try:
            packet = self._codec.decode(data)
        except ProtocolError as err:
            self._counters.malformed += 1
            log.debug("dropped malformed datagram from %s:%d: %s", address[0], address[1], err)
            return
        if not isinstance(packet, RemoteControlPacket):
            self._counters.foreign += 1
            log.debug("dropped %s from %s:%d", type(packet).__name__, address[0], address[1])
            return
        self._apply_rcp(packet, address, now_s)

    def _handle_extended(self, data: bytes, address: tuple[str, int], now_s: float) -> None:
        if self._ext is None:
            # A vendor robot does not speak the extension: dropped like any foreign packet.
            self._counters.foreign += 1
            return
        try:
            packet = self._ext_codec.decode(data) if self._ext_codec is not None else None
        except ProtocolError as err:
            self._counters.malformed += 1
            log.debug("dropped malformed extension datagram: %s", err)
            return
        if not isinstance(packet, HelloPacket):
            self._counters.foreign += 1
            return
        if not self._ext.active(now_s):
            log.info("extension hello from %s:%d", *address)
        self._ext.on_hello(packet, address, now_s)

    def _apply_rcp(
        self, packet: RemoteControlPacket, address: tuple[str, int], now_s: float
    ) -> None:
        # Integrate the old command up to now so the new one takes effect exactly from now.
        self._advance(now_s)
        command = self._mapper.to_command(packet)
        with self._received_lock:
            self._received.append(ReceivedRcp(now_s, packet, address))
        self._counters.rcp += 1
        if address != self._client:
            log.info("new client %s:%d", *address)
            self._client = address
        if self._watchdog_stopped:
            log.info("RCP received again: watchdog stop cleared")
            self._watchdog_stopped = False
        self._command = command
        self._last_rcp_s = now_s
        if command.torch != self._torch:
            self._torch = command.torch
            log.info("torch %s", "on" if command.torch else "off")
        self._select_camera(command.camera)
        self._quality = quality_for_bitrate(command.video_bitrate)
        self._update_velocities()
        self._publish()

    def _select_camera(self, camera: int | None) -> None:
        if camera is None or camera == self._camera:
            return
        names = self.profile.link.camera_names
        if camera >= len(names):
            if camera != self._bad_camera:
                log.warning("ignored selection of camera %d: only %d cameras", camera, len(names))
                self._bad_camera = camera
            return
        self._camera = camera
        log.info("camera %d (%s) selected", camera, names[camera])

    # ---- physics ----------------------------------------------------------------------------

    def _advance(self, now_s: float) -> None:
        if now_s <= self._time_s:
            return
        watchdog_s = self.profile.link.robot_watchdog_s
        expiry_s = self._last_rcp_s + watchdog_s
        if self._command is not None and not self._watchdog_stopped and expiry_s < now_s:
            # Move only until the watchdog fired, even when this step came late.
            stop_s = max(self._time_s, expiry_s)
            self._integrate(stop_s - self._time_s)
            self._time_s = stop_s
            self._watchdog_stopped = True
            log.info("watchdog: no RCP for %.2f s, all motors stopped", watchdog_s)
            self._update_velocities()
        self._integrate(now_s - self._time_s)
        self._time_s = now_s
        self._update_velocities()

    def _update_velocities(self) -> None:
        active = self._command is not None and not self._watchdog_stopped
        commanded = {
            name: self._command.velocity(name) if active and self._command is not None else 0.0
            for name in self.profile.channels
        }
        # Servo deadband: below min_speed a servo does not start moving. The tracks move as a
        # pair: a turn fast enough to start them carries a slow linear speed along (and the
        # other way round), as the OCU's drive scaling assumes (seed 002, eq. 5.4).
        channels = self.profile.channels
        effective = {
            name: speed if abs(speed) >= channels[name].min_speed else 0.0
            for name, speed in commanded.items()
        }
        drive = list(self.profile.drive_channels or ())
        if any(effective[name] != 0.0 for name in drive):
            for name in drive:
                effective[name] = commanded[name]
        # The vendor server refuses to turn the waist while the chassis moves (the profile's
        # locked_while_driving channels).
        driving = any(effective[name] != 0.0 for name in drive)
        locked = [name for name, ch in channels.items() if ch.locked_while_driving]
        self._waist_suppressed = driving and any(effective[name] != 0.0 for name in locked)
        if driving:
            for name in locked:
                effective[name] = 0.0
        for channel, motor in self._channel_motors.items():
            low_rad, high_rad = _limits_rad(motor)
            angle_rad = self._angles_rad[motor.name]
            speed = effective[channel]
            if (angle_rad <= low_rad and speed < 0.0) or (angle_rad >= high_rad and speed > 0.0):
                effective[channel] = 0.0
        self._commanded = commanded
        self._velocities = effective
        self._track_speeds_m_s = self._tracks(effective)
        self._commanded_tracks_m_s = self._tracks(commanded)

    def _tracks(self, velocities: Mapping[str, float]) -> tuple[float, float]:
        return track_speeds(self.profile, velocities)

    def _integrate(self, dt_s: float) -> None:
        if dt_s <= 0.0:
            return
        for channel, motor in self._channel_motors.items():
            speed_rad_s = self._velocities[channel]
            if speed_rad_s == 0.0:
                continue
            low_rad, high_rad = _limits_rad(motor)
            angle_rad = self._angles_rad[motor.name] + speed_rad_s * dt_s
            self._angles_rad[motor.name] = min(max(angle_rad, low_rad), high_rad)
        left_m_s, right_m_s = self._track_speeds_m_s
        if left_m_s == 0.0 and right_m_s == 0.0:
            return
        speed_m_s = (left_m_s + right_m_s) / 2.0
        turn_rad_s = (right_m_s - left_m_s) / self.profile.track_width_m
        x_m, y_m, heading_rad = self._pose
        # Mid-step heading: exact for straight lines and turns in place, close for arcs.
        mid_heading_rad = heading_rad + turn_rad_s * dt_s / 2.0
        self._pose = (
            x_m + speed_m_s * math.cos(mid_heading_rad) * dt_s,
            y_m + speed_m_s * math.sin(mid_heading_rad) * dt_s,
            math.remainder(heading_rad + turn_rad_s * dt_s, math.tau),
        )

    # ---- telemetry and video ----------------------------------------------------------------

    def _send_telemetry(self, now_s: float) -> None:
        if self._client is None:
            return
        self._advance(now_s)
        tick = int((now_s - self._start_s) * self.profile.link.telemetry_tick_hz)
        records = tuple(self._motor_record(motor) for motor in self.profile.motors.values())
        data = self._codec.encode(TelemetryPacket(tick=tick, motors=records))
        self._counters.telemetry_sent += 1
        self._route(Direction.TO_OCU, data, self._client, now_s)
        self._publish()

    def _motor_record(self, motor: Motor) -> MotorRecord:
        status = STATUS_WATCHDOG_STOP if self._watchdog_stopped else 0
        position = 0
        if motor.track is not None:
            index = 0 if motor.track == "left" else 1
            speed = self._track_speeds_m_s[index]
            speed_command = self._commanded_tracks_m_s[index]
            idle_a, amps_per_speed = TRACK_IDLE_CURRENT_A, TRACK_CURRENT_A_PER_M_S
        else:
            speed = self._velocities[motor.channel] if motor.channel else 0.0
            speed_command = self._commanded[motor.channel] if motor.channel else 0.0
            idle_a, amps_per_speed = JOINT_IDLE_CURRENT_A, JOINT_CURRENT_A_PER_RAD_S
            if motor.has_position:
                angle_rad = self._angles_rad[motor.name]
                with self._fault_lock:
                    noise_rad, raw_fault = self._noise_rad, self._raw_faults.get(motor.name)
                reported_rad = angle_rad
                if noise_rad > 0.0:
                    reported_rad += self._noise_rng.uniform(-noise_rad, noise_rad)
                position = rad_to_ticks(motor, reported_rad) if raw_fault is None else raw_fault
                low_rad, high_rad = _limits_rad(motor)
                if angle_rad <= low_rad:
                    status |= STATUS_AT_LOWER_LIMIT
                if angle_rad >= high_rad:
                    status |= STATUS_AT_UPPER_LIMIT
            locked = motor.channel is not None and (
                self.profile.channels[motor.channel].locked_while_driving
            )
            if locked and self._waist_suppressed:
                status |= STATUS_SUPPRESSED
        speed_scale = self.profile.telemetry_speed_per_rad_s
        current_scale = self.profile.telemetry_current_per_amp
        return MotorRecord(
            device_id=motor.device_id,
            state=DEVICE_STATE_OPERATIONAL,
            mode=OPERATION_MODE_VELOCITY,
            position=position,
            speed=_raw_i16(speed * speed_scale),
            current=_raw_i16((idle_a + amps_per_speed * abs(speed)) * current_scale),
            status=status,
            position_command=position,
            speed_command=_raw_i16(speed_command * speed_scale),
            current_command=_raw_i16(
                (idle_a + amps_per_speed * abs(speed_command)) * current_scale
            ),
        )

    def _send_video(self, now_s: float) -> None:
        if self._client is None:
            return
        if self._ext is not None and self._ext.active(now_s):
            return  # the client gets every camera through the extension instead
        jpeg = self._renderer.render(
            self._camera, self._frame_number, self._quality, torch=self._torch, time_s=now_s
        )
        data = self._codec.encode(VideoFramePacket(jpeg=jpeg))
        self._frame_number += 1
        self._counters.video_sent += 1
        self._route(Direction.TO_OCU, data, self._client, now_s)

    # ---- snapshots --------------------------------------------------------------------------

    def _build_snapshot(self) -> SimState:
        counters = self._counters
        return SimState(
            time_s=self._time_s,
            elapsed_s=self._time_s - self._start_s,
            joints_rad=dict(self._angles_rad),
            velocities=dict(self._velocities),
            commanded_velocities=dict(self._commanded),
            track_speeds_m_s=self._track_speeds_m_s,
            pose=self._pose,
            torch=self._torch,
            camera=self._camera,
            video_quality=self._quality,
            client=self._client,
            watchdog_stopped=self._watchdog_stopped,
            waist_suppressed=self._waist_suppressed,
            all_stopped=all(speed == 0.0 for speed in self._velocities.values()),
            link_cut=self._link_cut,
            rcp_count=counters.rcp,
            telemetry_sent=counters.telemetry_sent,
            video_sent=counters.video_sent,
            malformed_count=counters.malformed,
            foreign_count=counters.foreign,
            datagrams_received=counters.datagrams_received,
            datagrams_sent=counters.datagrams_sent,
            dropped_to_robot=counters.dropped_to_robot,
            dropped_to_ocu=counters.dropped_to_ocu,
            dropped_by_faults=counters.dropped_to_robot + counters.dropped_to_ocu,
            duplicated=counters.duplicated,
            send_errors=counters.send_errors,
            internal_errors=counters.internal_errors,
            extended=None if self._ext is None else self._ext.counters(self._time_s),
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
