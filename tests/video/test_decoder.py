"""The decoder thread: newest JPEG per camera, corrupt frames counted, clean stop."""

from __future__ import annotations

import threading

import cv2
import numpy as np

from ocu.profile import RobotProfile
from ocu.records import VideoFrame
from ocu.video.correction import CorrectionSettings, Corrector
from ocu.video.decoder import DecodedFrame, VideoDecoder, decode_jpeg


def jpeg(width: int = 64, height: int = 48, level: int = 100) -> bytes:
    image = np.full((height, width, 3), level, np.uint8)
    ok, data = cv2.imencode(".jpg", image)
    assert ok
    return data.tobytes()


def frame(data: bytes, camera: int | None, at: float) -> VideoFrame:
    return VideoFrame(data, camera, at, 0.0)


class Collector:
    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.decoded: list[DecodedFrame] = []
        self.corrupt: list[int] = []

    def on_decoded(self, decoded: DecodedFrame) -> None:
        with self.cond:
            self.decoded.append(decoded)
            self.cond.notify_all()

    def on_corrupt(self, _: VideoFrame, slot: int) -> None:
        with self.cond:
            self.corrupt.append(slot)
            self.cond.notify_all()

    def wait(self, decoded: int, corrupt: int = 0) -> bool:
        with self.cond:
            return self.cond.wait_for(
                lambda: len(self.decoded) >= decoded and len(self.corrupt) >= corrupt, 5.0
            )


def make(profile: RobotProfile, collector: Collector) -> VideoDecoder:
    corrector = Corrector(profile.cameras)
    for camera in range(len(profile.cameras)):
        corrector.set_settings(camera, CorrectionSettings())
    return VideoDecoder(4, corrector, collector.on_decoded, collector.on_corrupt)


def test_stale_frames_are_skipped_not_decoded(profile: RobotProfile) -> None:
    collector = Collector()
    decoder = make(profile, collector)
    for k in range(5):
        decoder.submit(frame(jpeg(level=10 * k), 1, at=float(k)))
    decoder.submit(frame(jpeg(width=80), None, at=9.0))  # vendor frame: camera unknown
    decoder.start()
    try:
        assert collector.wait(decoded=2)
    finally:
        decoder.stop()
    by_slot = {d.slot: d for d in collector.decoded}
    assert by_slot[1].source.received_at == 4.0
    assert by_slot[0].width == 80
    assert by_slot[1].pixels.shape == (48, 64, 4)  # BGRA, QImage.Format_RGB32 order
    assert by_slot[1].pixels[0, 0, 3] == 255
    assert decoder.stats(1).skipped == 4
    assert decoder.stats(1).decoded == 1


def test_corrupt_jpegs_are_counted(profile: RobotProfile) -> None:
    collector = Collector()
    decoder = make(profile, collector)
    decoder.start()
    try:
        garbage = b"\xff\xd8\xff" + bytes(range(200)) + b"\xff\xd9"
        decoder.submit(frame(garbage, 2, at=1.0))
        assert collector.wait(decoded=0, corrupt=1)
        decoder.submit(frame(jpeg(), 2, at=2.0))
        assert collector.wait(decoded=1, corrupt=1)
    finally:
        decoder.stop()
        decoder.stop()
    assert decoder.stats(2).corrupt == 1
    assert decoder.stats(2).decoded == 1
    assert decode_jpeg(b"") is None
    assert not decoder.submit(frame(jpeg(), 7, at=3.0))  # no such camera
