"""The video decoder thread: newest JPEG per camera in, corrected BGRA pixels out.

Decoding costs what the picture is shown at, not what was sent: the view tells the decoder
each camera's cell size (`set_display`); a JPEG is decoded at 1/2, 1/4 or 1/8 of its size with
libjpeg's DCT scaling (`cv2.IMREAD_REDUCED_COLOR_*`) when the cell shows no more than that,
then shrunk (bilinear, less than 2x) to exactly the size the cell shows, so the correction
runs on the smaller image and the view paints it 1:1. A camera no cell shows is not decoded
at all (counted as `hidden`). Without a display set, a camera is decoded at full size.

The link loop hands every complete JPEG to submit(), which only stores it in the camera's
one-slot mailbox. The "ocu-video" thread takes the newest JPEG of each camera (oldest
arrival first), decodes it
with OpenCV (which releases the GIL), applies the camera's correction and converts it to
BGRA, the byte order of QImage.Format_RGB32 on little-endian machines, so painting needs no
conversion. JPEGs replaced before the thread got to them are never decoded: when decoding
falls behind, the stale frames are dropped, not queued. Decoding stays out of the link loop
so the RCP tick, the e-stop repeats and the watchdogs never wait for an image.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import cast

import cv2
import numpy as np

from ocu.records import VideoFrame
from ocu.video.capture import CapturedFrame
from ocu.video.correction import CorrectionTimings, Corrector, Pixels
from ocu.video.slot import LatestFrames

log = logging.getLogger("ocu.video")

STOP_TIMEOUT_S = 2.0
IDLE_WAIT_S = 0.5
# libjpeg's DCT scaling: decode at 1/factor of the size, largest factor first.
REDUCTIONS = (
    (8, cv2.IMREAD_REDUCED_COLOR_8),
    (4, cv2.IMREAD_REDUCED_COLOR_4),
    (2, cv2.IMREAD_REDUCED_COLOR_2),
)
# Start-of-frame markers (baseline, extended, progressive, ...): they carry the size.
_SOF_MARKERS = frozenset({0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE})
# Markers without a length field.
_STANDALONE_MARKERS = frozenset({0x01, *range(0xD0, 0xD8)})
# Size of a cell the decoder must fill, in device pixels; None: the camera is not shown.
CellSize = tuple[int, int] | None


def jpeg_size(jpeg: bytes) -> tuple[int, int] | None:
    """Width and height from a JPEG's start-of-frame header, None if there is none."""
    if len(jpeg) < 4 or jpeg[0] != 0xFF or jpeg[1] != 0xD8:
        return None
    offset = 2
    end = len(jpeg)
    while offset + 4 <= end:
        if jpeg[offset] != 0xFF:
            return None
        marker = jpeg[offset + 1]
        if marker == 0xFF:  # fill byte
            offset += 1
            continue
        if marker in _STANDALONE_MARKERS:
            offset += 2
            continue
        length = (jpeg[offset + 2] << 8) | jpeg[offset + 3]
        if marker in _SOF_MARKERS:
            if offset + 9 > end:
                return None
            height = (jpeg[offset + 5] << 8) | jpeg[offset + 6]
            width = (jpeg[offset + 7] << 8) | jpeg[offset + 8]
            return (width, height) if width and height else None
        if marker == 0xDA or length < 2:  # start of scan: no size before it
            return None
        offset += 2 + length
    return None


@dataclass(frozen=True)
class DecodePlan:
    """How to decode a frame for its cell: DCT reduction, then a resize to `size_px`."""

    reduction: int = 1
    # The size the picture is shown at (None: as decoded, for a caller without a view).
    size_px: tuple[int, int] | None = None


FULL_SIZE = DecodePlan()


def plan_for(image_px: tuple[int, int], cell_px: tuple[int, int]) -> DecodePlan:
    """Decode no larger than the cell shows the image (never enlarged): the largest DCT
    reduction whose result still covers that size, then an area resize down to it."""
    width, height = image_px
    cell_width, cell_height = cell_px
    if width <= 0 or height <= 0 or cell_width <= 0 or cell_height <= 0:
        return FULL_SIZE
    scale = min(cell_width / width, cell_height / height, 1.0)  # the image's size on screen
    shown = (max(1, round(width * scale)), max(1, round(height * scale)))
    reduction = 1
    for factor, _ in REDUCTIONS:
        if factor * scale <= 1.0 and width % factor == 0 and height % factor == 0:
            reduction = factor
            break
    return DecodePlan(reduction, shown)


@dataclass(frozen=True)
class DecodedFrame:
    """A decoded, corrected frame: BGRA pixels (never written again) and how long it took."""

    source: VideoFrame
    slot: int
    pixels: Pixels
    decode_ms: float
    correction: CorrectionTimings
    decoded_at: float
    # Decoded at 1/reduction of the JPEG's size (libjpeg DCT scaling; 1 = full size), then
    # resized to the size it is shown at.
    reduction: int = 1
    # The JPEG's own size (the pixels may be smaller).
    source_px: tuple[int, int] = (0, 0)

    @property
    def width(self) -> int:
        """Width in pixels."""
        return int(self.pixels.shape[1])

    @property
    def height(self) -> int:
        """Height in pixels."""
        return int(self.pixels.shape[0])


@dataclass(frozen=True)
class DecoderStats:
    """Counters of one camera's decoding."""

    submitted: int = 0
    skipped: int = 0
    decoded: int = 0
    corrupt: int = 0
    last_decode_ms: float = 0.0
    last_correction_ms: float = 0.0
    # Frames not decoded because no cell showed the camera.
    hidden: int = 0
    # The DCT reduction of the last decoded frame (1 = full size).
    last_reduction: int = 1
    # The size the last frame was decoded to (width, height).
    last_size_px: tuple[int, int] = (0, 0)


def frame_size(frame: VideoFrame) -> tuple[int, int] | None:
    """Width and height of a frame: its JPEG's header, or a local camera's pixels."""
    if isinstance(frame, CapturedFrame):
        pixels = frame.pixels
        return None if pixels is None else (int(pixels.shape[1]), int(pixels.shape[0]))
    return jpeg_size(frame.jpeg)


def set_opencv_threads(threads: int) -> None:
    """OpenCV's worker threads, process-wide: 1 runs every call on the caller's thread, 0
    keeps OpenCV's default (one per core).

    Measured here (bench/bench_console_video.py): a frame's remap and colour table split
    across workers cost more CPU in hand-overs than they save, and the decoder is one thread.
    """
    cv2.setNumThreads(-1 if threads == 0 else (0 if threads == 1 else threads))


def decode_jpeg(jpeg: bytes, reduction: int = 1) -> Pixels | None:
    """BGR pixels of a JPEG (at 1/reduction of its size), or None when it cannot be decoded."""
    if not jpeg:
        return None
    flag = next((f for factor, f in REDUCTIONS if factor == reduction), cv2.IMREAD_COLOR)
    image = cv2.imdecode(np.frombuffer(jpeg, dtype=np.uint8), flag)
    if image is None or image.ndim != 3 or image.shape[2] != 3:
        return None
    return cast(Pixels, image)


class _Unset:
    """No display size was set for a camera: decode it whole."""


_UNSET = _Unset()


class VideoDecoder:
    """Decodes the newest JPEG of each camera in a named thread ("ocu-video").

    One thread, not one per camera: measured on two cores, parallel decoders lose more to
    GIL hand-overs than they gain (arrival-to-paint p99 roughly doubled).
    """

    def __init__(
        self,
        slots: int,
        corrector: Corrector,
        on_decoded: Callable[[DecodedFrame], None],
        on_corrupt: Callable[[VideoFrame, int], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
        *,
        opencv_threads: int | None = None,
    ) -> None:
        self.corrector = corrector
        self.opencv_threads = opencv_threads
        self.on_decoded = on_decoded
        self.on_corrupt = on_corrupt
        self.clock = clock
        self._inbox: LatestFrames[VideoFrame] = LatestFrames(slots)
        self._lock = threading.Lock()
        self._decoded = [0] * slots
        self._corrupt = [0] * slots
        self._decode_ms = [0.0] * slots
        self._correction_ms = [0.0] * slots
        self._hidden = [0] * slots
        self._reduction = [1] * slots
        self._size = [(0, 0)] * slots
        # Unset (the default): decode at full size; None: not shown; a size: fill that cell.
        self._display: list[CellSize | _Unset] = [_UNSET] * slots
        self._thread: threading.Thread | None = None

    @property
    def slots(self) -> int:
        """Number of cameras."""
        return self._inbox.slots

    def slot_for(self, frame: VideoFrame) -> int:
        """The camera slot of a frame: its camera, or 0 for a vendor frame of unknown camera."""
        camera = frame.camera if frame.camera is not None else 0
        return camera if 0 <= camera < self.slots else -1

    def set_display(self, slot: int, cell_px: CellSize) -> None:
        """How large a camera is shown (device pixels), or None when no cell shows it."""
        if 0 <= slot < self.slots:
            with self._lock:
                self._display[slot] = cell_px

    def submit(self, frame: VideoFrame) -> bool:
        """Queue a JPEG for decoding, replacing an undecoded older one of the same camera."""
        slot = self.slot_for(frame)
        if slot < 0:
            return False
        self._inbox.put(slot, frame)
        return True

    def start(self) -> None:
        """Start the thread (once)."""
        if self._thread is not None or self._inbox.closed:
            return
        if self.opencv_threads is not None:
            set_opencv_threads(self.opencv_threads)
        self._thread = threading.Thread(target=self._run, name="ocu-video", daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = STOP_TIMEOUT_S) -> None:
        """Stop the thread and wait for it; idempotent."""
        self._inbox.close()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout_s)
            if thread.is_alive():
                log.error("video decoder did not stop within %.1f s", timeout_s)

    def stats(self, slot: int) -> DecoderStats:
        """Counters of one camera."""
        with self._lock:
            decoded = self._decoded[slot]
            corrupt = self._corrupt[slot]
            decode_ms = self._decode_ms[slot]
            correction_ms = self._correction_ms[slot]
            hidden = self._hidden[slot]
            reduction = self._reduction[slot]
            size = self._size[slot]
        return DecoderStats(
            submitted=self._inbox.put_count(slot),
            skipped=self._inbox.replaced(slot),
            decoded=decoded,
            corrupt=corrupt,
            last_decode_ms=decode_ms,
            last_correction_ms=correction_ms,
            hidden=hidden,
            last_reduction=reduction,
            last_size_px=size,
        )

    def plan(self, frame: VideoFrame, slot: int) -> DecodePlan | None:
        """How to decode a frame for its cell; None: no cell shows the camera."""
        with self._lock:
            display = self._display[slot]
        if display is None:
            return None
        if isinstance(display, _Unset):
            return FULL_SIZE
        size = frame_size(frame)
        return FULL_SIZE if size is None else plan_for(size, display)

    def decode_now(
        self,
        frame: VideoFrame,
        slot: int,
        plan: DecodePlan = FULL_SIZE,
        *,
        learn: bool = True,
    ) -> DecodedFrame | None:
        """Decode and correct one frame in the calling thread; None if it is corrupt.

        `learn=False` (a snapshot, off the decoder thread) leaves the counters and the
        camera's smoothed colour gains as they are.
        """
        start = time.perf_counter()
        if isinstance(frame, CapturedFrame):
            # A local camera's picture (ocu.video.capture): pixels already, never reduced.
            image, plan = frame.pixels, replace(plan, reduction=1)
        else:
            image = decode_jpeg(frame.jpeg, plan.reduction)
        if image is None:
            if learn:
                with self._lock:
                    self._corrupt[slot] += 1
            return None
        decoded_px = (int(image.shape[1]) * plan.reduction, int(image.shape[0]) * plan.reduction)
        if plan.size_px is not None and plan.size_px != (image.shape[1], image.shape[0]):
            # Less than 2x left after the DCT reduction: bilinear is enough (and five times
            # cheaper than area averaging at a fractional ratio, measured 0.08 vs 0.4 ms); a
            # local camera's pixels may be shrunk more: area averaging, no aliasing.
            shrink = decoded_px[0] > 2 * plan.size_px[0]
            interpolation = cv2.INTER_AREA if shrink else cv2.INTER_LINEAR
            image = cast(Pixels, cv2.resize(image, plan.size_px, interpolation=interpolation))
        decode_ms = (time.perf_counter() - start) * 1000.0
        image, timings = self.corrector.apply(slot, image, learn=learn)
        start = time.perf_counter()
        pixels = cast(Pixels, cv2.cvtColor(image, cv2.COLOR_BGR2BGRA))
        decode_ms += (time.perf_counter() - start) * 1000.0
        if learn:
            with self._lock:
                self._decoded[slot] += 1
                self._decode_ms[slot] = decode_ms
                self._correction_ms[slot] = timings.total_ms
                self._reduction[slot] = plan.reduction
                self._size[slot] = (int(pixels.shape[1]), int(pixels.shape[0]))
        return DecodedFrame(
            frame, slot, pixels, decode_ms, timings, self.clock(), plan.reduction, decoded_px
        )

    def _run(self) -> None:
        while not self._inbox.closed:
            if not self._inbox.wait_any(IDLE_WAIT_S):
                continue
            # Oldest arrival first; one at a time, so a newer frame that arrives meanwhile
            # still replaces the one waiting.
            while (taken := self._inbox.take_first(lambda f: f.received_at)) is not None:
                slot, frame = taken
                try:
                    plan = self.plan(frame, slot)
                    if plan is None:
                        with self._lock:
                            self._hidden[slot] += 1
                        continue
                    decoded = self.decode_now(frame, slot, plan)
                    if decoded is None:
                        if self.on_corrupt is not None:
                            self.on_corrupt(frame, slot)
                    else:
                        self.on_decoded(decoded)
                except Exception:
                    # One bad frame or a failing consumer must not end the video.
                    log.exception("video decoding failed on camera slot %d", slot)
