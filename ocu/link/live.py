"""The live link to a robot: commands out on a transport, the robot's datagrams in, watchdogs.

`UdpLink` talks to a robot (or `ocu-sim`) over UDP; `VirtualLink` to an in-process simulator
over a virtual wire (ocu.net.transport), for tests and benchmarks. Both are a `LiveLink`.

One loop thread ("ocu-link") owns the periodic work: the RCP tick (5 Hz by default), the
extension hello, e-stop repeats, the watchdogs and the receive path (ocu.link.receiver).
Command changes and the first e-stop datagram are sent from the caller's thread at once, so a
busy loop (or Python's GIL switch interval) cannot delay them. The link bounds every command
by the channels' hard maxima only; the operator's current maxima are the console model's.
"""

from __future__ import annotations

import logging
import random
import threading
import time
import weakref
from collections.abc import Callable, Sequence
from typing import TypedDict, Unpack

from ocu.link.base import Link, LinkError
from ocu.link.receiver import Receiver
from ocu.link.stats import RateMeter
from ocu.net.loop import SelectLoop
from ocu.net.transport import (
    Address,
    Transport,
    TransportError,
    UdpTransport,
    VirtualEndpoint,
    is_loopback,
    resolve,
)
from ocu.profile import ExtensionSettings, RobotProfile
from ocu.protocol.extended import MIN_DATAGRAM, SEQUENCE_MODULUS, HelloPacket, SequencedRcp
from ocu.protocol.mapping import CommandMapper
from ocu.protocol.packets import MAX_DATAGRAM, RemoteControlPacket
from ocu.protocol.wire import make_codec, make_extension_codec
from ocu.records import (
    HELLO,
    RCP,
    CameraRequest,
    Command,
    CommandSent,
    DatagramSent,
    LinkState,
    LinkStateChanged,
    LinkStats,
    Listener,
    SafetyEvent,
    StreamRequest,
    VideoStats,
)

log = logging.getLogger("ocu.link")

RECV_BUFFER_BYTES = 65536
MAX_DATAGRAMS_PER_WAKE = 256
STATS_PERIOD_S = 0.5

# Every live link not yet shut down, for the process's last-chance hooks (ocu.link.guard).
_LIVE: weakref.WeakSet[LiveLink] = weakref.WeakSet()
_LIVE_LOCK = threading.Lock()


def live_links() -> list[LiveLink]:
    """The live links not yet shut down."""
    with _LIVE_LOCK:
        return list(_LIVE)


class LiveLink(Link):
    """Sends RCPs to the robot on a transport and turns what comes back into events."""

    def __init__(
        self,
        profile: RobotProfile,
        transport: Transport,
        robot_address: Address,
        description: str,
        *,
        listener: Listener | None = None,
        link_lost_after_s: float | None = None,
        gui_alive_timeout_s: float | None = -1.0,
        send_rate_hz: float | None = None,
        send_on_change: bool = True,
        extension: bool = False,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(profile, description)
        if listener is not None:
            self.subscribe(listener)
        self.clock = clock
        self.transport = transport
        self.robot_address = robot_address
        self.address = transport.address
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
        # The protocol extension: probe with a hello on every tick when asked to and the
        # profile defines it (and does not switch probing off).
        ext = profile.extension
        self.extension_enabled = extension and ext is not None and ext.probe
        self._ext_codec = make_extension_codec(profile) if self.extension_enabled else None
        # The next sequenced RCP's number: from a random start, so that a restarted OCU is not
        # taken for a late copy of its former self (the robot also starts over after a pause).
        self._rcp_sequence = random.randrange(SEQUENCE_MODULUS)
        self.receiver = Receiver(
            profile,
            self.emit,
            extension=self.extension_enabled,
            link_lost_after_s=self.link_lost_after_s,
        )
        self._hello = HelloPacket()
        if ext is not None:
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
                max_datagram_bytes=_path_datagram_bytes(ext, transport, robot_address),
            )

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
        # The loop steps at least every MAX_WAIT_S (ocu.net.loop). A gap longer than the
        # robot's own watchdog means the process was stopped (SIGSTOP, suspend, swapping) or
        # starved long enough for the robot to stop by itself: the command from before the
        # gap is stale and would restart it.
        self.freeze_limit_s = settings.robot_watchdog_s
        self._last_step_at: float | None = None
        self._silenced: str | None = None
        # The thread that calls heartbeat() owns the commands; until one does, whoever sets
        # commands counts as alive by doing so.
        self._owner_thread: int | None = None
        self._closed = False
        self._state = LinkState.CONNECTING
        self._started_at = clock()
        self._sent = 0
        self._send_errors = 0
        self._hellos_sent = 0
        self._rcp_rate = RateMeter()
        self._next_tick = clock()
        self._next_stats = self._next_tick + STATS_PERIOD_S
        self._buffer = bytearray(RECV_BUFFER_BYTES)
        self.loop = SelectLoop("ocu-link", clock=clock, on_error=self._loop_failed)
        self.loop.add_reader(transport.socket, self._receive_all)
        with _LIVE_LOCK:
            _LIVE.add(self)

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
        """Replace the command; sends it at once when it differs from the current one on the
        wire. A channel with an end (`Command.until`) goes to zero then, by this link's loop."""
        with self._lock:
            changed = self._replace_command(command)
            ends = self._command.next_end is not None
            silenced = self._take_silenced()
        if changed and self.send_on_change:
            self._send_current()
        if changed or ends:
            # The zero burst's repeats if this stopped motion; the loop's next wake-up if a
            # channel ends by itself.
            self.loop.wake()
        if silenced:
            self._notify_safety(silenced)

    def set_velocities(self, **velocities: float) -> None:
        """Change some channels of the current command (SI units), atomically."""
        with self._lock:
            changed = self._replace_command(self._command.with_velocities(velocities))
            silenced = self._take_silenced()
        if changed and self.send_on_change:
            self._send_current()
        if changed:
            self.loop.wake()  # the zero burst's repeats, if this stopped motion
        if silenced:
            self._notify_safety(silenced)

    def _take_silenced(self) -> str | None:
        message, self._silenced = self._silenced, None
        return message

    def _replace_command(self, command: Command) -> bool:
        """Install a new command (lock held); whether it differs from the old one."""
        if self._owner_thread in (None, threading.get_ident()):
            self._gui_alive_at = self.clock()
            self._gui_tripped = False
        elif self._owner_silent():
            # Commands from another thread (a ROS bridge hosted by the GUI) must neither
            # hide a stalled owner nor move the robot while it is stalled.
            if command.is_motion and not self._gui_tripped:
                self._gui_tripped = True
                stalled_s = self.clock() - self._gui_alive_at
                self._silenced = (
                    f"control thread silent for {stalled_s:.2f} s: motion commands zeroed"
                )
            command = command.stopped()
        frozen_s = self._loop_frozen_s()
        if frozen_s is not None and command.is_motion:
            # The loop has not run its watchdogs for that long (the process just woke up):
            # no motion goes out before they have.
            self._silenced = f"link loop frozen for {frozen_s:.2f} s: motion commands zeroed"
            command = command.stopped()
        if self._state is LinkState.LOST:
            # A robot the OCU cannot hear may still hear the OCU: it would drive blind.
            command = command.stopped()
        if command.is_motion:
            self._estop_latched = False
        command = command.expired(self.clock())
        if command.same_wire(self._command):
            self._command = command  # when channels end may differ: the loop follows it
            return False
        if self._command.is_motion and not command.is_motion:
            self._schedule_zero_repeats()
        self._command = command
        return True

    def _schedule_zero_repeats(self) -> None:
        """Motion just became zero (lock held): repeat the zeros as the e-stop does.

        One zero can be lost, and with jitter an older motion RCP can arrive after it and
        drive on until the next tick; the repeats (the same count and window as the e-stop's)
        make both unlikely. Each repeat sends the command current at its time.
        """
        settings = self.profile.link
        repeats = settings.estop_repeats - 1
        if repeats <= 0:
            return
        now = self.clock()
        step = settings.estop_window_s / repeats
        due = (now + step * (k + 1) for k in range(repeats))
        self._estop_due = sorted({*self._estop_due, *due})

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
        self.loop.wake()
        self._notify_safety(f"EMERGENCY STOP ({reason})")

    def _loop_frozen_s(self) -> float | None:
        """How long the running loop has gone without a step, if over the limit (lock held)."""
        last = self._last_step_at
        if last is None or self._closed:
            return None
        gap = self.clock() - last
        return gap if gap > self.freeze_limit_s else None

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
            # A rate change takes effect at once rather than after the old period.
            self._next_tick = min(self._next_tick, self.clock() + 1.0 / rate_hz)
        self.loop.wake()

    @property
    def rate_hz(self) -> float:
        """The periodic send rate."""
        with self._lock:
            return self._rate_hz

    @property
    def extension_active(self) -> bool:
        """Whether the robot speaks the protocol extension (valid packets lately)."""
        return self.receiver.extension_active

    @property
    def stream_request(self) -> StreamRequest:
        """What the hello sent to probe for the extension asks: the per-camera streams."""
        with self._lock:
            hello = self._hello
        return StreamRequest(cameras=hello.cameras, max_datagram_bytes=hello.max_datagram_bytes)

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

    def video_stats(self) -> VideoStats:
        """Counters of the extension's fragment reassembly."""
        return self.receiver.video_stats()

    def _check_rate(self, rate_hz: float) -> None:
        low, high = self.profile.link.send_rate_min_hz, self.profile.link.send_rate_max_hz
        if not low <= rate_hz <= high:
            raise ValueError(f"send rate must be within {low:g}-{high:g} Hz, got {rate_hz!r}")

    # ---- loop ------------------------------------------------------------------------------

    def start(self) -> None:
        """Run the loop in its named daemon thread ("ocu-link")."""
        self._begin_loop()
        self.loop.start(self._step)

    def run(self) -> None:
        """Run the loop in the calling thread until shutdown()."""
        self._begin_loop()
        self.loop.run(self._step)

    def _begin_loop(self) -> None:
        with self._lock:
            self._next_tick = self.clock()
            self._next_stats = self._next_tick + STATS_PERIOD_S
            self._last_step_at = self._next_tick

    def _step(self, now: float) -> float:
        # The watchdogs first: after a freeze the periodic tick is due at once, and what it
        # would send is the command from before the freeze (the robot may have stopped on its
        # own watchdog meanwhile and would be restarted by it).
        self._check_watchdogs(now)
        self._end_channels(now)
        with self._lock:
            tick_due = now >= self._next_tick
            if tick_due:
                self._next_tick = max(self._next_tick + 1.0 / self._rate_hz, now)
            stats_due = now >= self._next_stats
            if stats_due:
                self._next_stats = now + STATS_PERIOD_S
        if tick_due:
            self._send_current()
            self._send_hello()
        if stats_due:
            self.emit(self.stats())
        self.receiver.expire(now)
        due = self._send_due_estops(now)
        with self._lock:
            deadline = min(self._next_tick, self._next_stats)
            end = self._command.next_end
        if end is not None:
            deadline = min(deadline, end)
        return min(deadline, due) if due is not None else deadline

    def _end_channels(self, now: float) -> None:
        """Zero the channels whose end has come (Command.until) and send that at once."""
        with self._lock:
            ended = self._command.expired(now)
            if ended is self._command:
                return
            stopped = self._command.is_motion and not ended.is_motion
            changed = not ended.same_wire(self._command)
            self._command = ended
            if stopped:
                self._schedule_zero_repeats()
        if changed:
            self._send_current()

    def _loop_failed(self, err: BaseException) -> bool:
        log.error("link loop failed (%s); sending zeros", err)
        self._send_zeros()
        return False

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
            last_step, self._last_step_at = self._last_step_at, now
            frozen_s = None if last_step is None else now - last_step
            if frozen_s is not None and frozen_s > self.freeze_limit_s and self._command.is_motion:
                self._schedule_zero_repeats()
                self._command = self._command.stopped()
                message = f"link loop frozen for {frozen_s:.2f} s: motion commands zeroed"
            timeout = self.gui_alive_timeout_s
            stalled_s = now - self._gui_alive_at
            if (
                timeout is not None
                and self._command.is_motion
                and not self._gui_tripped
                and stalled_s > timeout
            ):
                self._gui_tripped = True
                self._schedule_zero_repeats()
                self._command = self._command.stopped()
                message = f"control thread silent for {stalled_s:.2f} s: motion commands zeroed"
            last = self.receiver.last_valid_at
            last = last if last is not None else self._started_at
            lost = self._state in (LinkState.CONNECTED, LinkState.CONNECTING) and (
                now - last > self.link_lost_after_s
            )
        if message:
            self._send_current()
            self._notify_safety(message)
        if lost:
            reason = f"no valid packet from the robot for {now - last:.1f} s"
            with self._lock:
                had_motion = self._command.is_motion
                if had_motion:
                    self._schedule_zero_repeats()
                self._command = self._command.stopped()
            self.receiver.robot_silent()
            self._set_state(LinkState.LOST, reason)
            if had_motion:
                self._send_current()
                self._notify_safety("link lost: motion commands zeroed")

    # ---- receive ---------------------------------------------------------------------------

    def _receive_all(self) -> None:
        view = memoryview(self._buffer)
        for _ in range(MAX_DATAGRAMS_PER_WAKE):
            try:
                item = self.transport.receive(self._buffer)
            except OSError as err:
                # ICMP port-unreachable from a closed robot port surfaces here on Linux.
                log.debug("receive error: %s", err)
                continue
            if item is None:
                return
            size, source = item
            self.handle_datagram(bytes(view[:size]), source)

    def handle_datagram(self, data: bytes, source: Address) -> None:
        """Decode and dispatch one datagram (the receiver's job); never raises on bad input."""
        now = self.clock()
        if source != self.robot_address:
            self.receiver.foreign()
            return
        if self.receiver.received(data, now, time.time()) and self.state != LinkState.CONNECTED:
            self._set_state(LinkState.CONNECTED, f"packets from {source[0]}:{source[1]}")

    # ---- send ------------------------------------------------------------------------------

    def current_packet_bytes(self) -> bytes:
        """The vendor RCP for the current command (bounded by the hard maxima)."""
        with self._lock:
            return self._codec.encode(self._mapper.to_packet(self._command.expired(self.clock())))

    def _send_current(self) -> None:
        # Built and sent under one lock: a tick that read the command just before the
        # operator stopped must not put its stale motion on the wire after the stop.
        with self._send_lock:
            with self._lock:
                # A channel whose end has come is zero even if the loop has not run since.
                packet = self._mapper.to_packet(self._command.expired(self.clock()))
            self._send_rcp(packet)

    def _send_zeros(self) -> None:
        with self._lock:
            zero = self._mapper.to_packet(self._command.stopped())
        self._send_rcp(zero)

    def _rcp_datagram(self, packet: RemoteControlPacket) -> bytes:
        """The RCP as sent (send lock held): sequenced to a robot speaking the extension (it
        drops one older than the newest it applied), the vendor's to any other."""
        ext = self._ext_codec
        if ext is None or ext.rcp_type is None or not self.receiver.extension_active:
            return self._codec.encode(packet)
        sequence = self._rcp_sequence
        self._rcp_sequence = (sequence + 1) % SEQUENCE_MODULUS
        return ext.encode(SequencedRcp(sequence, packet))

    def _send_rcp(self, packet: RemoteControlPacket) -> None:
        with self._send_lock:
            data = self._rcp_datagram(packet)
            sent_at = self._send_datagram(data, RCP)
            if sent_at is None:
                return
            command = self.receiver.sent(data, sent_at)
            with self._lock:
                self._sent += 1
                self._rcp_rate.add(sent_at)
        if command is not None:
            self.emit(CommandSent(command, sent_at))

    def _send_hello(self) -> None:
        if not self.extension_enabled or self._ext_codec is None:
            return
        with self._lock:
            data = self._ext_codec.encode(self._hello)
        if self._send_datagram(data, HELLO) is not None:
            with self._lock:
                self._hellos_sent += 1

    def _send_datagram(self, data: bytes, kind: str) -> float | None:
        """Put one datagram on the wire; its send time, or None if closed or it failed."""
        with self._send_lock:
            if self._closed:
                return None
            try:
                self.transport.send(data, self.robot_address)
            except OSError as err:
                with self._lock:
                    self._send_errors += 1
                log.debug("send failed: %s", err)
                return None
            sent_at = self.clock()
        self.emit(DatagramSent(data, sent_at, kind))
        return sent_at

    # ---- state and stats -------------------------------------------------------------------

    def _set_state(self, state: LinkState, reason: str) -> None:
        with self._lock:
            if self._state == state:
                return
            self._state = state
        log.info("link %s: %s", state.value, reason)
        self.emit(LinkStateChanged(state, reason))

    def stats(self) -> LinkStats:
        """Counters and rates now."""
        now = self.clock()
        with self._lock:
            sent, send_errors, estop = self._sent, self._send_errors, self._estop_latched
            rcp_rate_hz, send_rate_hz = self._rcp_rate.rate(now), self._rate_hz
        return self.receiver.link_stats(
            now,
            sent=sent,
            send_errors=send_errors,
            rcp_rate_hz=rcp_rate_hz,
            send_rate_hz=send_rate_hz,
            estop_latched=estop,
        )

    def _notify_safety(self, message: str) -> None:
        log.warning("%s", message)
        self.emit(SafetyEvent(message))

    # ---- shutdown --------------------------------------------------------------------------

    def shutdown(self, timeout_s: float = 2.0) -> None:
        """Stop the loop, send zeros last and close the transport; safe to call twice."""
        with self._send_lock:
            if self._closed:
                return
        with _LIVE_LOCK:
            _LIVE.discard(self)
        self.loop.stop(timeout_s)
        with self._lock:
            self._command = self._command.stopped()
            self._estop_due = []
        for _ in range(self.profile.link.estop_repeats):
            self._send_zeros()
        with self._send_lock:
            self._closed = True
            self.transport.close()
        self.loop.close()
        self._set_state(LinkState.CLOSED, "shut down")


class LinkOptions(TypedDict, total=False):
    """The live link's options, for the UdpLink and VirtualLink constructors."""

    listener: Listener | None
    link_lost_after_s: float | None
    gui_alive_timeout_s: float | None
    send_rate_hz: float | None
    send_on_change: bool
    extension: bool
    clock: Callable[[], float]


def _path_datagram_bytes(ext: ExtensionSettings, transport: Transport, robot: Address) -> int:
    """The video datagram size to ask for: the path's when known and wanted, else the profile's."""
    if not ext.fit_datagrams_to_path:
        return ext.max_datagram_bytes
    path = transport.path_payload_bytes(robot)
    if path is None or path < MIN_DATAGRAM:
        return ext.max_datagram_bytes
    return min(path, MAX_DATAGRAM)


class UdpLink(LiveLink):
    """The live link over UDP to a robot (or ocu-sim) at `robot_address`."""

    def __init__(
        self,
        profile: RobotProfile,
        robot_address: Address,
        *,
        bind_address: Address | None = None,
        description: str | None = None,
        **options: Unpack[LinkOptions],
    ) -> None:
        try:
            robot = resolve(robot_address)
        except TransportError as err:
            raise LinkError(f"cannot resolve robot host {robot_address[0]!r}: {err}") from err
        if bind_address is None:
            bind_address = ("127.0.0.1" if is_loopback(robot[0]) else "0.0.0.0", 0)
        try:
            transport = UdpTransport(bind_address)
        except TransportError as err:
            raise LinkError(str(err)) from err
        text = description or f"robot {robot[0]}:{robot[1]}"
        super().__init__(profile, transport, robot, text, **options)


class VirtualLink(LiveLink):
    """The live link over an in-process virtual wire (ocu.net.transport.VirtualWire)."""

    def __init__(
        self,
        profile: RobotProfile,
        endpoint: VirtualEndpoint,
        *,
        description: str = "virtual robot",
        **options: Unpack[LinkOptions],
    ) -> None:
        super().__init__(profile, endpoint, endpoint.peer, description, **options)
