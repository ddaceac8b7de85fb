"""The link core in a QThread: events become Qt signals; JPEGs decode off the GUI thread.

Video takes its own path so that a slow GUI drops stale frames instead of queueing them: the
loop hands each JPEG to the "ocu-video" decoder thread (newest per camera wins), which puts
the decoded QImage into a one-slot mailbox per camera and emits `video_frame_ready(camera)`
only when that mailbox was empty. At most one such signal per camera is ever queued; the
GUI takes the newest image with `take_video_frame(camera)`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from PySide6.QtCore import QMetaMethod, QObject, QThread, QTimer, Signal, SignalInstance
from PySide6.QtGui import QImage

from ocu.control.commands import Command
from ocu.link.core import (
    LinkCore,
    LinkListener,
    LinkState,
    StatusFrame,
    TelemetryFrame,
    VideoFrame,
)
from ocu.link.stats import LinkStats
from ocu.profile import RobotProfile
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


class VideoOwner(Protocol):
    """A QObject with the two video signals of LinkThread (the link or a replay)."""

    @property
    def video_frame_ready(self) -> SignalInstance: ...

    @property
    def video_frame_received(self) -> SignalInstance: ...

    def isSignalConnected(self, signal: QMetaMethod) -> bool: ...


class VideoPipeline:
    """Decoder thread, per-camera correction and latest-frame slots, feeding an owner's signals.

    `video_frame_ready(camera)` fires when a camera's slot goes from empty to full, so at most
    one is queued per camera; the GUI takes the newest image with `take(camera)`.
    `video_frame_received` (one signal per frame, which would queue) fires only while
    something is connected to it.
    """

    def __init__(self, profile: RobotProfile, owner: VideoOwner) -> None:
        cameras = len(profile.link.camera_names)
        self.corrector = Corrector(profile.cameras)
        self.frames: LatestFrames[DecodedVideoFrame] = LatestFrames(cameras)
        self.decoder = VideoDecoder(cameras, self.corrector, self._on_decoded, self._on_corrupt)
        self._owner = owner
        self._legacy_signal = QMetaMethod.fromSignal(owner.video_frame_received)

    def take(self, camera: int) -> DecodedVideoFrame | None:
        """The newest decoded frame of a camera not yet taken, or None (any thread)."""
        return self.frames.take(camera)

    def _on_decoded(self, decoded: DecodedFrame) -> None:
        # Decoder thread: QImage (unlike QPixmap) may be built outside the GUI thread.
        frame = DecodedVideoFrame(decoded.source, wrap_pixels(decoded), decoded)
        if self.frames.put(decoded.slot, frame):
            self._owner.video_frame_ready.emit(decoded.slot)
        if self._owner.isSignalConnected(self._legacy_signal):
            self._owner.video_frame_received.emit(frame)

    def _on_corrupt(self, frame: VideoFrame, slot: int) -> None:
        # Counted by the decoder (decoder.stats); the viewer keeps showing the last good frame.
        if self._owner.isSignalConnected(self._legacy_signal):
            self._owner.video_frame_received.emit(DecodedVideoFrame(frame, QImage()))


class SignalOwner(Protocol):
    """What a SignalForwarder emits into: a LinkThread, or a replay with the same signals."""

    @property
    def telemetry_received(self) -> SignalInstance: ...

    @property
    def telemetry_ready(self) -> SignalInstance: ...

    def isSignalConnected(self, signal: QMetaMethod) -> bool: ...

    @property
    def status_received(self) -> SignalInstance: ...

    @property
    def extension_changed(self) -> SignalInstance: ...

    @property
    def link_state_changed(self) -> SignalInstance: ...

    @property
    def stats_updated(self) -> SignalInstance: ...

    @property
    def safety_event(self) -> SignalInstance: ...

    @property
    def decoder(self) -> VideoDecoder: ...


class SignalForwarder(LinkListener):
    """Forwards link callbacks (loop or player thread) to the owner's signals (queued).

    Telemetry goes through a one-frame mailbox, as video does: `telemetry_ready` fires only
    when the mailbox goes from empty to full, so a robot flooding the link with telemetry
    queues at most one signal, never a backlog in front of the operator's key presses. The
    GUI takes the newest frame with `take_telemetry()` at the pace it can show.
    `telemetry_received` (every frame) fires only while something is connected to it.
    """

    def __init__(self, owner: SignalOwner) -> None:
        self.owner = owner
        self._telemetry: LatestFrames[TelemetryFrame] = LatestFrames(1)
        self._every_frame = QMetaMethod.fromSignal(owner.telemetry_received)

    def take_telemetry(self) -> TelemetryFrame | None:
        """The newest telemetry frame not yet taken (any thread)."""
        return self._telemetry.take(0)

    def telemetry_received(self, frame: TelemetryFrame) -> None:
        if self._telemetry.put(0, frame):
            self.owner.telemetry_ready.emit()
        if self.owner.isSignalConnected(self._every_frame):
            self.owner.telemetry_received.emit(frame)

    def video_frame_received(self, frame: VideoFrame) -> None:
        self.owner.decoder.submit(frame)

    def status_received(self, frame: StatusFrame) -> None:
        self.owner.status_received.emit(frame)

    def extension_changed(self, active: bool, reason: str) -> None:
        self.owner.extension_changed.emit(active, reason)

    def link_state_changed(self, state: LinkState, reason: str) -> None:
        self.owner.link_state_changed.emit(state, reason)

    def stats_updated(self, stats: LinkStats) -> None:
        self.owner.stats_updated.emit(stats)

    def safety_event(self, message: str) -> None:
        self.owner.safety_event.emit(message)


class LinkThread(QThread):
    """Runs a LinkCore's loop; the GUI thread proves it is alive with a heartbeat timer."""

    # Every telemetry frame: emitted only while something is connected (tests, tools).
    # Views use telemetry_ready and take_telemetry(), which never queue a backlog.
    telemetry_received = Signal(object)
    telemetry_ready = Signal()
    # One signal per decoded frame with its image: it queues when the GUI is slow, so it is
    # emitted only while something is connected (recording, tests). Viewers use
    # video_frame_ready and take_video_frame instead.
    video_frame_received = Signal(object)
    video_frame_ready = Signal(int)
    status_received = Signal(object)
    extension_changed = Signal(bool, str)
    link_state_changed = Signal(object, str)
    stats_updated = Signal(object)
    safety_event = Signal(str)

    def __init__(self, core: LinkCore, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("ocu-link")
        self.core = core
        self.video = VideoPipeline(core.profile, self)
        self.corrector, self.frames, self.decoder = (
            self.video.corrector,
            self.video.frames,
            self.video.decoder,
        )
        self.forwarder = SignalForwarder(self)
        core.listener = self.forwarder
        # The timer lives in the GUI thread: if that thread stalls, heartbeats stop and the
        # core zeroes any motion after gui_alive_timeout_s.
        self._heartbeat = QTimer(self)
        self._heartbeat.setInterval(HEARTBEAT_PERIOD_MS)
        self._heartbeat.timeout.connect(core.heartbeat)
        self._shut = False

    def start_link(self) -> None:
        """Start the loop thread, the video decoder and the heartbeat."""
        self._heartbeat.start()
        self.decoder.start()
        self.start()

    def take_video_frame(self, camera: int) -> DecodedVideoFrame | None:
        """The newest decoded frame of a camera not yet taken, or None (any thread)."""
        return self.video.take(camera)

    def take_telemetry(self) -> TelemetryFrame | None:
        """The newest telemetry frame not yet taken, or None (any thread)."""
        return self.forwarder.take_telemetry()

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
        self.decoder.stop(timeout_s)
        self.wait(int(timeout_s * 1000))
