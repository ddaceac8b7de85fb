"""The console's Record button: starts and stops a Recorder, shows what it writes."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QTimer, Signal
from PySide6.QtWidgets import QPushButton, QWidget

from ocu.qt.inbox import to_gui
from ocu.record.errors import RecordingError
from ocu.record.recorder import Recorder, default_recordings_dir, timestamped_name

REFRESH_PERIOD_MS = 500
RECORDING_STYLE = "QPushButton { background: #b00020; color: white; font-weight: bold; }"


class RecordButton(QPushButton):
    """A checkable button: pressed, it records to DIR/ocu-YYYYmmdd-HHMMSS.mcap.

    Errors (unwritable directory, disk full while writing) uncheck it and are reported
    through `recording_failed(message)`; the link is not touched either way.
    """

    recording_started = Signal(str)
    recording_stopped = Signal(str)
    recording_failed = Signal(str)
    # The recorder's writer thread reports errors through this (handed to the GUI thread).
    _writer_failed = Signal(str)

    def __init__(
        self,
        recorder: Recorder,
        directory: Path | None = None,
        parent: QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self.setObjectName("record-button")
        self.recorder = recorder
        self.directory = directory if directory is not None else default_recordings_dir()
        self.setCheckable(True)
        self.clicked.connect(self._on_clicked)
        self._writer_failed.connect(self._on_writer_failed)
        recorder.on_error = to_gui(self._writer_failed.emit)
        self._timer = QTimer(self)
        self._timer.setInterval(REFRESH_PERIOD_MS)
        self._timer.timeout.connect(self.refresh)
        self.refresh()
        if recorder.recording:
            self._timer.start()

    def start_recording(self, path: Path | None = None) -> bool:
        """Record to `path` (a new file in the directory if None); False with a message if not."""
        if self.recorder.recording:
            return True
        target = path if path is not None else self.directory / timestamped_name()
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            self.recorder.start(target)
        except (OSError, RecordingError) as err:
            message = str(err)
            if isinstance(err, OSError):
                message = f"cannot record to {target}: {err.strerror or err}"
            self.refresh()
            self.setToolTip(message)
            self.recording_failed.emit(message)
            return False
        self._timer.start()
        self.refresh()
        self.recording_started.emit(str(target))
        return True

    def stop_recording(self) -> None:
        """Finish the file; idempotent."""
        was_recording = self.recorder.recording
        stats = self.recorder.stop()
        self._timer.stop()
        self.refresh()
        if was_recording and stats.path is not None:
            summary = (
                f"{stats.path}: {stats.messages_written} messages, "
                f"{stats.bytes_written / 1e6:.1f} MB in {stats.elapsed_s:.0f} s"
            )
            if stats.dropped:
                summary += f", {stats.dropped} dropped (queue full)"
            self.recording_stopped.emit(summary)

    def refresh(self) -> None:
        """Show the recording's state, length and size."""
        stats = self.recorder.stats()
        self.setChecked(stats.recording)
        if stats.recording:
            minutes, seconds = divmod(int(stats.elapsed_s), 60)
            self.setText(
                f"\u25a0 Stop  REC {minutes:02d}:{seconds:02d}  {stats.bytes_written / 1e6:.1f} MB"
            )
            self.setStyleSheet(RECORDING_STYLE)
            tip = f"Recording to {stats.path}"
            if stats.dropped:
                tip += f"; {stats.dropped} messages dropped (disk too slow)"
            self.setToolTip(tip)
        else:
            self.setText("\u25cf Record")
            self.setStyleSheet("")
            if stats.error is None:
                self.setToolTip(f"Record the session to {self.directory}")

    def _on_clicked(self, checked: bool) -> None:
        if checked:
            self.start_recording()
        else:
            self.stop_recording()

    def _on_writer_failed(self, message: str) -> None:
        self.recorder.stop()
        self._timer.stop()
        self.refresh()
        self.setToolTip(message)
        self.recording_failed.emit(message)
