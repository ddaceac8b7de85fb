"""The link to an xArm 1S's board over a serial line: joint velocities out as short moves.

`XarmLink(arm, "/dev/ttyUSB0")` behaves from above as the other links do: a `Command`'s
channel velocities (one channel per joint, rad/s) go out, `TelemetryFrame`s (the servos'
positions), `StatusFrame`s (the battery), `LinkStateChanged`, `SafetyEvent`s, `CommandSent`
and `LinkStats` come back. One loop thread ("ocu-xarm-link") writes and reads the port
(pyserial; a pseudo-terminal in tests), reopening it with backoff when it fails.

Velocity from a position servo (docs/xarm.md "The link"): the servos only take "go to P
within T". The link keeps its own copy of each servo's setpoint as the board moves it (from
where it was to the move's target over the move's time), and while a joint has a velocity
it sends, every `jog_period_s`, a move from that setpoint to where the velocity takes it in
`jog_move_s`, within `jog_move_s`: the setpoint moves at the velocity, and if the stream
stops (a crash, a freeze, the cable) the servos stop within `jog_move_s` by themselves. A
velocity that goes to zero sends a move to the setpoint where it is now, within 0 ms: the
joint stops at once. Positions are read every `read_period_s`, every `read_period_moving_s`
while moves stream (a read holds the servo bus: commands come first), one read at a time.
The frames a command becomes are ocu.link.xarm_moves' (jogs, the stop move, and a goal's
one move: `Command.goals`); the replies are decoded by ocu.link.xarm_decode, which hands
every frame read to the listeners as this link hands every frame it writes (a recording).

Safety rules (as the UR link's):
- velocities are clamped to each joint's top speed, targets to its limits;
- no heartbeat from the commanding thread for the GUI-alive timeout: the stop move;
- `emergency_stop` sends the stop move at once, repeated, and latches until a motion command;
  `shutdown` sends it last;
- LINK LOST (no reply to a read for `link_lost_after_s`, or the port failing): the stop move
  (it may still get through), and the command in force then is held: after the link is back
  the link sends nothing until a command different from the held one is set.
- a position reading outside the servo's range (-100 to 1100 units) is not believed: the
  reading carries a fault, and the setpoint is not taken from it.
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import threading
import time
from collections.abc import Callable, Sequence

from ocu.link.base import Link
from ocu.link.stats import RateMeter
from ocu.link.xarm_decode import BatteryReply, XarmDecoder, plausible
from ocu.link.xarm_moves import XarmMoves
from ocu.link.xarm_wire import PortOpener, SerialPort, XarmStatus, XarmTelemetry
from ocu.profile import RobotProfile
from ocu.profile.xarm import XarmProfile
from ocu.profile.xarm_robot import xarm_robot_profile
from ocu.protocol.xarm import read_battery, read_positions
from ocu.records import (
    XARM_TO_BOARD,
    CameraRequest,
    Command,
    CommandSent,
    DatagramSent,
    LinkState,
    LinkStateChanged,
    LinkStats,
    Listener,
    SafetyEvent,
    StatusFrame,
    StreamRequest,
    TelemetryFrame,
    VideoStats,
)

log = logging.getLogger("ocu.link.xarm")

STATS_PERIOD_S = 0.5
#: A read not answered within this long is given up (and another may go).
READ_TIMEOUT_S = 0.3
#: Reopening the port: the first attempt at once, then waits doubling to the last.
BACKOFF_S = (0.0, 0.1, 0.2, 0.4, 0.8, 1.6, 2.0)
#: A loop step later than this after the previous one: the process was frozen.
FREEZE_LIMIT_S = 0.3
MAX_WAIT_S = 0.02


class XarmLink(Link):
    """An xArm's board on serial device `port` as a Link."""

    def __init__(
        self,
        arm: XarmProfile,
        port: str,
        *,
        profile: RobotProfile | None = None,
        baud: int | None = None,
        listener: Listener | None = None,
        gui_alive_timeout_s: float | None = -1.0,
        clock: Callable[[], float] = time.monotonic,
        open_port: PortOpener = SerialPort,
    ) -> None:
        profile = profile or xarm_robot_profile(arm, port)
        super().__init__(profile, f"xArm {arm.name} on {port}")
        if listener is not None:
            self.subscribe(listener)
        self.arm = arm
        self.port = port
        self.baud = arm.baud if baud is None else baud
        self.clock = clock
        self._open_port = open_port
        self.timing = arm.timing
        self._jog_period_s = arm.timing.jog_period_s
        # None disables the GUI-alive watchdog (a caller with its own timeout, e.g. ROS).
        self.gui_alive_timeout_s = (
            profile.link.gui_alive_timeout_s
            if gui_alive_timeout_s is not None and gui_alive_timeout_s < 0
            else gui_alive_timeout_s
        )
        self._lock = threading.RLock()
        self._send_lock = threading.Lock()
        self._command = Command()
        self._held: Command | None = None
        self._estop_latched = False
        self._estop_due: list[float] = []
        self._owner_thread: int | None = None
        self._gui_alive_at = clock()
        self._gui_tripped = False
        self._state = LinkState.CONNECTING
        self._serial: SerialPort | None = None
        # Replies in (every frame read handed to the listeners: a recording), moves out.
        self._decoder = XarmDecoder(arm, tap=self.emit, clock=clock)
        self._moves = XarmMoves(arm)
        self._read_sent_at: float | None = None
        self._last_reply_at: float | None = None
        self._opened_at: float | None = None
        self._attempt = 0
        now = clock()
        self._next_open = self._next_jog = self._next_read = self._next_battery = now
        self._next_stats = now + STATS_PERIOD_S
        self._last_step: float | None = None
        self._replies = 0
        self._sent = 0
        self._send_errors = 0
        self._read_timeouts = 0
        self.reopened = 0
        self._send_rate = RateMeter()
        self._telemetry_rate = RateMeter()
        self._closed = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)

    # ---- commands (any thread) -------------------------------------------------------------

    @property
    def command(self) -> Command:
        """The command the link sends now (after its safety rules)."""
        with self._lock:
            return self._command

    @property
    def state(self) -> LinkState:
        """Whether the board answers."""
        with self._lock:
            return self._state

    def set_command(self, command: Command) -> None:
        """Send this command from now on, at once when it changed (after the safety rules)."""
        message = None
        with self._lock:
            if self._owner_thread in (None, threading.get_ident()):
                self._gui_alive_at = self.clock()
                self._gui_tripped = False
            elif self._owner_silent():
                if command.is_motion and not self._gui_tripped:
                    self._gui_tripped = True
                    message = "control thread silent: motion commands zeroed"
                command = command.stopped()
            if self._state is not LinkState.CONNECTED:
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
            changed = command != self._command
            self._command = command
        if changed:
            self._send_moves()
        if message:
            self._notify_safety(message)

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
        """The stop move now, repeated within the e-stop window, latched until motion."""
        settings = self.profile.link
        with self._lock:
            self._command = self._command.stopped()
            self._estop_latched = True
            now = self.clock()
            repeats = settings.estop_repeats - 1
            step = settings.estop_window_s / repeats if repeats > 0 else 0.0
            self._estop_due = [now + step * (k + 1) for k in range(repeats)]
        self._send_stop()
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
        """An xArm has no cameras: nothing is asked."""
        return StreamRequest()

    def set_stream_request(self, cameras: Sequence[CameraRequest]) -> None:
        """An xArm has no cameras: ignored."""

    @property
    def rate_hz(self) -> float:
        """How often jog moves are sent."""
        with self._lock:
            return 1.0 / self._jog_period_s

    def set_rate_hz(self, rate_hz: float) -> None:
        """Send jog moves this often: within the profile's bounds, and more often than a
        move lasts (else the stream would stop between moves)."""
        low, high = self.profile.link.send_rate_min_hz, self.profile.link.send_rate_max_hz
        if not low <= rate_hz <= high or 1.0 / rate_hz >= self.timing.jog_move_s:
            raise ValueError(
                f"jog rate must be within {low:g}-{high:g} Hz and above "
                f"{1.0 / self.timing.jog_move_s:g} Hz (a move lasts "
                f"{self.timing.jog_move_s:g} s), got {rate_hz!r}"
            )
        with self._lock:
            self._jog_period_s = 1.0 / rate_hz
            self._next_jog = min(self._next_jog, self.clock() + self._jog_period_s)
        self._wake()

    @property
    def extension_active(self) -> bool:
        """An xArm speaks no protocol extension."""
        return False

    def video_stats(self) -> VideoStats:
        """An xArm sends no video."""
        return VideoStats()

    # ---- moves (ocu.link.xarm_moves) --------------------------------------------------------

    def _send_moves(self) -> None:
        with self._send_lock:
            with self._lock:
                if self._serial is None or self._state is not LinkState.CONNECTED:
                    return
                if not self._command.is_motion and self._estop_latched:
                    return
                frames, sent = self._moves.frames(self._command, self.clock())
            if frames and self._write(*frames):
                self.emit(CommandSent(sent, self.clock()))

    def _send_stop(self) -> None:
        with self._send_lock:
            with self._lock:
                frame = self._moves.stop_frame(self.clock()) if self._serial is not None else None
            if frame is not None:
                self._write(frame)

    def _write(self, *frames: bytes) -> bool:
        """Write frames in one go; each is handed to the listeners (a recording)."""
        with self._lock:
            port = self._serial
        if port is None:
            return False
        try:
            port.write(b"".join(frames))
        except OSError as err:
            with self._lock:
                self._send_errors += 1
            log.debug("write failed: %s", err)
            return False
        now = self.clock()
        with self._lock:
            self._sent += 1
            self._send_rate.add(now)
        for frame in frames:
            self.emit(DatagramSent(frame, now, XARM_TO_BOARD))
        return True

    # ---- the loop --------------------------------------------------------------------------

    def start(self) -> None:
        """Run the loop in its named daemon thread ("ocu-xarm-link")."""
        if self._thread is not None:
            return
        with self._lock:
            now = self.clock()
            self._next_open = self._next_jog = self._next_read = self._last_step = now
        self._thread = threading.Thread(target=self._run, name="ocu-xarm-link", daemon=True)
        self._thread.start()

    def _wake(self) -> None:
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"\x00")

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                deadline = self._step(self.clock())
                timeout = min(max(deadline - self.clock(), 0.0), MAX_WAIT_S)
                with self._lock:
                    port = self._serial
                fds = [self._wake_r] + ([port.fileno()] if port is not None else [])
                readable, _, _ = select.select(fds, [], [], timeout)
                if self._wake_r in readable:
                    with contextlib.suppress(BlockingIOError):
                        os.read(self._wake_r, 4096)
                if port is not None and port.fileno() in readable and not self._stop.is_set():
                    self._read(port)
            except Exception:
                if self._stop.is_set():
                    break
                # The servos stop within a jog move's time if nothing is sent; say why here.
                log.exception("xArm link loop step failed; zeroing the command")
                with self._lock:
                    had_motion = self._take_motion()
                if had_motion:
                    self._notify_safety("xArm link failed: motion commands zeroed")

    def _step(self, now: float) -> float:
        self._check_watchdogs(now)
        with self._lock:
            open_due = self._serial is None and now >= self._next_open
        if open_due and not self._stop.is_set():
            self._open()
            now = self.clock()
        with self._lock:
            connected = self._serial is not None
            moving = self._command.is_motion or self._moves.moving(now)
            jog_due = connected and now >= self._next_jog
            if jog_due:
                self._next_jog = max(self._next_jog + self._jog_period_s, now)
            estops = [t for t in self._estop_due if t <= now]
            self._estop_due = [t for t in self._estop_due if t > now]
            if self._read_sent_at is not None and now - self._read_sent_at > READ_TIMEOUT_S:
                self._read_sent_at = None
                self._read_timeouts += 1
            read_due = connected and self._read_sent_at is None and now >= self._next_read
            if read_due:
                period = self.timing.read_period_moving_s if moving else self.timing.read_period_s
                self._next_read = now + period
            battery_due = connected and now >= self._next_battery
            if battery_due:
                self._next_battery = now + self.timing.battery_period_s
            stats_due = now >= self._next_stats
            if stats_due:
                self._next_stats = now + STATS_PERIOD_S
        if estops:
            self._send_stop()
        if jog_due and self._command.is_motion:
            self._send_moves()
        if read_due:
            servos = [joint.servo for joint in self.arm.joints]
            if self._write(read_positions(servos)):
                with self._lock:
                    self._read_sent_at = self.clock()
        if battery_due:
            self._write(read_battery())
        if stats_due:
            self.emit(self.stats())
        with self._lock:
            deadlines = [self._next_jog, self._next_read, self._next_stats, *self._estop_due]
            if self._serial is None:
                deadlines.append(self._next_open)
        return min(deadlines)

    def _check_watchdogs(self, now: float) -> None:
        messages: list[str] = []
        with self._lock:
            last_step, self._last_step = self._last_step, now
            gap = None if last_step is None else now - last_step
            frozen = gap is not None and gap > FREEZE_LIMIT_S
            if frozen and self._take_motion():
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
            last = self._last_reply_at if self._last_reply_at is not None else self._opened_at
            silent = (
                not frozen
                and self._serial is not None
                and last is not None
                and now - last > self.timing.link_lost_after_s
            )
        if messages:
            self._send_stop()
            for message in messages:
                self._notify_safety(message)
        if silent and self._state is not LinkState.LOST:
            assert last is not None
            self._lost(f"no reply from the board for {now - last:.2f} s")

    def _open(self) -> None:
        try:
            port = self._open_port(self.port, self.baud)
        except OSError as err:
            with self._lock:
                self._attempt += 1
                wait = BACKOFF_S[min(self._attempt, len(BACKOFF_S) - 1)]
                self._next_open = self.clock() + wait
            log.info("xArm board %s: %s (next attempt in %.1f s)", self.port, err, wait)
            if self._state is not LinkState.LOST and self._attempt > 1:
                self._set_state(LinkState.LOST, f"cannot open {self.port}: {err}")
            return
        with self._lock:
            if self._stop.is_set():
                port.close()
                return
            self._serial = port
            self._opened_at = self.clock()
            self._last_reply_at = None
            self._read_sent_at = None
            self._next_read = self._next_battery = self._opened_at
        log.info("xArm board %s opened at %d baud", self.port, self.baud)

    def _read(self, port: SerialPort) -> None:
        try:
            data = port.read()
        except OSError as err:
            self._drop_port(f"the port failed: {err}")
            return
        for reply in self._decoder.feed(data):
            if isinstance(reply, BatteryReply):
                self._on_battery(reply.millivolts)
            else:
                self._on_positions(reply.positions)

    def _on_reply(self) -> None:
        now = self.clock()
        with self._lock:
            self._replies += 1
            self._last_reply_at = now
            first = self._state is not LinkState.CONNECTED
            if first:
                self._attempt = 0
        if first:
            self._set_state(LinkState.CONNECTED, f"xArm board on {self.port}")

    def _on_battery(self, millivolts: int) -> None:
        self._on_reply()
        self.emit(StatusFrame(XarmStatus(voltage_mv=millivolts), self.clock(), time.time()))

    def _on_positions(self, positions: dict[int, int]) -> None:
        now, wall = self.clock(), time.time()
        with self._lock:
            # The board read its servos when the request came, with every move sent before
            # it: the request-to-reply time is the reading's round trip (TelemetryFrame).
            asked, self._read_sent_at = self._read_sent_at, None
            delay_s = None if asked is None else max(now - asked, 0.0)
            self._telemetry_rate.add(now)
            for joint in self.arm.joints:
                raw = positions.get(joint.servo)
                if raw is not None and plausible(raw):  # never from an impossible reading
                    self._moves.first_reading(joint.servo, raw, now)
            readings, motors = self._decoder.readings(
                positions, now, self._moves.targets(), self._command
            )
            tick = self._replies + 1
        self._on_reply()
        self.emit(
            TelemetryFrame(XarmTelemetry(tick=tick, motors=motors), readings, now, wall, delay_s)
        )

    def _lost(self, reason: str) -> None:
        with self._lock:
            had_motion = self._take_motion()
        self._send_stop()  # it may still reach the board: only the replies may be lost
        self._set_state(LinkState.LOST, reason)
        if had_motion:
            self._notify_safety("link lost: motion commands zeroed")

    def _drop_port(self, reason: str) -> None:
        """The port failed (loop thread): close it, LOST, reopen later."""
        with self._lock:
            port, self._serial = self._serial, None
            had_motion = self._take_motion()
            wait = BACKOFF_S[min(self._attempt, len(BACKOFF_S) - 1)]
            self._attempt += 1
            self._next_open = self.clock() + wait
            self.reopened += 1
        if port is not None:
            port.close()
        self._set_state(LinkState.LOST, reason)
        if had_motion:
            self._notify_safety("link lost: motion commands zeroed")

    # ---- state and stats -------------------------------------------------------------------

    def _set_state(self, state: LinkState, reason: str) -> None:
        with self._lock:
            if self._state == state:
                return
            self._state = state
        log.info("xArm link %s: %s", state.value, reason)
        self.emit(LinkStateChanged(state, reason))

    def _notify_safety(self, message: str) -> None:
        log.warning("%s", message)
        self.emit(SafetyEvent(message))

    def setpoints(self) -> dict[int, float]:
        """The link's copy of each servo's setpoint now (servo units; known servos only)."""
        now = self.clock()
        with self._lock:
            return self._moves.setpoints(now)

    def stats(self) -> LinkStats:
        """Counters and rates now."""
        now = self.clock()
        with self._lock:
            last = self._last_reply_at
            return LinkStats(
                sent=self._sent,
                received=self._replies,
                telemetry=self._replies,
                video=0,
                malformed=self._decoder.bad_frames + self._read_timeouts,
                foreign=0,
                send_errors=self._send_errors,
                rcp_rate_hz=self._send_rate.rate(now),
                telemetry_rate_hz=self._telemetry_rate.rate(now),
                video_rate_hz=0.0,
                loss_estimate=None,
                duplicates=0,
                reordered=0,
                last_valid_age_s=None if last is None else now - last,
                send_rate_hz=self.rate_hz,
                estop_latched=self._estop_latched,
            )

    @property
    def bad_frames(self) -> int:
        """Replies the frame reader could not make sense of (episodes of garbage)."""
        with self._lock:
            return self._decoder.bad_frames

    # ---- shutdown --------------------------------------------------------------------------

    def shutdown(self, timeout_s: float = 2.0) -> None:
        """Stop the loop, send the stop move last and close the port; idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._stop.set()
        self._wake()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout_s)
        with self._lock:
            self._command = self._command.stopped()
            self._estop_due = []
        for _ in range(self.profile.link.estop_repeats):
            self._send_stop()
        with self._lock:
            port, self._serial = self._serial, None
        if port is not None:
            port.close()
        for fd in (self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._set_state(LinkState.CLOSED, "shut down")
