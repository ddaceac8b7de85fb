"""A recording played back as a read-only Link: the same events a live link emits.

The raw datagrams of the recording go through the same receiver as live (ocu.link.receiver),
so a replay shows exactly what the OCU decoded; link statistics, link states, safety and
extension events come from the channels that recorded them. Commands are never sent: the
RCPs of the recording are noted as sent (the camera they selected is where vendor video is
shown, and their echoes measure the delay as they did live).

Frames carry `received_at` = the replay's monotonic time of emission (freshness checks and
plots work as live) and `wall_time` = the wall-clock time of the recording.

A UR arm's recording plays through `UrReplayLink` (ocu.record.ur_replay), which overrides
the decoding steps (`_sent`, `_received`, `_reset_decoding`); `open_replay` there picks the
one a file needs.

A named thread ("ocu-replay") reads one chunk at a time and waits between messages so they
come out at the recorded pace times `speed`. It starts paused at the beginning. No Qt.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ocu.link.base import Link, LinkError
from ocu.link.receiver import Receiver
from ocu.profile import RobotProfile
from ocu.record import schemas as s
from ocu.record.errors import RecordingError
from ocu.record.reader import RecordedMessage, Recording
from ocu.records import (
    CameraRequest,
    Command,
    CommandSent,
    ExtensionChanged,
    LinkEvent,
    LinkState,
    LinkStateChanged,
    LinkStats,
    SafetyEvent,
    StreamRequest,
    VideoStats,
)

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
        jitter_s=s.none_if_nan(getattr(message, "jitter_s", math.nan)),
        scan_rate_hz=float(getattr(message, "scan_rate_hz", 0.0)),
        frame_age_s=tuple(s.none_if_nan(float(age)) for age in getattr(message, "frame_age_s", ())),
        uplink_loss=s.none_if_nan(getattr(message, "uplink_loss", math.nan)),
    )


class ReplayLink(Link):
    """A recording as a Link: events out at the recorded pace, commands ignored.

    `on_finished` is called (player thread) when the end is reached.
    """

    read_only = True
    #: The topics played, and the one whose latest message before a seek gives the command.
    replayed_topics = REPLAYED_TOPICS
    command_topic: str = s.RAW_RCP

    def __init__(
        self,
        path: str | Path,
        profile: RobotProfile | None = None,
        *,
        clock: Callable[[], float] = time.monotonic,
        on_finished: Callable[[], None] | None = None,
    ) -> None:
        try:
            recording = Recording(path)
        except RecordingError as err:
            raise LinkError(str(err)) from err
        try:
            replay_profile = recording.profile(profile)
        except BaseException:
            recording.close()
            raise
        super().__init__(replay_profile, f"replay {recording.path.name}")
        self.recording = recording
        self.clock = clock
        self.on_finished = on_finished
        self.receiver = self._new_receiver()
        self._state = LinkState.CONNECTING
        self._extension_active = False
        self._last_stats: LinkStats | None = None
        self._command = Command()
        self._stream_request = StreamRequest()
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
        self._closed = False

    def _new_receiver(self) -> Receiver:
        # Extension packets are decoded as live whenever the profile defines them.
        return Receiver(self.profile, self._on_receiver_event, extension=True)

    def _on_receiver_event(self, event: LinkEvent) -> None:
        # The recording holds the live link's own extension events: the receiver's (which
        # would also fire after a seek) are not replayed twice.
        if not isinstance(event, ExtensionChanged):
            self.emit(event)

    @property
    def path(self) -> Path:
        """The recording's file."""
        return self.recording.path

    # ---- the Link interface: a replay commands nothing -------------------------------------

    @property
    def command(self) -> Command:
        """The command of the latest replayed RCP."""
        with self._cond:
            return self._command

    def set_command(self, command: Command) -> None:
        """Nothing: a replay sends no commands."""

    def set_velocities(self, **velocities: float) -> None:
        """Nothing: a replay sends no commands."""

    def emergency_stop(self, reason: str = "operator") -> None:
        """Nothing: a replay drives no robot."""

    def heartbeat(self) -> None:
        """Nothing to keep alive."""

    @property
    def stream_request(self) -> StreamRequest:
        """The last stream request the console made (never sent)."""
        return self._stream_request

    def set_stream_request(self, cameras: Sequence[CameraRequest]) -> None:
        """Remember the request; nothing is sent."""
        self._stream_request = StreamRequest(
            cameras=tuple(cameras), max_datagram_bytes=self._stream_request.max_datagram_bytes
        )

    @property
    def rate_hz(self) -> float:
        """The recording's RCP rate setting as the latest statistics give it."""
        stats = self._last_stats
        return stats.send_rate_hz if stats is not None else self.profile.link.send_rate_hz

    def set_rate_hz(self, rate_hz: float) -> None:
        """Nothing: a replay sends no commands."""

    @property
    def state(self) -> LinkState:
        """The link state at the replayed moment."""
        return self._state

    @property
    def extension_active(self) -> bool:
        """Whether the robot spoke the extension at the replayed moment."""
        return self._extension_active

    def stats(self) -> LinkStats:
        """The latest replayed statistics (all zero before the first)."""
        stats = self._last_stats
        return stats if stats is not None else LinkStats.empty(self.rate_hz)

    def video_stats(self) -> VideoStats:
        """Counters of the replay's fragment reassembly."""
        return self.receiver.video_stats()

    # ---- playback (any thread) -------------------------------------------------------------

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
    def finished(self) -> bool:
        """Whether the replay reached the end (until play() or a seek)."""
        with self._cond:
            return self._finished

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

    def toggle_play(self) -> None:
        """Play when paused, pause when playing."""
        if self.playing:
            self.pause()
        else:
            self.play()

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

    # ---- life ------------------------------------------------------------------------------

    def start(self) -> None:
        """Start the player thread (paused until play())."""
        if self._thread is not None:
            return
        self._thread = threading.Thread(target=self._run, name="ocu-replay", daemon=True)
        self._thread.start()

    def shutdown(self, timeout_s: float = STOP_TIMEOUT_S) -> None:
        """Stop the thread and close the file; idempotent."""
        if self._closed:
            return
        self._closed = True
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout_s)
            if thread.is_alive():
                log.error("replay thread did not stop within %.1f s", timeout_s)
        self.recording.close()

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
            finished = False
            with self._cond:
                if self._stop or self._seek_to is not None:
                    continue
                if next_ns is None:
                    self._at_end()
                    self._anchor_ns = self.end_ns
                    self._playing = False
                    self._finished = True
                    finished = True
                else:
                    wait_s = (next_ns - self._position_ns()) / 1e9 / speed
                    if wait_s > 0:
                        self._cond.wait(min(wait_s, MAX_WAIT_S))
            if finished and self.on_finished is not None:
                try:
                    self.on_finished()
                except Exception:
                    log.exception("replay finished callback failed")

    def _at_end(self) -> None:
        """The end of the file is reached (player thread): a subclass emits what it held."""

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
            self._feed(message)

    def _feed(self, message: RecordedMessage) -> None:
        """Emit what one recorded message stands for."""
        topic = message.topic
        if topic not in self.replayed_topics:
            return
        decoded = self.recording.decode(message)
        if topic == s.LINK_STATS:
            self._stats(link_stats(decoded))
        elif topic == s.EVENTS:
            self._event(decoded.kind, decoded.state, decoded.message)
        elif decoded.source == s.SOURCE_OCU:
            now = self.clock()
            command = self._sent(message, bytes(decoded.data), now)
            if command is not None:
                with self._cond:
                    self._command = command
                self.emit(CommandSent(command, now))
        else:
            self._received(message, bytes(decoded.data))

    def _sent(self, message: RecordedMessage, data: bytes, now: float) -> Command | None:
        """What the OCU sent, decoded: the command it carried (None: none)."""
        return self.receiver.sent(data, now)

    def _received(self, message: RecordedMessage, data: bytes) -> None:
        """What the robot sent, through the live link's receiver."""
        self.receiver.received(data, self.clock(), message.log_time_ns / 1e9)

    def _reset_decoding(self) -> None:
        """Forget what the decoding held (a seek)."""
        self.receiver = self._new_receiver()

    def _stats(self, stats: LinkStats) -> None:
        self._last_stats = stats
        self.emit(stats)

    def _set_state(self, state: LinkState, reason: str) -> None:
        self._state = state
        self.emit(LinkStateChanged(state, reason))

    def _set_extension(self, active: bool, reason: str) -> None:
        self._extension_active = active
        self.emit(ExtensionChanged(active, reason))

    def _event(self, kind: str, state: str, message: str) -> None:
        if kind == s.EVENT_LINK_STATE:
            link_state = LinkState.parse(state)
            if link_state is None:
                log.warning("unknown link state %r in recording", state)
                return
            self._set_state(link_state, message)
        elif kind == s.EVENT_SAFETY:
            self.emit(SafetyEvent(message))
        elif kind == s.EVENT_EXTENSION:
            self._set_extension(state == "active", message)

    def _do_seek(self, target_ns: int) -> None:
        recording = self.recording
        index = recording.chunk_at(target_ns)
        self._reset_decoding()
        stats: Any | None = None
        rcp: RecordedMessage | None = None
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
                elif rcp is None and message.topic == self.command_topic:
                    rcp = message
            if (stats is not None and rcp is not None) or lookback <= 0:
                break
            if index - lookback >= LOOKBACK_CHUNKS:
                break
            lookback -= 1
            before = recording.read_chunk(lookback)
        self._restore(stats, rcp)

    def _restore(self, stats: Any | None, rcp: RecordedMessage | None) -> None:
        """Put the listeners in the state the link had at a seek target."""
        if rcp is not None:
            data = bytes(self.recording.decode(rcp).data)
            command = self._sent(rcp, data, self.clock())
            if command is not None:
                with self._cond:
                    self._command = command
        if stats is None:
            return
        if stats.link_state:
            state = LinkState.parse(stats.link_state)
            if state is not None:
                self._set_state(state, "replay: state at this time")
        self._set_extension(bool(stats.extension_active), "replay: state at this time")
        self._stats(link_stats(stats))
