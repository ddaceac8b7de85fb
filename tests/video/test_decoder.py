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


# ---- decoding at the size a cell shows --------------------------------------------------------


def test_jpeg_size_is_read_from_the_frame_header() -> None:
    from ocu.video.decoder import jpeg_size

    assert jpeg_size(jpeg(640, 480)) == (640, 480)
    assert jpeg_size(jpeg(1280, 720)) == (1280, 720)
    image = np.zeros((90, 160, 3), np.uint8)
    ok, progressive = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_PROGRESSIVE, 1])
    assert ok
    assert jpeg_size(progressive.tobytes()) == (160, 90)
    assert jpeg_size(b"") is None
    assert jpeg_size(b"\xff\xd8\xff\xda\x00\x02") is None  # scan before any frame header
    assert jpeg_size(jpeg(64, 48)[:8]) is None  # cut short
    assert jpeg_size(b"not a jpeg at all") is None


def test_the_plan_decodes_no_more_than_the_cell_shows() -> None:
    from ocu.video.decoder import FULL_SIZE, DecodePlan, plan_for

    # A 2x2 grid cell of 219x164: 1/2 by the DCT (320x240), then down to 219x164.
    assert plan_for((640, 480), (440, 164)) == DecodePlan(2, (219, 164))
    # Exactly half: the DCT alone does it.
    assert plan_for((640, 480), (320, 240)) == DecodePlan(2, (320, 240))
    # HD in a small cell: 1/4.
    assert plan_for((1280, 720), (292, 164)) == DecodePlan(4, (292, 164))
    # Never enlarged: a big cell gets the picture as sent.
    assert plan_for((640, 480), (1600, 1000)) == DecodePlan(1, (640, 480))
    # A size the DCT cannot divide is only resized.
    assert plan_for((641, 481), (320, 240)).reduction == 1
    assert plan_for((0, 0), (100, 100)) == FULL_SIZE


def test_hidden_cameras_are_not_decoded_and_shown_ones_come_at_the_cell_size(
    profile: RobotProfile,
) -> None:
    collector = Collector()
    decoder = make(profile, collector)
    decoder.set_display(0, (219, 164))
    decoder.set_display(1, None)  # no cell shows camera 1
    decoder.start()
    try:
        decoder.submit(frame(jpeg(640, 480), 1, at=1.0))
        decoder.submit(frame(jpeg(640, 480), 0, at=2.0))
        decoder.submit(frame(jpeg(640, 480), 2, at=3.0))  # never told: decoded whole
        assert collector.wait(decoded=2)
    finally:
        decoder.stop()
    by_slot = {d.slot: d for d in collector.decoded}
    assert set(by_slot) == {0, 2}
    assert (by_slot[0].width, by_slot[0].height) == (219, 164)
    assert by_slot[0].reduction == 2
    assert by_slot[0].source_px == (640, 480)
    assert (by_slot[2].width, by_slot[2].height) == (640, 480)
    assert decoder.stats(1).hidden == 1
    assert decoder.stats(1).decoded == 0
    assert decoder.stats(0).last_size_px == (219, 164)
