"""Play a recording back as link events: the same LinkListener calls a live link makes.

Telemetry, video and extension packets are rebuilt from the raw datagrams through the
project's own codecs, reassembler and SI conversion, so a replay shows exactly what the OCU
decoded live; link statistics, link states, safety and extension events come from the
channels that recorded them. A vendor video frame carries no camera id: it is shown on the
camera selected by the latest RCP, as the live link does. Commands are never sent: the RCPs
of the recording reach the listener only as `datagram_sent`.

Frames carry `received_at` = the replay's monotonic time of emission (freshness checks and
plots work as live) and `wall_time` = the wall-clock time of the recording.

The player runs in a named thread ("ocu-replay"), reads one chunk at a time and waits
between messages so they come out at the recorded pace times `speed`. No Qt here.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

from ocu.control.commands import (
    Command,
    CommandMapper,
    VelocityLimits,
    make_codec,
    read_telemetry,
)
from ocu.link.core import (
    LinkListener,
    LinkState,
    StatusFrame,
    TelemetryFrame,
    VideoFrame,
)
from ocu.link.reassembly import Reassembler, ReassemblyStats
from ocu.link.stats import LinkStats
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
from ocu.record import schemas as s
from ocu.record.reader import RecordedMessage, Recording

log = logging.getLogger("ocu.record")

MIN_SPEED = 0.25
MAX_SPEED = 4.0
SPEEDS = (0.25, 0.5, 1.0, 2.0, 4.0)
# The longest the thread waits before looking at its controls again.
MAX_WAIT_S = 0.1
# The longest it emits a backlog before looking at its controls again.
EMIT_BUDGET_S = 0.05
# How many chunks before a seek target are searched for the link's state at that moment.
LOOKBACK_CHUNKS = 8
STOP_TIMEOUT_S = 5.0

REPLAYED_TOPICS = frozenset((*s.RAW_TOPICS, s.LINK_STATS, s.EVENTS))


class ReplayDecoder:
    """Turns recorded messages into LinkListener calls, decoding as LinkCore does."""

    def __init__(
        self,
        recording: Recording,
        profile: RobotProfile,
        listener: LinkListener,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.recording = recording
        self.profile = profile
        self.listener = listener
        self.clock = clock
        self._codec = make_codec(profile)
        self._mapper = CommandMapper(profile)
        ext = profile.extension
        self._ext_codec = (
            ExtendedCodec(
                ext.frame_types.hello, ext.frame_types.video_fragment, ext.frame_types.status
            )
            if ext is not None
            else None
        )
        self.command = Command()
        self.state = LinkState.CONNECTING
        self.extension_active = False
        self.last_stats: LinkStats | None = None
        self._lock = threading.Lock()
        self._reassembler = self._new_reassembler()

    def _new_reassembler(self) -> Reassembler:
        video = self.profile.video
        return Reassembler(
            video.reassembly_max_frames, video.reassembly_max_bytes, video.reassembly_timeout_s
        )

    @property
    def camera(self) -> int | None:
        """The camera the latest replayed RCP selected (vendor video is shown on it)."""
        return self.command.camera

    def reset(self) -> None:
        """Forget partial video frames (after a seek)."""
        with self._lock:
            self._reassembler = self._new_reassembler()

    def video_stats(self) -> ReassemblyStats:
        """Counters of the replay's fragment reassembly (any thread)."""
        with self._lock:
            return self._reassembler.stats()

    def _stats(self, stats: LinkStats) -> None:
        self.last_stats = stats
        self._call(self.listener.stats_updated, stats)

    def _state(self, state: LinkState, reason: str) -> None:
        self.state = state
        self._call(self.listener.link_state_changed, state, reason)

    def _extension(self, active: bool, reason: str) -> None:
        self.extension_active = active
        self._call(self.listener.extension_changed, active, reason)

    def _call(self, callback: Callable[..., None], *args: object) -> None:
        try:
            callback(*args)
        except Exception:
            log.exception("replay listener %s failed", getattr(callback, "__name__", callback))

    def feed(self, message: RecordedMessage) -> None:
        """Emit what one recorded message stands for."""
        topic = message.topic
        if topic not in REPLAYED_TOPICS:
            return
        decoded = self.recording.decode(message)
        if topic == s.LINK_STATS:
            self._stats(link_stats(decoded))
        elif topic == s.EVENTS:
            self._event(decoded.kind, decoded.state, decoded.message)
        elif decoded.source == s.SOURCE_OCU:
            self._sent(bytes(decoded.data))
        else:
            self._received(bytes(decoded.data), message.log_time_ns)

    def restore(self, stats: Any | None, rcp: Any | None) -> None:
        """Put the listener in the state the link had at a seek target."""
        if rcp is not None:
            self._track_camera(bytes(rcp.data))
        if stats is None:
            return
        if stats.link_state:
            try:
                state = LinkState(stats.link_state)
            except ValueError:
                state = None
            if state is not None:
                self._state(state, "replay: state at this time")
        self._extension(bool(stats.extension_active), "replay: state at this time")
        self._stats(link_stats(stats))

    def _event(self, kind: str, state: str, message: str) -> None:
        if kind == s.EVENT_LINK_STATE:
            try:
                link_state = LinkState(state)
            except ValueError:
                log.warning("unknown link state %r in recording", state)
                return
            self._state(link_state, message)
        elif kind == s.EVENT_SAFETY:
            self._call(self.listener.safety_event, message)
        elif kind == s.EVENT_EXTENSION:
            self._extension(state == "active", message)

    def _track_camera(self, data: bytes) -> None:
        if not data or data[0] != self._codec.rcp_type:
            return
        try:
            packet = RemoteControlPacket.decode(data, data[0])
        except ProtocolError:
            return
        self.command = self._mapper.to_command(packet)

    def _sent(self, data: bytes) -> None:
        self._track_camera(data)
        self._call(self.listener.datagram_sent, data, self.clock())

    def _received(self, data: bytes, log_time_ns: int) -> None:
        now = self.clock()
        wall = log_time_ns / 1e9
        self._call(self.listener.datagram_received, data, now)
        if self._ext_codec is not None and self._ext_codec.handles(data[0] if data else -1):
            self._extended(data, now, wall, log_time_ns / 1e9)
            return
        try:
            packet = self._codec.decode(data)
        except ProtocolError:
            return
        if isinstance(packet, TelemetryPacket):
            frame = TelemetryFrame(packet, read_telemetry(self.profile, packet), now, wall)
            self._call(self.listener.telemetry_received, frame)
        elif isinstance(packet, VideoFramePacket):
            video = VideoFrame(packet.jpeg, self.camera, now, wall)
            self._call(self.listener.video_frame_received, video)

    def _extended(self, data: bytes, now: float, wall: float, recorded_s: float) -> None:
        assert self._ext_codec is not None
        try:
            packet = self._ext_codec.decode(data)
        except ProtocolError:
            return
        if isinstance(packet, StatusPacket):
            self._call(self.listener.status_received, StatusFrame(packet, now, wall))
        elif isinstance(packet, VideoFragment):
            # The reassembler's timeouts run on the recording's clock, as they did live.
            with self._lock:
                complete = self._reassembler.add(packet, recorded_s)
            if complete is not None:
                frame = VideoFrame(
                    complete.jpeg,
                    complete.camera,
                    now,
                    wall,
                    sequence=complete.sequence,
                    capture_time_us=complete.capture_time_us,
                )
                self._call(self.listener.video_frame_received, frame)


def link_stats(message: Any) -> LinkStats:
    """A LinkStats from a decoded ocu_msgs/msg/LinkStats."""
    return LinkStats(
        sent=int(message.sent),
        received=int(message.received),
        telemetry=int(message.telemetry),
        video=int(message.video),
        malformed=int(message.malformed),
        foreign=int(message.foreign),
        send_errors=int(message.send_errors),
        rcp_rate_hz=float(message.rcp_rate_hz),
        telemetry_rate_hz=float(message.telemetry_rate_hz),
        video_rate_hz=float(message.video_rate_hz),
        loss_estimate=s.none_if_nan(message.loss_estimate),
        duplicates=int(message.duplicates),
        reordered=int(message.reordered),
        last_valid_age_s=s.none_if_nan(message.last_valid_age_s),
        send_rate_hz=float(message.send_rate_hz),
        estop_latched=bool(message.estop_latched),
        # Recordings made before these fields existed lack them.
        delay_s=s.none_if_nan(getattr(message, "delay_s", math.nan)),
        stale_telemetry=int(getattr(message, "stale_telemetry", 0)),
    )


class ReplayPlayer:
    """Plays a recording into a LinkListener in real time times `speed`, with pause and seek.

    Starts paused at the beginning. `on_finished` is called (player thread) at the end.
    """

    def __init__(
        self,
        recording: Recording,
        profile: RobotProfile,
        listener: LinkListener,
        *,
        clock: Callable[[], float] = time.monotonic,
        on_finished: Callable[[], None] | None = None,
    ) -> None:
        self.recording = recording
        self.clock = clock
        self.on_finished = on_finished
        self.decoder = ReplayDecoder(recording, profile, listener, clock)
        self.start_ns = recording.start_ns
        self.end_ns = recording.end_ns
        self._cond = threading.Condition()
        self._playing = False
        self._finished = False
        self._speed = 1.0
        self._anchor_ns = self.start_ns
        self._anchor_mono = clock()
        self._seek_to: int | None = self.start_ns
        self._stop = False
        self._pending: deque[RecordedMessage] = deque()
        self._next_chunk = 0
        self._thread: threading.Thread | None = None

    # ---- controls (any thread) -------------------------------------------------------------

    @property
    def duration_s(self) -> float:
        """Length of the recording in seconds."""
        return (self.end_ns - self.start_ns) / 1e9

    @property
    def position_s(self) -> float:
        """Seconds from the start of the recording to the replay's current moment."""
        with self._cond:
            return (self._position_ns() - self.start_ns) / 1e9

    @property
    def playing(self) -> bool:
        """Whether time runs (not paused, not at the end)."""
        with self._cond:
            return self._playing

    @property
    def speed(self) -> float:
        """The replay speed factor."""
        with self._cond:
            return self._speed

    def _position_ns(self) -> int:
        if not self._playing:
            return self._anchor_ns
        elapsed = (self.clock() - self._anchor_mono) * self._speed
        return min(self._anchor_ns + round(elapsed * 1e9), self.end_ns)

    def _reanchor(self) -> None:
        self._anchor_ns = self._position_ns()
        self._anchor_mono = self.clock()

    def play(self) -> None:
        """Run time forward; from the start again when at the end."""
        with self._cond:
            if self._finished:
                self._seek_locked(self.start_ns)
            self._reanchor()
            self._playing = True
            self._cond.notify_all()

    def pause(self) -> None:
        """Stop time; the current frame stays shown."""
        with self._cond:
            self._reanchor()
            self._playing = False
            self._cond.notify_all()

    def set_speed(self, speed: float) -> None:
        """Change the speed factor (0.25-4)."""
        if not MIN_SPEED <= speed <= MAX_SPEED:
            raise ValueError(f"speed must be within {MIN_SPEED}-{MAX_SPEED}, got {speed!r}")
        with self._cond:
            self._reanchor()
            self._speed = speed
            self._cond.notify_all()

    def seek(self, position_s: float) -> None:
        """Jump to a moment (seconds from the start), clamped to the recording."""
        target = self.start_ns + round(max(position_s, 0.0) * 1e9)
        with self._cond:
            self._seek_locked(min(target, self.end_ns))
            self._cond.notify_all()

    def _seek_locked(self, target_ns: int) -> None:
        self._seek_to = target_ns
        self._anchor_ns = target_ns
        self._anchor_mono = self.clock()
        self._finished = False

    def start(self) -> None:
        """Start the player thread (paused until play())."""
        if self._thread is not None:
            return
        self._thread = threading.Thread(target=self._run, name="ocu-replay", daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = STOP_TIMEOUT_S) -> None:
        """Stop the thread; idempotent."""
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout_s)
            if thread.is_alive():
                log.error("replay thread did not stop within %.1f s", timeout_s)

    # ---- the player thread -----------------------------------------------------------------

    def _run(self) -> None:
        try:
            self._loop()
        except Exception:
            log.exception("replay failed")

    def _loop(self) -> None:
        while True:
            with self._cond:
                if self._stop:
                    return
                target = self._seek_to
                self._seek_to = None
            if target is not None:
                self._do_seek(target)
                continue
            with self._cond:
                if not self._playing or self._finished:
                    self._cond.wait(MAX_WAIT_S * 5)
                    continue
                position = self._position_ns()
                speed = self._speed
            next_ns = self._emit_until(position)
            with self._cond:
                if self._stop or self._seek_to is not None:
                    continue
                if next_ns is None:
                    self._anchor_ns = self.end_ns
                    self._playing = False
                    self._finished = True
                    finished = True
                else:
                    finished = False
                    wait_s = (next_ns - self._position_ns()) / 1e9 / speed
                    if wait_s > 0:
                        self._cond.wait(min(wait_s, MAX_WAIT_S))
            if finished and self.on_finished is not None:
                try:
                    self.on_finished()
                except Exception:
                    log.exception("replay finished callback failed")

    def _emit_until(self, position_ns: int) -> int | None:
        """Emit the messages up to a log time; the time of the next one, None at the end."""
        deadline = self.clock() + EMIT_BUDGET_S
        while True:
            if not self._pending:
                if self._next_chunk >= len(self.recording.chunks):
                    return None
                self._pending.extend(self.recording.read_chunk(self._next_chunk))
                self._next_chunk += 1
                continue
            message = self._pending[0]
            if message.log_time_ns > position_ns or self.clock() > deadline:
                return message.log_time_ns
            self._pending.popleft()
            self.decoder.feed(message)

    def _do_seek(self, target_ns: int) -> None:
        recording = self.recording
        index = recording.chunk_at(target_ns)
        self.decoder.reset()
        stats = rcp = None
        self._pending.clear()
        if index < len(recording.chunks):
            messages = recording.read_chunk(index)
            self._pending.extend(m for m in messages if m.log_time_ns >= target_ns)
            before = [m for m in messages if m.log_time_ns < target_ns]
        else:
            before = []
        self._next_chunk = index + 1
        # The link's state, the stats and the selected camera at the target: the latest such
        # messages before it, searched backwards over a few chunks.
        lookback = index
        while True:
            for message in reversed(before):
                if stats is None and message.topic == s.LINK_STATS:
                    stats = recording.decode(message)
                elif rcp is None and message.topic == s.RAW_RCP:
                    rcp = recording.decode(message)
            if (stats is not None and rcp is not None) or lookback <= 0:
                break
            if index - lookback >= LOOKBACK_CHUNKS:
                break
            lookback -= 1
            before = recording.read_chunk(lookback)
        self.decoder.restore(stats, rcp)


class ReplayCore:
    """What the console reads of a LinkCore, answered by a replay: it never sends anything.

    The command, link state, statistics and video counters are those of the replayed moment.
    set_command, set_velocities, emergency_stop, set_stream_request and heartbeat are accepted
    and do nothing; set_max_velocity only keeps the value, so the windows can show it.
    """

    def __init__(self, player: ReplayPlayer) -> None:
        self._decoder = player.decoder
        self.profile = player.decoder.profile
        self.limits = VelocityLimits(self.profile)
        self._stream_request = HelloPacket()

    @property
    def command(self) -> Command:
        """The command of the latest replayed RCP."""
        return self._decoder.command

    @property
    def state(self) -> LinkState:
        """The link state at the replayed moment."""
        return self._decoder.state

    @property
    def extension_active(self) -> bool:
        """Whether the robot spoke the extension at the replayed moment."""
        return self._decoder.extension_active

    @property
    def rate_hz(self) -> float:
        """The recording's RCP rate setting as the latest statistics give it."""
        stats = self._decoder.last_stats
        return stats.send_rate_hz if stats is not None else self.profile.link.send_rate_hz

    @property
    def stream_request(self) -> HelloPacket:
        """The last stream request the console made (never sent)."""
        return self._stream_request

    def stats(self) -> LinkStats:
        """The latest replayed statistics (all zero before the first)."""
        stats = self._decoder.last_stats
        if stats is not None:
            return stats
        return LinkStats(0, 0, 0, 0, 0, 0, 0, 0.0, 0.0, 0.0, None, 0, 0, None, self.rate_hz, False)

    def video_stats(self) -> ReassemblyStats:
        """Counters of the replay's fragment reassembly."""
        return self._decoder.video_stats()

    def set_command(self, command: Command) -> None:
        """Nothing: a replay sends no commands."""

    def set_velocities(self, **velocities: float) -> None:
        """Nothing: a replay sends no commands."""

    def emergency_stop(self, reason: str = "operator") -> None:
        """Nothing: a replay drives no robot."""

    def heartbeat(self) -> None:
        """Nothing to keep alive."""

    def set_max_velocity(self, channel: str, value: float) -> float:
        """Keep a channel's maximum (clipped like the link's); nothing is sent."""
        return self.limits.set(channel, value)

    def set_stream_request(self, cameras: Sequence[CameraRequest]) -> None:
        """Remember the request; nothing is sent."""
        self._stream_request = HelloPacket(
            cameras=tuple(cameras), max_datagram_bytes=self._stream_request.max_datagram_bytes
        )
