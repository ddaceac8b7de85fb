"""The video decoder thread: newest JPEG per camera in, corrected BGRA pixels out.

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
from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np

from ocu.records import VideoFrame
from ocu.video.correction import CorrectionTimings, Corrector, Pixels
from ocu.video.slot import LatestFrames

log = logging.getLogger("ocu.video")

STOP_TIMEOUT_S = 2.0
IDLE_WAIT_S = 0.5


@dataclass(frozen=True)
class DecodedFrame:
    """A decoded, corrected frame: BGRA pixels (never written again) and how long it took."""

    source: VideoFrame
    slot: int
    pixels: Pixels
    decode_ms: float
    correction: CorrectionTimings
    decoded_at: float

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


def decode_jpeg(jpeg: bytes) -> Pixels | None:
    """BGR pixels of a JPEG, or None when OpenCV cannot decode it."""
    if not jpeg:
        return None
    image = cv2.imdecode(np.frombuffer(jpeg, dtype=np.uint8), cv2.IMREAD_COLOR)
    if image is None or image.ndim != 3 or image.shape[2] != 3:
        return None
    return cast(Pixels, image)


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
    ) -> None:
        self.corrector = corrector
        self.on_decoded = on_decoded
        self.on_corrupt = on_corrupt
        self.clock = clock
        self._inbox: LatestFrames[VideoFrame] = LatestFrames(slots)
        self._lock = threading.Lock()
        self._decoded = [0] * slots
        self._corrupt = [0] * slots
        self._decode_ms = [0.0] * slots
        self._correction_ms = [0.0] * slots
        self._thread: threading.Thread | None = None

    @property
    def slots(self) -> int:
        """Number of cameras."""
        return self._inbox.slots

    def slot_for(self, frame: VideoFrame) -> int:
        """The camera slot of a frame: its camera, or 0 for a vendor frame of unknown camera."""
        camera = frame.camera if frame.camera is not None else 0
        return camera if 0 <= camera < self.slots else -1

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
        return DecoderStats(
            submitted=self._inbox.put_count(slot),
            skipped=self._inbox.replaced(slot),
            decoded=decoded,
            corrupt=corrupt,
            last_decode_ms=decode_ms,
            last_correction_ms=correction_ms,
        )

    def decode_now(self, frame: VideoFrame, slot: int) -> DecodedFrame | None:
        """Decode and correct one frame in the calling thread; None if it is corrupt."""
        start = time.perf_counter()
        image = decode_jpeg(frame.jpeg)
        decode_ms = (time.perf_counter() - start) * 1000.0
        if image is None:
            with self._lock:
                self._corrupt[slot] += 1
            return None
        image, timings = self.corrector.apply(slot, image)
        start = time.perf_counter()
        pixels = cast(Pixels, cv2.cvtColor(image, cv2.COLOR_BGR2BGRA))
        decode_ms += (time.perf_counter() - start) * 1000.0
        with self._lock:
            self._decoded[slot] += 1
            self._decode_ms[slot] = decode_ms
            self._correction_ms[slot] = timings.total_ms
        return DecodedFrame(frame, slot, pixels, decode_ms, timings, self.clock())

    def _run(self) -> None:
        while not self._inbox.closed:
            if not self._inbox.wait_any(IDLE_WAIT_S):
                continue
            # Oldest arrival first; one at a time, so a newer frame that arrives meanwhile
            # still replaces the one waiting.
            while (taken := self._inbox.take_first(lambda f: f.received_at)) is not None:
                slot, frame = taken
                try:
                    decoded = self.decode_now(frame, slot)
                    if decoded is None:
                        if self.on_corrupt is not None:
                            self.on_corrupt(frame, slot)
                    else:
                        self.on_decoded(decoded)
                except Exception:
                    # One bad frame or a failing consumer must not end the video.
                    log.exception("video decoding failed on camera slot %d", slot)
