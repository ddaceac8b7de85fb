"""The link core in a QThread: events become Qt signals; JPEGs decode off the GUI thread."""

from __future__ import annotations

from dataclasses import dataclass

from PySide6.QtCore import QObject, QThread, QTimer, Signal
from PySide6.QtGui import QImage

from ocu.control.commands import Command
from ocu.link.core import LinkCore, LinkListener, LinkState, TelemetryFrame, VideoFrame
from ocu.link.stats import LinkStats

HEARTBEAT_PERIOD_MS = 100


@dataclass(frozen=True)
class DecodedVideoFrame:
    """A video frame with its image decoded in the link thread (null image if corrupt)."""

    frame: VideoFrame
    image: QImage


class _SignalListener(LinkListener):
    """Forwards the core's callbacks (loop thread) to the QThread's signals (queued)."""

    def __init__(self, owner: LinkThread) -> None:
        self.owner = owner

    def telemetry_received(self, frame: TelemetryFrame) -> None:
        self.owner.telemetry_received.emit(frame)

    def video_frame_received(self, frame: VideoFrame) -> None:
        image = QImage.fromData(frame.jpeg)
        self.owner.video_frame_received.emit(DecodedVideoFrame(frame, image))

    def link_state_changed(self, state: LinkState, reason: str) -> None:
        self.owner.link_state_changed.emit(state, reason)

    def stats_updated(self, stats: LinkStats) -> None:
        self.owner.stats_updated.emit(stats)

    def safety_event(self, message: str) -> None:
        self.owner.safety_event.emit(message)


class LinkThread(QThread):
    """Runs a LinkCore's loop; the GUI thread proves it is alive with a heartbeat timer."""

    telemetry_received = Signal(object)
    video_frame_received = Signal(object)
    link_state_changed = Signal(object, str)
    stats_updated = Signal(object)
    safety_event = Signal(str)

    def __init__(self, core: LinkCore, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("ocu-link")
        self.core = core
        core.listener = _SignalListener(self)
        # The timer lives in the GUI thread: if that thread stalls, heartbeats stop and the
        # core zeroes any motion after gui_alive_timeout_s.
        self._heartbeat = QTimer(self)
        self._heartbeat.setInterval(HEARTBEAT_PERIOD_MS)
        self._heartbeat.timeout.connect(core.heartbeat)
        self._shut = False

    def start_link(self) -> None:
        """Start the loop thread and the heartbeat."""
        self._heartbeat.start()
        self.start()

    def run(self) -> None:
        """QThread body: the core's loop."""
        self.core.run()

    def set_command(self, command: Command) -> None:
        """Send a new command (at once if it changed)."""
        self.core.set_command(command)

    def emergency_stop(self, reason: str = "operator") -> None:
        """Zero all motion now, with repeats."""
        self.core.emergency_stop(reason)

    def shutdown(self, timeout_s: float = 2.0) -> None:
        """Stop the loop, send zeros last, wait for the thread; idempotent."""
        if self._shut:
            return
        self._shut = True
        self._heartbeat.stop()
        self.core.shutdown(timeout_s)
        self.wait(int(timeout_s * 1000))
