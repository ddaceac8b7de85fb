"""A replay's playback in Qt: position, playing and the end as signals, for the replay bar."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QObject, QTimer, Signal

from ocu.record.replay_link import ReplayLink

POSITION_PERIOD_MS = 100


class ReplayController(QObject):
    """Play, pause, seek and speed of a ReplayLink, with signals the replay bar shows."""

    position_changed = Signal(float)
    playing_changed = Signal(bool)
    speed_changed = Signal(float)
    finished = Signal()

    def __init__(self, replay: ReplayLink, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.replay = replay
        # The player thread reaches its end: queued to the GUI thread by the signal.
        replay.on_finished = self.finished.emit
        self._timer = QTimer(self)
        self._timer.setInterval(POSITION_PERIOD_MS)
        self._timer.timeout.connect(self._poll)
        self._was_playing = False
        self._timer.start()

    @property
    def path(self) -> Path:
        """The recording's file."""
        return self.replay.path

    @property
    def duration_s(self) -> float:
        """Length of the recording in seconds."""
        return self.replay.duration_s

    @property
    def position_s(self) -> float:
        """Seconds from the start of the recording."""
        return self.replay.position_s

    @property
    def playing(self) -> bool:
        """Whether the replay runs."""
        return self.replay.playing

    @property
    def speed(self) -> float:
        """The replay speed factor."""
        return self.replay.speed

    def play(self) -> None:
        """Run the replay (from the start again when at the end)."""
        self.replay.play()
        self._poll()

    def pause(self) -> None:
        """Hold the replay at the current moment."""
        self.replay.pause()
        self._poll()

    def toggle_play(self) -> None:
        """Play when paused, pause when playing."""
        self.replay.toggle_play()
        self._poll()

    def set_speed(self, speed: float) -> None:
        """Replay speed factor, 0.25-4."""
        self.replay.set_speed(speed)
        self.speed_changed.emit(speed)

    def seek(self, position_s: float) -> None:
        """Jump to a moment, seconds from the start."""
        self.replay.seek(position_s)
        self._poll()

    def stop(self) -> None:
        """Stop polling (the link itself is shut down by its QtLink)."""
        self._timer.stop()
        self.replay.on_finished = None

    def _poll(self) -> None:
        self.position_changed.emit(self.replay.position_s)
        playing = self.replay.playing
        if playing != self._was_playing:
            self._was_playing = playing
            self.playing_changed.emit(playing)
