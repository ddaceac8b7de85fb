"""The link to a Universal Robots controller: speedj streamed over TCP, realtime state in.

`UrLink(arm, host)` behaves from above as the Engineer's live link (ocu.link.live) does: a
`Command`'s channel velocities (one channel per joint, rad/s) go out, `TelemetryFrame`s,
`LinkStateChanged`, `SafetyEvent`s, `CommandSent` and `LinkStats` come back. One loop thread
("ocu-ur-link") connects (ocu.link.ur_wire), reads, streams `speedj(qd, a, t)` at the send rate
with a short `t` so that the controller itself brakes when the OCU falls silent (crash,
freeze, cable: the robot-side watchdog), runs the watchdogs and reconnects with backoff.

Safety rules (docs/ur.md "The UR link"):
- velocities are clamped to each joint's top speed (the profile's hard maxima);
- no heartbeat from the commanding thread for the GUI-alive timeout: zero velocities;
- `emergency_stop` sends `stopj` at once, repeated, and keeps sending it until a motion
  command; `shutdown` sends `stopj` last;
- LINK LOST (no realtime packet for the link-lost time, or a port closed), a protective or
  emergency stop, or the robot leaving RUNNING: zero velocities, and the command in force then
  is held: after reconnecting (or the stop clearing) the link sends zero velocity until a
  command different from the held one is set while connected. Nothing resumes by itself.
"""

from __future__ import annotations

import contextlib
import logging
import math
import selectors
import socket
import threading
import time
from collections.abc import Callable, Sequence

from ocu.link.base import Link
from ocu.link.stats import RateMeter
from ocu.link.ur_wire import SpeedEcho, UrConnection, UrRobotStatus, telemetry_frame
from ocu.profile import RobotProfile
from ocu.profile.ur import UrArmProfile
from ocu.profile.ur_robot import UR_TICKS_PER_RAD, ur_robot_profile
from ocu.protocol.ur import UrProtocolError, speedj, stopj
from ocu.records import (
    CameraRequest,
    Command,
    CommandSent,
    LinkState,
    LinkStateChanged,
    LinkStats,
    Listener,
    SafetyEvent,
    StreamRequest,
    VideoStats,
)

log = logging.getLogger("ocu.link.ur")

DEFAULT_PORTS = (30001, 30002, 30003)
STATS_PERIOD_S = 0.5
CONNECT_TIMEOUT_S = 1.0
#: Reconnection: the first attempt at once, then waits doubling from the first to the last.
BACKOFF_S = (0.0, 0.1, 0.2, 0.4, 0.8, 1.6, 2.0)
#: A loop step later than this after the previous one: the process was frozen; motion from
#: before the gap is not sent again (the controller has braked on speedj's t meanwhile).
FREEZE_LIMIT_S = 0.3
MAX_WAIT_S = 0.05


class UrLink(Link):
    """A UR controller at `host` (ports 30001-30003 unless given) as a Link."""

    def __init__(
        self,
        arm: UrArmProfile,
        host: str,
        *,
        profile: RobotProfile | None = None,
        ports: Sequence[int] = DEFAULT_PORTS,
        listener: Listener | None = None,
        gui_alive_timeout_s: float | None = -1.0,
        link_lost_after_s: float | None = None,
        send_rate_hz: float | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        profile = profile or ur_robot_profile(arm, host)
        super().__init__(profile, f"UR {arm.name} at {host}")
        if listener is not None:
            self.subscribe(listener)
        self.arm = arm
        self.host = host
        self.ports = tuple(ports)
        self.clock = clock
        settings = profile.link
        self.joint_names = arm.joint_names
        self.acceleration_rad_s2 = arm.max_acceleration_rad_s2
        # speedj's t: the controller brakes this long after the last command (robot side).
        self.speedj_t_s = settings.robot_watchdog_s
        self.link_lost_after_s = (
            settings.link_lost_after_s if link_lost_after_s is None else link_lost_after_s
        )
        # None disables the GUI-alive watchdog (a caller with its own timeout, e.g. ROS).
        self.gui_alive_timeout_s = (
            settings.gui_alive_timeout_s
            if gui_alive_timeout_s is not None and gui_alive_timeout_s < 0
            else gui_alive_timeout_s
        )
        self._rate_hz = settings.send_rate_hz if send_rate_hz is None else send_rate_hz
        self._check_rate(self._rate_hz)
        self._lock = threading.RLock()
        self._send_lock = threading.RLock()
        self._command = Command()
        # The command in force when motion was taken away (lost, stopped): it is not resumed.
        self._held: Command | None = None
        self._estop_latched = False
        self._estop_due: list[float] = []
        self._owner_thread: int | None = None
        self._gui_alive_at = clock()
        self._gui_tripped = False
        self._state = LinkState.CONNECTING
        self._status: UrRobotStatus | None = None
        self._connection: UrConnection | None = None
        self._last_valid_at: float | None = None
        self._connected_at: float | None = None
        self._attempt = 0
        self._failures_since_lost = 0  # connection attempts failed since the last connection
        self._next_connect = clock()
        self._next_send = clock()
        self._next_stats = clock() + STATS_PERIOD_S
        self._last_step: float | None = None
        self._sent = 0
        self._send_errors = 0
        self._received = 0
        self._telemetry = 0
        self._malformed_closed = 0
        # Connections lost (each starts a reconnection) and connection attempts that failed.
        self.connections_lost = 0
        self.failed_connects = 0
        self._send_rate = RateMeter()
        self._telemetry_rate = RateMeter()
        self._emitted_at = -math.inf  # when a TelemetryFrame was last handed on
        self._echo = SpeedEcho()  # the round trip, from the controller's reaction
        self._closed = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._selector = selectors.DefaultSelector()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._selector.register(self._wake_r, selectors.EVENT_READ, None)

    # ---- commands (any thread) -------------------------------------------------------------

    @property
    def command(self) -> Command:
        """The command the link sends now (after its safety rules)."""
        with self._lock:
            return self._command

    @property
    def state(self) -> LinkState:
        """Whether realtime packets are arriving."""
        with self._lock:
            return self._state

    @property
    def robot_status(self) -> UrRobotStatus | None:
        """The robot and safety modes and stop flags last reported (None: none yet)."""
        with self._lock:
            return self._status

    @property
    def controller_version(self) -> tuple[int, int, int] | None:
        """The version the controller reported on connecting (None: not connected yet)."""
        with self._lock:
            connection = self._connection
        return connection.version if connection is not None else None

    def set_command(self, command: Command) -> None:
        """Send this command from now on, at once when it changed (after the safety rules)."""
        with self._lock:
            changed, message = self._replace_command(command)
        if changed:
            self._send_current()
        if message:
            self._notify_safety(message)

    def set_velocities(self, **velocities: float) -> None:
        """Change some joints of the current command (rad/s), atomically."""
        with self._lock:
            changed, message = self._replace_command(self._command.with_velocities(velocities))
        if changed:
            self._send_current()
        if message:
            self._notify_safety(message)

    def _replace_command(self, command: Command) -> tuple[bool, str | None]:
        """Install a command (lock held): whether it changed, and a safety message if zeroed."""
        message = None
        if self._owner_thread in (None, threading.get_ident()):
            self._gui_alive_at = self.clock()
            self._gui_tripped = False
        elif self._owner_silent():
            if command.is_motion and not self._gui_tripped:
                self._gui_tripped = True
                message = "control thread silent: motion commands zeroed"
            command = command.stopped()
        if self._state is not LinkState.CONNECTED or not self._may_move():
            # Not heard, or the controller refuses motion: hold whatever is asked.
            if command.is_motion:
                self._held = command
            command = command.stopped()
        elif self._held is not None:
            if command == self._held:
                command = command.stopped()
            else:
                self._held = None
        if command.is_motion:
            self._estop_latched = False
        if command == self._command:
            return False, message
        self._command = command
        return True, message

    def _may_move(self) -> bool:
        status = self._status
        return status is None or status.may_move

    def _owner_silent(self) -> bool:
        timeout = self.gui_alive_timeout_s
        return timeout is not None and self.clock() - self._gui_alive_at > timeout

    def _take_motion(self) -> bool:
        """Zero the command and hold it (lock held); whether there was motion."""
        had_motion = self._command.is_motion
        if had_motion:
            self._held = self._command
        self._command = self._command.stopped()
        return had_motion

    def emergency_stop(self, reason: str = "operator") -> None:
        """stopj now, repeated within the e-stop window, then until a motion command."""
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

    def heartbeat(self) -> None:
        """The commanding thread is alive (it becomes the command's owner)."""
        with self._lock:
            self._owner_thread = threading.get_ident()
            self._gui_alive_at = self.clock()
            self._gui_tripped = False

    @property
    def stream_request(self) -> StreamRequest:
        """A UR has no cameras: nothing is asked."""
        return StreamRequest()

    def set_stream_request(self, cameras: Sequence[CameraRequest]) -> None:
        """A UR has no cameras: ignored."""

    @property
    def rate_hz(self) -> float:
        """The speedj streaming rate."""
        with self._lock:
            return self._rate_hz

    def set_rate_hz(self, rate_hz: float) -> None:
        """Change the streaming rate (within the profile's bounds)."""
        self._check_rate(rate_hz)
        with self._lock:
            self._rate_hz = rate_hz
            self._next_send = min(self._next_send, self.clock() + 1.0 / rate_hz)
        self._wake()

    def _check_rate(self, rate_hz: float) -> None:
        low, high = self.profile.link.send_rate_min_hz, self.profile.link.send_rate_max_hz
        if not low <= rate_hz <= high:
            raise ValueError(f"send rate must be within {low:g}-{high:g} Hz, got {rate_hz!r}")

    @property
    def extension_active(self) -> bool:
        """A UR speaks no protocol extension."""
        return False

    def video_stats(self) -> VideoStats:
        """A UR sends no video."""
        return VideoStats()

    # ---- sending ---------------------------------------------------------------------------

    def _script(self) -> tuple[bytes, Command | None]:
        """The URScript line for now (lock held) and the command it carries (None: stopj)."""
        # A joint whose end has come (Command.until) is zero from then, command or not.
        command = self._command.expired(self.clock())
        if not command.is_motion and self._estop_latched:
            return stopj(self.acceleration_rad_s2), None
        qd = []
        for name in self.joint_names:
            limit = self.profile.channels[name].hard_max
            qd.append(max(-limit, min(limit, command.velocity(name))))
        sent = command.with_velocities(dict(zip(self.joint_names, qd, strict=True)))
        return speedj(qd, self.acceleration_rad_s2, self.speedj_t_s), sent

    def _send_current(self) -> None:
        # Built and sent under one lock: a tick that read the command just before the
        # operator stopped must not put its stale motion on the wire after the stop.
        frozen = None
        with self._send_lock:
            with self._lock:
                connection = self._connection if self._state is LinkState.CONNECTED else None
                if connection is None or self._closed:
                    return
                # The loop has not run its watchdogs for that long (the process was stopped
                # and a send was due): no motion from before the gap goes out before they have.
                last_step = self._last_step
                gap = None if last_step is None else self.clock() - last_step
                if gap is not None and gap > FREEZE_LIMIT_S and self._take_motion():
                    frozen = f"link loop frozen for {gap:.2f} s: motion commands zeroed"
                data, sent = self._script()
            if self._write(connection, data, sent):
                qd = (
                    [0.0] * len(self.joint_names)
                    if sent is None
                    else [sent.velocity(name) for name in self.joint_names]
                )
                with self._lock:
                    self._echo.sent(qd, self.clock())
        if frozen:
            self._notify_safety(frozen)

    def _write(self, connection: UrConnection, data: bytes, sent: Command | None) -> bool:
        try:
            connection.send(data)
        except (OSError, UrProtocolError) as err:
            with self._lock:
                self._send_errors += 1
            log.debug("send failed: %s", err)
            return False
        now = self.clock()
        with self._lock:
            self._sent += 1
            self._send_rate.add(now)
        if sent is not None:
            self.emit(CommandSent(sent, now))
        return True

    # ---- the loop --------------------------------------------------------------------------

    def start(self) -> None:
        """Run the loop in its named daemon thread ("ocu-ur-link")."""
        if self._thread is not None:
            return
        with self._lock:
            now = self.clock()
            self._next_connect = self._next_send = self._last_step = now
            self._next_stats = now + STATS_PERIOD_S
        self._thread = threading.Thread(target=self._run, name="ocu-ur-link", daemon=True)
        self._thread.start()

    def _wake(self) -> None:
        with contextlib.suppress(OSError):
            self._wake_w.send(b"\x00")

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                deadline = self._step(self.clock())
                timeout = min(max(deadline - self.clock(), 0.0), MAX_WAIT_S)
                for key, _ in self._selector.select(timeout):
                    if key.data is None:
                        self._drain_wake()
                    elif not self._stop.is_set():
                        key.data()
            except Exception:
                if self._stop.is_set():
                    break
                # The robot-side watchdog stops the arm if nothing is sent; say why here.
                log.exception("UR link loop step failed; zeroing the command")
                with self._lock:
                    had_motion = self._take_motion()
                if had_motion:
                    self._notify_safety("UR link failed: motion commands zeroed")

    def _drain_wake(self) -> None:
        try:
            while self._wake_r.recv(4096):
                pass
        except BlockingIOError:
            pass

    def _step(self, now: float) -> float:
        self._check_watchdogs(now)
        with self._lock:
            connect_due = self._connection is None and now >= self._next_connect
        if connect_due and not self._stop.is_set():
            self._connect()
            now = self.clock()
        with self._lock:
            send_due = now >= self._next_send
            if send_due:
                self._next_send = max(self._next_send + 1.0 / self._rate_hz, now)
            stats_due = now >= self._next_stats
            if stats_due:
                self._next_stats = now + STATS_PERIOD_S
            estops = [t for t in self._estop_due if t <= now]
            self._estop_due = [t for t in self._estop_due if t > now]
        if send_due or estops:
            self._send_current()
        if stats_due:
            self.emit(self.stats())
        with self._lock:
            deadlines = [self._next_send, self._next_stats, *self._estop_due]
            if self._connection is None:
                deadlines.append(self._next_connect)
        return min(deadlines)

    def _check_watchdogs(self, now: float) -> None:
        messages: list[str] = []
        with self._lock:
            last_step, self._last_step = self._last_step, now
            gap = None if last_step is None else now - last_step
            if gap is not None and gap > FREEZE_LIMIT_S and self._take_motion():
                messages.append(f"link loop frozen for {gap:.2f} s: motion commands zeroed")
            timeout = self.gui_alive_timeout_s
            stalled = now - self._gui_alive_at
            if (
                timeout is not None
                and self._command.is_motion
                and not self._gui_tripped
                and stalled > timeout
            ):
                self._gui_tripped = True
                self._command = self._command.stopped()
                messages.append(
                    f"control thread silent for {stalled:.2f} s: motion commands zeroed"
                )
            # After a freeze the socket holds what arrived meanwhile: read it before judging.
            frozen = gap is not None and gap > FREEZE_LIMIT_S
            connected = self._connection is not None
            last = self._last_valid_at if self._last_valid_at is not None else self._connected_at
            silent = (
                not frozen
                and connected
                and last is not None
                and now - last > self.link_lost_after_s
            )
        if messages:
            self._send_current()
            for message in messages:
                self._notify_safety(message)
        if silent:
            assert last is not None
            self._lose(f"no realtime packet from the controller for {now - last:.2f} s")

    def _connect(self) -> None:
        connection = UrConnection(
            self.host, self.ports, CONNECT_TIMEOUT_S, tap=self.emit, clock=self.clock
        )
        try:
            connection.open()
        except OSError as err:
            with self._lock:
                self._attempt += 1
                self.failed_connects += 1
                self._failures_since_lost += 1
                wait = BACKOFF_S[min(self._attempt, len(BACKOFF_S) - 1)]
                self._next_connect = self.clock() + wait
            log.info("UR controller %s: %s (next attempt in %.1f s)", self.host, err, wait)
            return
        if self._stop.is_set():  # shut down while connecting: shutdown() did not see it
            connection.close()
            return
        assert connection.secondary is not None
        assert connection.realtime is not None
        with self._lock:
            self._connection = connection
            self._connected_at = self.clock()
            self._last_valid_at = None
        self._selector.register(connection.realtime, selectors.EVENT_READ, self._read_realtime)
        self._selector.register(connection.secondary, selectors.EVENT_READ, self._read_secondary)
        version = ".".join(map(str, connection.version))
        log.info(
            "UR controller %s: version %s, realtime %d bytes",
            self.host,
            version,
            connection.realtime_size,
        )

    def _read_realtime(self) -> None:
        with self._lock:
            connection = self._connection
        if connection is None:
            return
        states = connection.read_realtime()
        if states is None:
            self._lose("the controller closed the realtime port")
            return
        if not states:
            return
        now, wall = self.clock(), time.time()
        with self._lock:
            self._received += len(states)
            self._telemetry += len(states)
            for state in states:
                self._telemetry_rate.add(now)
                self._echo.received(state.qd_target, now)
            delay_s = self._echo.delay_s
            self._last_valid_at = now
            first = self._state is not LinkState.CONNECTED
            if first:
                self._attempt = self._failures_since_lost = 0
        if first:
            version = ".".join(map(str, connection.version))
            self._set_state(LinkState.CONNECTED, f"UR controller {version} at {self.host}")
        # The newest state, at most at the profile's telemetry rate (UR_TELEMETRY_HZ): every
        # packet counts for the link's liveness above, the console reads what it can use.
        with self._lock:
            due = now - self._emitted_at >= 1.0 / self.profile.link.telemetry_rate_hz
            if due:
                self._emitted_at = now
        if due:
            self.emit(
                telemetry_frame(
                    states[-1],
                    self.joint_names,
                    ticks_per_s=self.arm.realtime_hz,
                    ticks_per_rad=UR_TICKS_PER_RAD,
                    received_at=now,
                    wall_time=wall,
                    delay_s=delay_s,
                )
            )

    def _read_secondary(self) -> None:
        with self._lock:
            connection = self._connection
        if connection is None:
            return
        statuses = connection.read_secondary()
        if statuses is None:
            self._lose("the controller closed the secondary port")
            return
        with self._lock:
            self._received += len(statuses)
        for status in statuses:
            self._on_status(status)

    def _on_status(self, status: UrRobotStatus) -> None:
        with self._lock:
            old, self._status = self._status, status
        if old != status:
            self.emit(status.report())
        with self._lock:
            if old == status or (old is None and status.may_move):
                return
            had_motion = self._take_motion() if not status.may_move else False
        if not status.may_move:
            if had_motion:
                self._send_current()
            self._notify_safety(f"UR controller: {status.describe()}: motion stopped")
        else:
            message = f"UR controller: {status.describe()}: ready, nothing resumed"
            log.warning("%s", message)
            self.emit(SafetyEvent(message, stopped=False))

    def _lose(self, reason: str) -> None:
        """The connection is gone (loop thread): close it, zero, LOST, reconnect later."""
        with self._lock:
            connection, self._connection = self._connection, None
            had_motion = self._take_motion()
            if connection is not None:
                self._malformed_closed += connection.malformed
            self._last_valid_at = None
            self._connected_at = None
            self._status = None
            wait = BACKOFF_S[min(self._attempt, len(BACKOFF_S) - 1)]
            self._attempt += 1
            self._next_connect = self.clock() + wait
            self.connections_lost += 1
        if connection is not None:
            for sock in (connection.realtime, connection.secondary):
                if sock is not None:
                    with contextlib.suppress(KeyError, ValueError):
                        self._selector.unregister(sock)
            # What the controller still hears: the stop, before the sockets close.
            with self._send_lock, contextlib.suppress(OSError):
                connection.send(stopj(self.acceleration_rad_s2))
            connection.close()
        self._set_state(LinkState.LOST, reason)
        if had_motion:
            self._notify_safety("link lost: motion commands zeroed")

    # ---- state and stats -------------------------------------------------------------------

    def _set_state(self, state: LinkState, reason: str) -> None:
        with self._lock:
            if self._state == state:
                return
            self._state = state
        log.info("UR link %s: %s", state.value, reason)
        self.emit(LinkStateChanged(state, reason))

    def _notify_safety(self, message: str) -> None:
        log.warning("%s", message)
        self.emit(SafetyEvent(message))

    def stats(self) -> LinkStats:
        """Counters and rates now."""
        now = self.clock()
        with self._lock:
            connection = self._connection
            malformed = self._malformed_closed + (connection.malformed if connection else 0)
            last = self._last_valid_at
            return LinkStats(
                sent=self._sent,
                received=self._received,
                telemetry=self._telemetry,
                video=0,
                malformed=malformed,
                foreign=0,
                send_errors=self._send_errors,
                rcp_rate_hz=self._send_rate.rate(now),
                telemetry_rate_hz=self._telemetry_rate.rate(now),
                video_rate_hz=0.0,
                loss_estimate=None,
                duplicates=0,
                reordered=0,
                last_valid_age_s=None if last is None else now - last,
                send_rate_hz=self._rate_hz,
                estop_latched=self._estop_latched,
                delay_s=self._echo.delay_s,
                reconnect_failures=self._failures_since_lost,
                next_attempt_in_s=(
                    None if connection is not None else max(0.0, self._next_connect - now)
                ),
            )

    # ---- shutdown --------------------------------------------------------------------------

    def shutdown(self, timeout_s: float = 2.0) -> None:
        """Stop the loop, send stopj last and close; idempotent."""
        with self._send_lock:
            if self._closed:
                return
        self._stop.set()
        self._wake()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout_s)
        with self._lock:
            self._command = self._command.stopped()
            self._estop_due = []
            connection, self._connection = self._connection, None
        with self._send_lock:
            self._closed = True
            if connection is not None:
                for _ in range(self.profile.link.estop_repeats):
                    try:
                        connection.send(stopj(self.acceleration_rad_s2))
                    except OSError:
                        break
                connection.close()
        self._selector.close()
        self._wake_r.close()
        self._wake_w.close()
        self._set_state(LinkState.CLOSED, "shut down")
