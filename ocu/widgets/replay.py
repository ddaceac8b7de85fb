"""The replay bar: an unmistakable REPLAY banner, and play/pause, seek and speed controls."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import (
    QComboBox,
    QHBoxLayout,
    QLabel,
    QSlider,
    QStyle,
    QToolButton,
    QWidget,
)

from ocu.qt.replay import ReplayController
from ocu.record.replay_link import SPEEDS

REPLAY_STYLE = (
    "QLabel { background: #b00020; color: white; font-weight: bold; padding: 4px 10px; "
    "border-radius: 3px; }"
)


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
    """Play/pause, speed, a seek bar and the time; a view of a ReplayController."""

    def __init__(self, source: ReplayController, parent: QWidget | None = None) -> None:
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
