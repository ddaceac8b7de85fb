"""Any Link in Qt: its events become signals, its JPEGs are decoded off the GUI thread.

`QtLink` wraps a live link or a replay alike (the window never asks which: `link.read_only`
says whether commands go anywhere). The signals are declared here once.

Telemetry and video take mailboxes so a slow GUI drops stale data instead of queueing it: the
link's thread puts the newest telemetry frame in a one-frame slot and emits
`telemetry_ready()` only when the slot was empty; JPEGs go to the "ocu-video" decoder thread
(newest per camera wins), which puts the decoded image in a one-slot mailbox per camera and
emits `video_frame_ready(camera)` only when that mailbox was empty. At most one such signal
per mailbox is ever queued; the GUI takes the newest with `take_telemetry()` and
`take_video_frame(camera)`. `telemetry_received` and `video_frame_received` (one signal per
frame, which would queue) fire only while something is connected to them, as does
`command_sent` (a CommandSent record per RCP on the wire, for odometry). Range scans
(`scan_received`) and status packets come at a few per second and are signalled each.
"""

from __future__ import annotations

from dataclasses import dataclass

from PySide6.QtCore import QMetaMethod, QObject, QTimer, Signal
from PySide6.QtGui import QImage

from ocu.link.base import Link
from ocu.records import (
    CommandSent,
    ExtensionChanged,
    LinkEvent,
    LinkStateChanged,
    LinkStats,
    SafetyEvent,
    ScanFrame,
    StatusFrame,
    TelemetryFrame,
    VideoFrame,
)
from ocu.video.correction import Corrector
from ocu.video.decoder import DecodedFrame, VideoDecoder
from ocu.video.slot import LatestFrames

HEARTBEAT_PERIOD_MS = 100


@dataclass(frozen=True)
class DecodedVideoFrame:
    """A video frame with its image decoded off the GUI thread (null image if corrupt).

    `image` wraps `decoded.pixels` without a copy; keep this object (not only the QImage)
    alive while the image is in use.
    """

    frame: VideoFrame
    image: QImage
    decoded: DecodedFrame | None = None


def wrap_pixels(decoded: DecodedFrame) -> QImage:
    """A QImage over the decoder's BGRA pixels, no copy (Format_RGB32 on little-endian)."""
    pixels = decoded.pixels
    return QImage(
        pixels.data, decoded.width, decoded.height, pixels.strides[0], QImage.Format.Format_RGB32
    )


class QtLink(QObject):
    """A Link's events as signals, its video decoded; the GUI thread's heartbeat for it."""

    telemetry_received = Signal(object)
    telemetry_ready = Signal()
    video_frame_received = Signal(object)
    video_frame_ready = Signal(int)
    status_received = Signal(object)
    scan_received = Signal(object)
    extension_changed = Signal(bool, str)
    link_state_changed = Signal(object, str)
    stats_updated = Signal(object)
    safety_event = Signal(str)
    command_sent = Signal(object)

    def __init__(self, link: Link, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("ocu-qt-link")
        self.link = link
        profile = link.profile
        cameras = len(profile.link.camera_names)
        self.corrector = Corrector(profile.cameras)
        self.frames: LatestFrames[DecodedVideoFrame] = LatestFrames(cameras)
        self.decoder = VideoDecoder(
            cameras,
            self.corrector,
            self._on_decoded,
            self._on_corrupt,
            opencv_threads=profile.video.opencv_threads,
        )
        self._telemetry: LatestFrames[TelemetryFrame] = LatestFrames(1)
        self._every_frame = QMetaMethod.fromSignal(self.telemetry_received)
        self._every_video = QMetaMethod.fromSignal(self.video_frame_received)
        self._every_command = QMetaMethod.fromSignal(self.command_sent)
        link.subscribe(self._on_event)
        # The timer lives in the GUI thread: if that thread stalls, heartbeats stop and the
        # link zeroes any motion after its GUI-alive timeout.
        self._heartbeat = QTimer(self)
        self._heartbeat.setInterval(HEARTBEAT_PERIOD_MS)
        self._heartbeat.timeout.connect(link.heartbeat)
        self._shut = False

    @property
    def read_only(self) -> bool:
        """Whether the link commands nothing (a replay)."""
        return self.link.read_only

    def start(self) -> None:
        """Start the heartbeat, the video decoder and the link."""
        self._heartbeat.start()
        self.decoder.start()
        self.link.start()

    def take_telemetry(self) -> TelemetryFrame | None:
        """The newest telemetry frame not yet taken, or None (any thread)."""
        return self._telemetry.take(0)

    def take_video_frame(self, camera: int) -> DecodedVideoFrame | None:
        """The newest decoded frame of a camera not yet taken, or None (any thread)."""
        return self.frames.take(camera)

    def full_size(self, frame: DecodedVideoFrame) -> DecodedVideoFrame | None:
        """The frame decoded again at its full size (a snapshot); None if it cannot be."""
        decoded = frame.decoded
        if decoded is None:
            return None
        again = self.decoder.decode_now(frame.frame, decoded.slot, learn=False)
        return None if again is None else DecodedVideoFrame(frame.frame, wrap_pixels(again), again)

    def shutdown(self, timeout_s: float = 2.0) -> None:
        """Stop the heartbeat, the link (zeros last) and the decoder; idempotent."""
        if self._shut:
            return
        self._shut = True
        self._heartbeat.stop()
        self.link.shutdown(timeout_s)
        self.link.unsubscribe(self._on_event)
        self.decoder.stop(timeout_s)

    # ---- the link's threads ----------------------------------------------------------------

    def _on_event(self, event: LinkEvent) -> None:
        if isinstance(event, TelemetryFrame):
            if self._telemetry.put(0, event):
                self.telemetry_ready.emit()
            if self.isSignalConnected(self._every_frame):
                self.telemetry_received.emit(event)
        elif isinstance(event, VideoFrame):
            self.decoder.submit(event)
        elif isinstance(event, StatusFrame):
            self.status_received.emit(event)
        elif isinstance(event, ScanFrame):
            self.scan_received.emit(event)
        elif isinstance(event, ExtensionChanged):
            self.extension_changed.emit(event.active, event.reason)
        elif isinstance(event, LinkStateChanged):
            self.link_state_changed.emit(event.state, event.reason)
        elif isinstance(event, LinkStats):
            self.stats_updated.emit(event)
        elif isinstance(event, SafetyEvent):
            self.safety_event.emit(event.message)
        elif isinstance(event, CommandSent) and self.isSignalConnected(self._every_command):
            self.command_sent.emit(event)

    def _on_decoded(self, decoded: DecodedFrame) -> None:
        # Decoder thread: QImage (unlike QPixmap) may be built outside the GUI thread.
        frame = DecodedVideoFrame(decoded.source, wrap_pixels(decoded), decoded)
        if self.frames.put(decoded.slot, frame):
            self.video_frame_ready.emit(decoded.slot)
        if self.isSignalConnected(self._every_video):
            self.video_frame_received.emit(frame)

    def _on_corrupt(self, frame: VideoFrame, slot: int) -> None:
        # Counted by the decoder (decoder.stats); the viewer keeps showing the last good frame.
        if self.isSignalConnected(self._every_video):
            self.video_frame_received.emit(DecodedVideoFrame(frame, QImage()))
