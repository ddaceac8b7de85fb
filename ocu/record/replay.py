"""Replay in the console: a link-like Qt source fed by a recording, and its controls.

ReplaySource has the signals of ocu.link.qt.LinkThread (telemetry_received,
video_frame_ready + take_video_frame, video_frame_received, status_received,
extension_changed, link_state_changed, stats_updated, safety_event) and its start_link() /
shutdown(), and a `core` (ReplayCore) with what the console reads of a LinkCore, so the
console's windows connect to it as they do to a live link. Video is decoded and corrected
off the GUI thread by the same VideoDecoder and Corrector a live link uses (`decoder`,
`corrector`, `frames` as on LinkThread). It sends nothing: set_command(), emergency_stop()
and everything on `core` that would send do nothing in a replay.
"""

from __future__ import annotations

import logging
from pathlib import Path

from PySide6.QtCore import QObject, Qt, QTimer, Signal
from PySide6.QtWidgets import (
    QComboBox,
    QHBoxLayout,
    QLabel,
    QSlider,
    QStyle,
    QToolButton,
    QWidget,
)

from ocu.control.commands import Command, CommandMapper, make_codec
from ocu.link.core import TelemetryFrame
from ocu.link.qt import DecodedVideoFrame, SignalForwarder, VideoPipeline
from ocu.profile import RobotProfile
from ocu.protocol import ProtocolError, RemoteControlPacket
from ocu.record.player import SPEEDS, ReplayCore, ReplayPlayer
from ocu.record.reader import Recording

log = logging.getLogger("ocu.record")

POSITION_PERIOD_MS = 100
REPLAY_STYLE = (
    "QLabel { background: #b00020; color: white; font-weight: bold; padding: 4px 10px; "
    "border-radius: 3px; }"
)


class _ReplayForwarder(SignalForwarder):
    """The link's forwarding, plus the commands that were sent, decoded for the console."""

    def __init__(self, owner: ReplaySource) -> None:
        super().__init__(owner)
        self.source = owner
        self._codec = make_codec(owner.profile)
        self._mapper = CommandMapper(owner.profile)

    def datagram_sent(self, data: bytes, sent_at: float) -> None:
        if not data or data[0] != self._codec.rcp_type:
            return
        try:
            packet = RemoteControlPacket.decode(data, data[0])
        except ProtocolError:
            return
        self.source.command_replayed.emit(self._mapper.to_command(packet))


class ReplaySource(QObject):
    """A recording played as if it were the link; paused at the start until play()."""

    telemetry_received = Signal(object)
    telemetry_ready = Signal()
    # As on LinkThread: emitted only while something is connected; viewers use
    # video_frame_ready(camera) and take_video_frame(camera).
    video_frame_received = Signal(object)
    video_frame_ready = Signal(int)
    status_received = Signal(object)
    extension_changed = Signal(bool, str)
    link_state_changed = Signal(object, str)
    stats_updated = Signal(object)
    safety_event = Signal(str)
    # Replay only: the command each recorded RCP carried, the playback state.
    command_replayed = Signal(object)
    position_changed = Signal(float)
    playing_changed = Signal(bool)
    speed_changed = Signal(float)
    finished = Signal()

    is_replay = True

    def __init__(
        self,
        path: str | Path,
        profile: RobotProfile | None = None,
        parent: QObject | None = None,
    ) -> None:
        super().__init__(parent)
        self.setObjectName("ocu-replay")
        self.recording = Recording(path)
        try:
            self.profile = self.recording.profile(profile)
        except BaseException:
            self.recording.close()
            raise
        self.video = VideoPipeline(self.profile, self)
        self.corrector, self.frames, self.decoder = (
            self.video.corrector,
            self.video.frames,
            self.video.decoder,
        )
        self.forwarder = _ReplayForwarder(self)
        self.player = ReplayPlayer(
            self.recording,
            self.profile,
            self.forwarder,
            on_finished=self.finished.emit,
        )
        # LinkThread's `core`, as far as the console reads it; it sends nothing.
        self.core = ReplayCore(self.player)
        self._timer = QTimer(self)
        self._timer.setInterval(POSITION_PERIOD_MS)
        self._timer.timeout.connect(self._poll)
        self._was_playing = False
        self._shut = False

    @property
    def path(self) -> Path:
        """The recording's file."""
        return self.recording.path

    @property
    def duration_s(self) -> float:
        """Length of the recording in seconds."""
        return self.player.duration_s

    @property
    def position_s(self) -> float:
        """Seconds from the start of the recording."""
        return self.player.position_s

    @property
    def playing(self) -> bool:
        """Whether the replay runs."""
        return self.player.playing

    @property
    def speed(self) -> float:
        """The replay speed factor."""
        return self.player.speed

    def start_link(self) -> None:
        """Start the player (paused at the start) and the video decoder."""
        self.decoder.start()
        self.player.start()
        self._timer.start()

    def play(self) -> None:
        """Run the replay (from the start again when at the end)."""
        self.player.play()
        self._poll()

    def pause(self) -> None:
        """Hold the replay at the current moment."""
        self.player.pause()
        self._poll()

    def toggle_play(self) -> None:
        """Play when paused, pause when playing."""
        if self.player.playing:
            self.pause()
        else:
            self.play()

    def set_speed(self, speed: float) -> None:
        """Replay speed factor, 0.25-4."""
        self.player.set_speed(speed)
        self.speed_changed.emit(speed)

    def seek(self, position_s: float) -> None:
        """Jump to a moment, seconds from the start."""
        self.player.seek(position_s)
        self._poll()

    def take_video_frame(self, camera: int) -> DecodedVideoFrame | None:
        """The newest decoded frame of a camera not yet taken, or None (any thread)."""
        return self.video.take(camera)

    def take_telemetry(self) -> TelemetryFrame | None:
        """The newest telemetry frame not yet taken, or None (any thread)."""
        return self.forwarder.take_telemetry()

    def set_command(self, command: Command) -> None:
        """Nothing: a replay sends no commands."""

    def emergency_stop(self, reason: str = "operator") -> None:
        """Nothing: a replay drives no robot."""

    def shutdown(self, timeout_s: float = 2.0) -> None:
        """Stop the player and the decoder, close the file; idempotent."""
        if self._shut:
            return
        self._shut = True
        self._timer.stop()
        self.player.stop(timeout_s)
        self.decoder.stop(timeout_s)
        self.recording.close()

    def _poll(self) -> None:
        self.position_changed.emit(self.player.position_s)
        playing = self.player.playing
        if playing != self._was_playing:
            self._was_playing = playing
            self.playing_changed.emit(playing)


def format_time(seconds: float) -> str:
    """m:ss.s (h:mm:ss from an hour on)."""
    tenths = round(max(seconds, 0.0) * 10)
    minutes, tenth_seconds = divmod(tenths, 600)
    hours, minutes = divmod(minutes, 60)
    if hours:
        return f"{hours}:{minutes:02d}:{tenth_seconds / 10:04.1f}"
    return f"{minutes}:{tenth_seconds / 10:04.1f}"


class ReplayBanner(QLabel):
    """An unmistakable REPLAY label: the robot is not being driven."""

    def __init__(self, path: Path, parent: QWidget | None = None) -> None:
        super().__init__(f"REPLAY  {path.name}  (commands disabled)", parent)
        self.setObjectName("replay-banner")
        self.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.setStyleSheet(REPLAY_STYLE)
        self.setToolTip(str(path))


class ReplayControls(QWidget):
    """Play/pause, speed, a seek bar and the time; a view of a ReplaySource."""

    def __init__(self, source: ReplaySource, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.source = source
        self.setObjectName("replay-controls")
        self.badge = QLabel("REPLAY")
        self.badge.setStyleSheet(REPLAY_STYLE)
        self.play_button = QToolButton()
        self.play_button.setObjectName("replay-play")
        self.play_button.clicked.connect(source.toggle_play)
        self.slider = QSlider(Qt.Orientation.Horizontal)
        self.slider.setObjectName("replay-seek")
        self.slider.setRange(0, max(round(source.duration_s * 1000), 1))
        self.slider.setPageStep(5000)
        self.slider.setSingleStep(1000)
        self.slider.sliderReleased.connect(self._seek_to_slider)
        self.slider.actionTriggered.connect(self._on_slider_action)
        self.slider.sliderMoved.connect(self._show_time)
        self.time_label = QLabel()
        self.time_label.setObjectName("replay-time")
        self.speed_box = QComboBox()
        self.speed_box.setObjectName("replay-speed")
        for speed in SPEEDS:
            self.speed_box.addItem(f"{speed:g}x", speed)
        self.speed_box.setCurrentIndex(SPEEDS.index(1.0))
        self.speed_box.currentIndexChanged.connect(self._on_speed)

        layout = QHBoxLayout(self)
        layout.setContentsMargins(4, 2, 4, 2)
        layout.addWidget(self.badge)
        layout.addWidget(self.play_button)
        layout.addWidget(self.slider, 1)
        layout.addWidget(self.time_label)
        layout.addWidget(self.speed_box)

        source.position_changed.connect(self._on_position)
        source.playing_changed.connect(self._on_playing)
        self._on_playing(source.playing)
        self._on_position(source.position_s)

    def _on_playing(self, playing: bool) -> None:
        icon = (
            QStyle.StandardPixmap.SP_MediaPause if playing else QStyle.StandardPixmap.SP_MediaPlay
        )
        self.play_button.setIcon(self.style().standardIcon(icon))
        self.play_button.setText("Pause" if playing else "Play")
        self.play_button.setToolTip("Pause the replay" if playing else "Play the recording")

    def _on_position(self, position_s: float) -> None:
        if not self.slider.isSliderDown():
            self.slider.setValue(round(position_s * 1000))
            self._show_time(self.slider.value())

    def _show_time(self, value_ms: int) -> None:
        total = format_time(self.source.duration_s)
        self.time_label.setText(f"{format_time(value_ms / 1000)} / {total}")

    def _seek_to_slider(self) -> None:
        self.source.seek(self.slider.sliderPosition() / 1000)

    def _on_slider_action(self, action: int) -> None:
        # Clicks on the groove and keys move the slider without a press and release.
        if action != QSlider.SliderAction.SliderMove.value:
            QTimer.singleShot(0, self._seek_to_slider)

    def _on_speed(self, index: int) -> None:
        self.source.set_speed(float(self.speed_box.itemData(index)))
