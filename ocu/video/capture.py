"""A camera on the OCU's own machine (a USB camera, a video file, a synthetic scene) as one
more video source of any robot, no Qt.

`ocu --camera /dev/video0` (or an index, `--camera 0`, or a video file's path) adds a camera
to the robot's: `with_camera` appends its `CameraSettings` to the profile's `cameras` (its
index is the next video slot) while `link.camera_names` stay the robot's own, so nothing of
it reaches the robot's protocol (the camera selector, the extension's stream requests).
`video_names` are the names the Video dock shows: the robot's cameras, then these.

`CameraCapture` reads a `FrameSource` (OpenCV's `cv2.VideoCapture` for a device or a file) on
a thread of its own ("ocu-camera-N"), never the GUI's or the control thread, and hands each
picture as a `CapturedFrame` (a `VideoFrame` carrying BGR pixels instead of a JPEG) to its sink:
the link adapter's decoder (ocu.qt.link), which corrects it, sizes it for its cell and hands it
to the Video dock as it does the robot's frames — snapshots, colour correction and
click-to-track work on it unchanged. A camera that cannot be opened is refused by name at
start; one that stops delivering shows NO SIGNAL with the time since its last frame (the
view's rule), and `status()` says why (a failed read, the end of a file).
"""

from __future__ import annotations

import logging
import math
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Protocol, cast

import cv2
import numpy as np
import numpy.typing as npt

from ocu.profile import CameraCalibration, CameraMount, CameraSettings, RobotProfile
from ocu.records import VideoFrame

log = logging.getLogger("ocu.video")

Pixels = npt.NDArray[np.uint8]
# Assumed for a camera nobody calibrated: a 70° horizontal field of view (a typical USB
# camera module's; seed 003's IMX291 module does not state its lens), no distortion.
DEFAULT_FOV_DEG = 70.0
DEFAULT_SIZE_PX = (640, 480)
# A file (or a synthetic source) plays at its own rate; this when it states none.
DEFAULT_FPS = 30.0
# A device read that fails is tried again after this long (the camera may come back).
RETRY_S = 0.1
STOP_TIMEOUT_S = 2.0


class CameraError(RuntimeError):
    """A camera that cannot be opened or read; the message names it."""


class FrameSource(Protocol):
    """Pictures one after the other; `read` blocks until the next one (None: none came)."""

    name: str
    # Seconds between pictures for a source that does not pace itself (a file, a scene);
    # None for a device, whose read waits for the next picture.
    period_s: float | None
    # Whether a failed read is the end (a file), not a camera that may deliver again.
    finite: bool

    def read(self) -> Pixels | None: ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class CapturedFrame(VideoFrame):
    """A picture of a local camera: BGR pixels in place of a JPEG (`jpeg` is empty)."""

    pixels: Pixels | None = field(default=None, compare=False, repr=False)


def camera_target(text: str) -> int | str:
    """`--camera`'s value: an index (`0`), a device path or a video file's path."""
    text = text.strip()
    if not text:
        raise CameraError("--camera: give a device (/dev/video0), an index (0) or a file")
    if text.isdigit():
        return int(text)
    return text


class OpenCvSource:
    """A device or a video file through OpenCV's `cv2.VideoCapture`."""

    def __init__(self, target: int | str) -> None:
        self.name = str(target)
        self.finite = False
        self.period_s: float | None = None
        if isinstance(target, str):
            path = Path(target)
            if not path.exists():
                raise CameraError(f"camera {target}: no such device or file")
            if not os.access(path, os.R_OK):
                raise CameraError(f"camera {target}: not readable (permissions: the video group?)")
            self.finite = not target.startswith("/dev/")
        self._capture = cv2.VideoCapture(target)
        if not self._capture.isOpened():
            self._capture.release()
            raise CameraError(
                f"camera {target}: OpenCV cannot open it (not a camera, busy, or a format it "
                "cannot read)"
            )
        if self.finite:
            fps = float(self._capture.get(cv2.CAP_PROP_FPS))
            self.period_s = 1.0 / (
                fps if math.isfinite(fps) and 1.0 <= fps <= 240.0 else DEFAULT_FPS
            )

    def read(self) -> Pixels | None:
        """The next picture (BGR), or None when the camera gave none."""
        ok, image = self._capture.read()
        if not ok or image is None or image.ndim != 3 or image.shape[2] != 3:
            return None
        return cast(Pixels, image)

    def close(self) -> None:
        """Release the device or file."""
        self._capture.release()


@dataclass(frozen=True)
class CaptureStatus:
    """What a capture did: pictures delivered, failed reads, and why it stopped (if it did)."""

    name: str
    frames: int
    failures: int
    last_frame_at: float | None
    stopped: str = ""

    def describe(self, now: float, no_signal_after_s: float) -> str:
        """One line for the view: 'camera /dev/video0: 812 frames' or why it delivers none."""
        text = f"camera {self.name}: {self.frames} frames"
        if self.stopped:
            return f"{text} · STOPPED: {self.stopped}"
        age = None if self.last_frame_at is None else now - self.last_frame_at
        if age is None or age > no_signal_after_s:
            since = "none yet" if age is None else f"none for {age:.1f} s"
            return f"{text} · NOT DELIVERING ({since}, {self.failures} failed reads)"
        return text


class CameraCapture:
    """Reads one source on its own thread and hands each picture to the sink (if any)."""

    def __init__(
        self,
        source: FrameSource,
        slot: int,
        *,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.source = source
        self.slot = slot
        self.clock = clock
        self._lock = threading.Lock()
        self._sink: Callable[[VideoFrame], object] | None = None
        self._frames = 0
        self._failures = 0
        self._last_at: float | None = None
        self._stopped = ""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def name(self) -> str:
        """The source's name (the device, the file)."""
        return self.source.name

    def set_sink(self, sink: Callable[[VideoFrame], object] | None) -> None:
        """Where pictures go from now on (None: nowhere; they are still counted)."""
        with self._lock:
            self._sink = sink

    def start(self) -> None:
        """Start the thread (once)."""
        if self._thread is not None:
            return
        self._thread = threading.Thread(
            target=self._run, name=f"ocu-camera-{self.slot}", daemon=True
        )
        self._thread.start()

    def stop(self, timeout_s: float = STOP_TIMEOUT_S) -> None:
        """Stop the thread and release the source; idempotent."""
        self._stop.set()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout_s)
            if thread.is_alive():
                log.error("camera %s did not stop within %.1f s", self.name, timeout_s)
                return  # still reading: it releases nothing under a blocked read
        self.source.close()

    def status(self) -> CaptureStatus:
        """The counters now."""
        with self._lock:
            return CaptureStatus(
                self.name, self._frames, self._failures, self._last_at, self._stopped
            )

    def _run(self) -> None:
        period = self.source.period_s
        due = self.clock()
        try:
            while not self._stop.is_set():
                if period is not None:
                    wait = due - self.clock()
                    if wait > 0 and self._stop.wait(wait):
                        break
                    due = max(due + period, self.clock() - period)
                pixels = self.source.read()
                if pixels is None:
                    with self._lock:
                        self._failures += 1
                    if self.source.finite:
                        self._end("end of the file")
                        return
                    self._stop.wait(RETRY_S)
                    continue
                now = self.clock()
                frame = CapturedFrame(b"", self.slot, now, time.time(), pixels=pixels)
                with self._lock:
                    self._frames += 1
                    self._last_at = now
                    sink = self._sink
                if sink is not None:
                    sink(frame)
        except Exception as err:  # a source that raises must not pass for a live camera
            log.exception("camera %s failed", self.name)
            self._end(f"{type(err).__name__}: {err}")

    def _end(self, reason: str) -> None:
        with self._lock:
            self._stopped = reason
        log.warning("camera %s stopped delivering: %s", self.name, reason)


def default_calibration(size_px: tuple[int, int] = DEFAULT_SIZE_PX) -> CameraCalibration:
    """A pinhole camera of DEFAULT_FOV_DEG across, no distortion (assumed; docs/xarm.md)."""
    width, height = size_px
    focal = width / 2.0 / math.tan(math.radians(DEFAULT_FOV_DEG) / 2.0)
    return CameraCalibration(
        model="standard",
        size_px=size_px,
        focal_px=(focal, focal),
        centre_px=(width / 2.0, height / 2.0),
        distortion=(0.0, 0.0, 0.0, 0.0, 0.0),
        balance=0.0,
    )


def with_camera(
    profile: RobotProfile,
    name: str,
    *,
    mount: CameraMount | None = None,
    calibration: CameraCalibration | None = None,
) -> RobotProfile:
    """The profile with one more camera (the next video slot); the robot's own camera names,
    which its protocol speaks, are left as they are."""
    taken = {camera.name for camera in profile.cameras} | set(profile.link.camera_names)
    unique, number = name, 2
    while unique in taken:
        unique, number = f"{name} {number}", number + 1
    camera = CameraSettings(
        name=unique,
        index=len(profile.cameras),
        calibration=calibration if calibration is not None else default_calibration(),
        mount=mount,
    )
    return replace(profile, cameras=(*profile.cameras, camera))


def video_names(profile: RobotProfile) -> tuple[str, ...]:
    """The Video dock's cameras: the robot's, then the local ones `with_camera` added."""
    robot = profile.link.camera_names
    return robot + tuple(camera.name for camera in profile.cameras[len(robot) :])


def is_local(profile: RobotProfile, camera: int) -> bool:
    """Whether a video slot is a local camera (not one the robot streams)."""
    return len(profile.link.camera_names) <= camera < len(profile.cameras)
