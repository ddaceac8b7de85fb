"""The UR link's connection and decoding: three TCP sockets to a controller, packets to records.

`UrConnection.open()` connects as seed 004 says (docs/ur.md "The UR link"): the primary port
(30001) for the version message, which fixes the realtime layout; then the secondary (30002:
robot mode, safety mode, the stop flags at 10 Hz) and the realtime port (30003: joints and TCP
at 125 or 500 Hz, and where the URScript goes). Reading never raises on bad bytes: a packet
that does not decode is counted in `malformed` and dropped. No threads here; the link's loop
calls `read_realtime` / `read_secondary` when a socket is readable. The bytes-to-states step is
`UrDecoder`, which a replay and `ocu inspect` use too; a connection's `tap` is handed every
packet read and every URScript line written, for a recording (docs/recordings.md).
"""

from __future__ import annotations

import math
import socket
import statistics
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from ocu.protocol.ur import (
    RealtimeState,
    RobotMode,
    RobotState,
    SafetyMode,
    StreamSplitter,
    UrProtocolError,
    VersionMessage,
    decode_primary,
    realtime_size,
)
from ocu.records import (
    OTHER,
    UR_PRIMARY,
    UR_REALTIME,
    UR_SCRIPT,
    UR_SECONDARY,
    DatagramReceived,
    DatagramSent,
    JointReading,
    Listener,
    RobotModeReport,
    TelemetryFrame,
)

RECV_BYTES = 65536
#: Sends that cannot be written within this long mean the connection is dead.
SEND_TIMEOUT_S = 0.2


class UrConnectionError(OSError):
    """The controller cannot be reached, or its version message says nothing usable."""


@dataclass(frozen=True)
class UrMotor:
    """One joint's raw record (RawMotor): joint mode, robot mode, µrad, safety mode."""

    device_id: int
    state: int
    mode: int
    position: int
    status: int


@dataclass(frozen=True)
class UrTelemetry:
    """A realtime packet as RawTelemetry: the controller's cycle count and six joint records."""

    tick: int
    motors: tuple[UrMotor, ...]
    state: RealtimeState


@dataclass(frozen=True)
class UrRobotStatus:
    """The robot and safety modes and the stop flags, as the secondary port reports them."""

    robot_mode: RobotMode
    safety_mode: SafetyMode
    emergency_stopped: bool
    protective_stopped: bool

    @property
    def may_move(self) -> bool:
        """Whether the controller takes motion: running, normal or reduced, no stop."""
        return (
            self.robot_mode is RobotMode.RUNNING
            and self.safety_mode in (SafetyMode.NORMAL, SafetyMode.REDUCED)
            and not self.emergency_stopped
            and not self.protective_stopped
        )

    def report(self) -> RobotModeReport:
        """The neutral record of it (ocu.records), for the console and ROS."""
        stops = tuple(
            name
            for name, on in (
                ("emergency stop", self.emergency_stopped),
                ("protective stop", self.protective_stopped),
            )
            if on
        )
        return RobotModeReport(self.robot_mode.name, self.safety_mode.name, self.may_move, stops)

    def describe(self) -> str:
        """One line for messages: "robot RUNNING, safety PROTECTIVE_STOP, protective stop"."""
        parts = [f"robot {self.robot_mode.name}", f"safety {self.safety_mode.name}"]
        if self.emergency_stopped:
            parts.append("emergency stop")
        if self.protective_stopped:
            parts.append("protective stop")
        return ", ".join(parts)


class SpeedEcho:
    """The round trip, from the controller's own reaction to a changed speedj.

    A UR echoes no command, but its realtime packet carries `qd_target`, the joint speeds its
    motion planner is heading for: when a changed speedj lands, the next cycle's `qd_target`
    leaves the old speeds toward the new ones. So a change sent while the targets were steady
    at the last command (not still ramping) is a probe: the first packet whose targets moved
    toward it arrived one round trip (both ways and a control cycle) after it was sent. The
    median of the last samples is the link's delay (TelemetryFrame.delay_s, LinkStats): the
    position controller's prediction needs it (docs/ur.md). Not thread-safe: the link's lock.
    """

    SAMPLES = 9
    EPS = 1e-6
    GIVE_UP_S = 2.0  # a probe never answered (the controller refused the command)

    def __init__(self) -> None:
        self._commanded: tuple[float, ...] | None = None
        self._targets: tuple[float, ...] | None = None
        self._probe: tuple[float, tuple[float, ...], tuple[float, ...]] | None = None
        self._samples: deque[float] = deque(maxlen=self.SAMPLES)

    def sent(self, qd: Sequence[float], at: float) -> None:
        """Joint speeds went out at `at` (speedj; stopj: zeros)."""
        new = tuple(qd)
        before, self._commanded = self._commanded, new
        if before is None or new == before or self._probe is not None:
            return
        targets = self._targets
        if targets is None or any(
            abs(t - b) > self.EPS for t, b in zip(targets, before, strict=True)
        ):
            return  # still ramping to an earlier command: a reaction could be that ramp
        self._probe = (at, before, new)

    def received(self, qd_target: Sequence[float], at: float) -> None:
        """A realtime packet's target speeds, arrived at `at`."""
        self._targets = tuple(qd_target)
        probe = self._probe
        if probe is None:
            return
        sent_at, before, after = probe
        for target, old, new in zip(qd_target, before, after, strict=True):
            moved = target - old
            if abs(new - old) > self.EPS and abs(moved) > self.EPS and moved * (new - old) > 0:
                self._samples.append(max(at - sent_at, 0.0))
                self._probe = None
                return
        if at - sent_at > self.GIVE_UP_S:
            self._probe = None

    @property
    def delay_s(self) -> float | None:
        """The median of the last round trips (None: none measured yet)."""
        if not self._samples:
            return None
        return float(statistics.median(self._samples))


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None


def telemetry_frame(
    state: RealtimeState,
    joint_names: Sequence[str],
    *,
    ticks_per_s: float,
    ticks_per_rad: float,
    received_at: float,
    wall_time: float,
    delay_s: float | None = None,
) -> TelemetryFrame:
    """A realtime packet as a TelemetryFrame: one JointReading per joint, SI units."""
    robot_mode = int(state.robot_mode)
    safety = int(state.safety_mode)
    motors: list[UrMotor] = []
    readings: dict[str, JointReading] = {}
    for index, name in enumerate(joint_names):
        angle = _finite(state.q_actual[index])
        fault = None if angle is not None else "the controller sent a non-finite angle"
        joint_mode = state.joint_modes[index]
        mode_int = int(joint_mode) if math.isfinite(joint_mode) else -1
        motors.append(
            UrMotor(
                device_id=index + 1,
                state=mode_int,
                mode=robot_mode,
                position=round(angle * ticks_per_rad) if angle is not None else 0,
                status=safety,
            )
        )
        readings[name] = JointReading(
            name=name,
            device_id=index + 1,
            state=mode_int,
            mode=robot_mode,
            angle_rad=angle,
            speed_rad_s=_finite(state.qd_actual[index]) or 0.0,
            current_a=_finite(state.i_actual[index]) or 0.0,
            status=safety,
            target_angle_rad=_finite(state.q_target[index]),
            speed_command_rad_s=_finite(state.qd_target[index]) or 0.0,
            current_command_a=_finite(state.i_target[index]) or 0.0,
            fault=fault,
        )
    tick = round(state.time_s * ticks_per_s) if math.isfinite(state.time_s) else 0
    packet = UrTelemetry(tick=tick, motors=tuple(motors), state=state)
    return TelemetryFrame(packet, readings, received_at, wall_time, delay_s)


def robot_status(packet: RobotState) -> UrRobotStatus | None:
    """The status in a robot-state packet, or None if it lacks the robot mode data."""
    mode = packet.robot_mode
    if mode is None:
        return None
    board = packet.masterboard
    safety = board.safety if board is not None else SafetyMode.NORMAL
    return UrRobotStatus(
        robot_mode=RobotMode(mode.robot_mode),
        safety_mode=safety,
        emergency_stopped=mode.emergency_stopped,
        protective_stopped=mode.protective_stopped,
    )


def read_version(
    host: str,
    port: int,
    timeout_s: float,
    *,
    tap: Listener | None = None,
    clock: Callable[[], float] = time.monotonic,
) -> VersionMessage:
    """Connect to the primary port and read the version message it sends first (`tap`: each
    packet read, as a DatagramReceived, for a recording)."""
    deadline = time.monotonic() + timeout_s
    splitter = StreamSplitter.primary()
    try:
        with socket.create_connection((host, port), timeout=timeout_s) as sock:
            while True:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise UrConnectionError(f"no version message on {host}:{port} in {timeout_s} s")
                sock.settimeout(left)
                data = sock.recv(RECV_BYTES)
                if not data:
                    raise UrConnectionError(f"{host}:{port} closed before its version message")
                packets = splitter.feed(data)
                _tap_skipped(tap, splitter, clock)
                for packet in packets:
                    try:
                        decoded = decode_primary(packet)
                    except UrProtocolError:
                        _tap(tap, packet, clock(), OTHER)
                        continue
                    _tap(tap, packet, clock(), UR_PRIMARY)
                    if isinstance(decoded, VersionMessage):
                        return decoded
    except TimeoutError as err:
        raise UrConnectionError(f"no version message on {host}:{port} in {timeout_s} s") from err


def _tap(
    tap: Listener | None, data: bytes, at: float, kind: str, robot_time_s: float | None = None
) -> None:
    if tap is not None:
        tap(DatagramReceived(data, at, kind, robot_time_s))


def _tap_skipped(
    tap: Listener | None, splitter: StreamSplitter, clock: Callable[[], float]
) -> None:
    skipped = splitter.take_skipped()
    if skipped:
        _tap(tap, skipped, clock(), OTHER)


class UrDecoder:
    """Realtime and secondary packets to states, for the live link, a replay and `ocu inspect`.

    Bytes go through the stream splitters (a recorded packet is one whole packet) and the
    codecs of ocu.protocol.ur; a packet that does not decode is counted in `malformed` and
    dropped. `tap` is handed each packet as a DatagramReceived of its port's kind (OTHER:
    skipped bytes and packets that did not decode), with the controller's own time where the
    packet has one. `realtime_size` None: any of the known layouts (a recording started after
    the version message).
    """

    def __init__(
        self,
        realtime_size: int | None = None,
        *,
        tap: Listener | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.realtime_size = realtime_size
        self.tap = tap
        self.clock = clock
        sizes = None if realtime_size is None else {realtime_size}
        self._realtime_splitter = (
            StreamSplitter.realtime() if sizes is None else StreamSplitter.realtime(sizes)
        )
        self._secondary_splitter = StreamSplitter.primary()
        self.decode_errors = 0

    @property
    def malformed(self) -> int:
        """Byte runs skipped by the splitters plus packets that did not decode."""
        return (
            self._realtime_splitter.malformed
            + self._secondary_splitter.malformed
            + self.decode_errors
        )

    def realtime(self, data: bytes) -> list[RealtimeState]:
        """The realtime states in these bytes (and those held from before)."""
        packets = self._realtime_splitter.feed(data)
        now = self.clock()
        _tap_skipped(self.tap, self._realtime_splitter, self.clock)
        states: list[RealtimeState] = []
        for packet in packets:
            try:
                state = RealtimeState.decode(packet, expected_size=self.realtime_size)
            except UrProtocolError:
                self.decode_errors += 1
                _tap(self.tap, packet, now, OTHER)
                continue
            stamp = state.time_s if math.isfinite(state.time_s) else None
            _tap(self.tap, packet, now, UR_REALTIME, stamp)
            states.append(state)
        return states

    def secondary(self, data: bytes) -> list[UrRobotStatus]:
        """The robot statuses in these secondary-port bytes."""
        packets = self._secondary_splitter.feed(data)
        now = self.clock()
        _tap_skipped(self.tap, self._secondary_splitter, self.clock)
        statuses: list[UrRobotStatus] = []
        for packet in packets:
            try:
                decoded = decode_primary(packet)
                status = robot_status(decoded) if isinstance(decoded, RobotState) else None
            except (UrProtocolError, ValueError):
                self.decode_errors += 1
                _tap(self.tap, packet, now, OTHER)
                continue
            mode = decoded.robot_mode if isinstance(decoded, RobotState) else None
            stamp = None if mode is None else mode.timestamp_us / 1e6
            _tap(self.tap, packet, now, UR_SECONDARY, stamp)
            if status is not None:
                statuses.append(status)
        return statuses


def _connect(host: str, port: int, timeout_s: float) -> socket.socket:
    sock = socket.create_connection((host, port), timeout=timeout_s)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    sock.settimeout(SEND_TIMEOUT_S)
    return sock


class UrConnection:
    """One session with the controller: the version, then the secondary and realtime sockets."""

    def __init__(
        self,
        host: str,
        ports: Sequence[int],
        timeout_s: float,
        *,
        tap: Listener | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if len(ports) != 3:
            raise ValueError("ports: primary, secondary and realtime, three of them")
        self.host = host
        self.ports = tuple(ports)
        self.timeout_s = timeout_s
        # Every packet read and every script sent, as DatagramReceived / DatagramSent.
        self.tap = tap
        self.clock = clock
        self.version: tuple[int, int, int] = (0, 0, 0)
        self.realtime_size = 0
        self.secondary: socket.socket | None = None
        self.realtime: socket.socket | None = None
        self.decoder = UrDecoder(tap=tap, clock=clock)

    @property
    def malformed(self) -> int:
        """Byte runs skipped by the splitters plus packets that did not decode."""
        return self.decoder.malformed

    def open(self) -> None:
        """Connect: version from primary, then secondary and realtime; UrConnectionError/OSError."""
        message = read_version(
            self.host, self.ports[0], self.timeout_s, tap=self.tap, clock=self.clock
        )
        self.version = (message.major, message.minor, message.bugfix)
        try:
            self.realtime_size = realtime_size(message.version)
        except UrProtocolError as err:
            raise UrConnectionError(str(err)) from err
        self.decoder = UrDecoder(self.realtime_size, tap=self.tap, clock=self.clock)
        try:
            self.secondary = _connect(self.host, self.ports[1], self.timeout_s)
            self.realtime = _connect(self.host, self.ports[2], self.timeout_s)
        except OSError:
            self.close()
            raise

    def close(self) -> None:
        """Close both sockets; idempotent."""
        for sock in (self.secondary, self.realtime):
            if sock is not None:
                sock.close()
        self.secondary = self.realtime = None

    def send(self, data: bytes) -> None:
        """Write URScript on the realtime port; OSError if the connection is gone."""
        sock = self.realtime
        if sock is None:
            raise ConnectionError("not connected")
        sock.sendall(data)
        if self.tap is not None:
            self.tap(DatagramSent(data, self.clock(), UR_SCRIPT))

    def read_realtime(self) -> list[RealtimeState] | None:
        """The realtime packets now complete; None when the controller closed the port."""
        data = self._recv(self.realtime)
        if data is None:
            return None
        return self.decoder.realtime(data)

    def read_secondary(self) -> list[UrRobotStatus] | None:
        """The robot statuses in the secondary packets now complete; None when it closed."""
        data = self._recv(self.secondary)
        if data is None:
            return None
        return self.decoder.secondary(data)

    @staticmethod
    def _recv(sock: socket.socket | None) -> bytes | None:
        if sock is None:
            return None
        try:
            data = sock.recv(RECV_BYTES)
        except (BlockingIOError, TimeoutError):
            return b""
        except OSError:
            return None
        return data or None
