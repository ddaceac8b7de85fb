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

The link's and the decoder's threads never call Qt: they hand the emits to the GUI thread
through the application's inbox (`ocu.qt.inbox`), so every signal here is emitted on the GUI
thread. (Emitting across threads, or asking `isSignalConnected` there, takes Qt's locks with
the GIL held; that deadlocked a CI run.)
"""

from __future__ import annotations

from dataclasses import dataclass

from PySide6.QtCore import QMetaMethod, QObject, QTimer, Signal
from PySide6.QtGui import QImage

from ocu.link.base import Link
from ocu.qt.inbox import gui_inbox
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
_EVERY_FRAME, _EVERY_VIDEO, _EVERY_COMMAND = range(3)


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

    def __init__(
        self, link: Link, parent: QObject | None = None, *, heartbeat: bool = True
    ) -> None:
        super().__init__(parent)
        self.setObjectName("ocu-qt-link")
        self.link = link
        profile = link.profile
        # A robot without cameras (a UR arm) keeps one idle slot: no frame ever comes. The
        # local cameras (ocu.video.capture) take the slots after the robot's.
        cameras = max(1, len(profile.link.camera_names), len(profile.cameras))
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
        self._inbox = gui_inbox()
        self._every = (
            QMetaMethod.fromSignal(self.telemetry_received),
            QMetaMethod.fromSignal(self.video_frame_received),
            QMetaMethod.fromSignal(self.command_sent),
        )
        # Read on the link's and the decoder's threads, set on the GUI thread.
        self._wants = [self.isSignalConnected(method) for method in self._every]
        link.subscribe(self._on_event)
        # The timer lives in the GUI thread: if that thread stalls, heartbeats stop and the
        # link zeroes any motion after its GUI-alive timeout.
        self._heartbeat = QTimer(self)
        self._heartbeat.setInterval(HEARTBEAT_PERIOD_MS)
        self._heartbeat.timeout.connect(self._beat)
        # False: another thread (the console's control thread) tells the link it is alive.
        self._beats_link = heartbeat
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
        # No Qt here (see ocu.qt.inbox): the GUI thread emits what is posted to it.
        post = self._inbox.post
        if isinstance(event, TelemetryFrame):
            if self._telemetry.put(0, event):
                post(self.telemetry_ready.emit)
            if self._wants[_EVERY_FRAME]:
                post(self.telemetry_received.emit, event)
        elif isinstance(event, VideoFrame):
            self.decoder.submit(event)
        elif isinstance(event, StatusFrame):
            post(self.status_received.emit, event)
        elif isinstance(event, ScanFrame):
            post(self.scan_received.emit, event)
        elif isinstance(event, ExtensionChanged):
            post(self.extension_changed.emit, event.active, event.reason)
        elif isinstance(event, LinkStateChanged):
            post(self.link_state_changed.emit, event.state, event.reason)
        elif isinstance(event, LinkStats):
            post(self.stats_updated.emit, event)
        elif isinstance(event, SafetyEvent):
            post(self.safety_event.emit, event.message)
        elif isinstance(event, CommandSent) and self._wants[_EVERY_COMMAND]:
            post(self.command_sent.emit, event)

    def _on_decoded(self, decoded: DecodedFrame) -> None:
        # Decoder thread: QImage (unlike QPixmap) may be built outside the GUI thread.
        frame = DecodedVideoFrame(decoded.source, wrap_pixels(decoded), decoded)
        if self.frames.put(decoded.slot, frame):
            self._inbox.post(self.video_frame_ready.emit, decoded.slot)
        if self._wants[_EVERY_VIDEO]:
            self._inbox.post(self.video_frame_received.emit, frame)

    def _on_corrupt(self, frame: VideoFrame, slot: int) -> None:
        # Counted by the decoder (decoder.stats); the viewer keeps showing the last good frame.
        if self._wants[_EVERY_VIDEO]:
            self._inbox.post(self.video_frame_received.emit, DecodedVideoFrame(frame, QImage()))

    # ---- who wants every frame (the GUI thread) ---------------------------------------------

    def connectNotify(self, signal: QMetaMethod) -> None:
        """Something connected: one of the every-frame signals is wanted from now on."""
        for index, method in enumerate(self._every):
            if signal == method:
                self._wants[index] = True
        super().connectNotify(signal)

    def _beat(self) -> None:
        # The GUI thread's heartbeat; it also forgets every-frame signals nobody listens to
        # any more (isSignalConnected on this thread only: see ocu.qt.inbox).
        if self._beats_link:
            self.link.heartbeat()
        for index, method in enumerate(self._every):
            if self._wants[index] and not self.isSignalConnected(method):
                self._wants[index] = False
