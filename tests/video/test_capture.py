"""Local cameras (ocu.video.capture), no Qt: a video file read on its own thread as a camera,
pictures handed to the decoder as the robot's are, its end shown as an end, a camera that
cannot be opened named, the profile's extra camera kept out of the robot's protocol."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from ocu.profile import load_profile
from ocu.records import VideoFrame
from ocu.video.capture import (
    CameraCapture,
    CameraError,
    CapturedFrame,
    OpenCvSource,
    camera_target,
    is_local,
    video_names,
    with_camera,
)
from ocu.video.correction import Corrector
from ocu.video.decoder import DecodedFrame, VideoDecoder

DEADLINE_S = 10.0


def wait_for(check: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + DEADLINE_S
    pause = threading.Event()
    while not check():
        if time.monotonic() > deadline:
            raise AssertionError(f"not {what} within {DEADLINE_S} s")
        pause.wait(0.005)


def clip(path: Path, frames: int = 10, fps: float = 50.0) -> Path:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), fps, (160, 120))
    assert writer.isOpened()
    for index in range(frames):
        image = np.full((120, 160, 3), 100, np.uint8)
        cv2.circle(image, (20 + 10 * index, 60), 10, (40, 40, 210), -1)
        writer.write(image)
    writer.release()
    return path


def test_a_video_file_plays_on_its_own_thread_at_its_rate_then_ends(tmp_path: Path) -> None:
    source = OpenCvSource(str(clip(tmp_path / "clip.avi")))
    assert source.finite
    assert source.period_s == pytest.approx(0.02)
    capture = CameraCapture(source, 2)
    frames: list[tuple[VideoFrame, str]] = []
    capture.set_sink(lambda frame: frames.append((frame, threading.current_thread().name)))
    capture.start()
    try:
        wait_for(lambda: capture.status().stopped != "", "the end of the file")
    finally:
        capture.stop()
    assert len(frames) == 10
    assert {name for _, name in frames} == {"ocu-camera-2"}
    first = frames[0][0]
    assert isinstance(first, CapturedFrame)
    assert first.camera == 2
    assert first.pixels is not None
    assert first.pixels.shape == (120, 160, 3)
    spacing = frames[-1][0].received_at - frames[0][0].received_at
    assert spacing >= 9 * 0.02 * 0.9  # paced at the file's 50 fps, not as fast as it reads
    status = capture.status()
    assert status.frames == 10
    assert status.stopped == "end of the file"
    text = status.describe(time.monotonic(), 1.0)
    assert "STOPPED: end of the file" in text


def test_a_camera_that_stops_delivering_is_not_passed_off_as_live() -> None:
    class Stalled:
        name = "/dev/video7"
        period_s: float | None = None
        finite = False

        def __init__(self) -> None:
            self.reads = 0

        def read(self) -> np.ndarray | None:
            self.reads += 1
            if self.reads <= 3:
                return np.zeros((4, 4, 3), np.uint8)
            threading.Event().wait(0.01)
            return None  # unplugged: every read fails

        def close(self) -> None:
            pass

    source = Stalled()
    capture = CameraCapture(source, 0)
    capture.start()
    try:
        wait_for(lambda: capture.status().failures >= 3, "failed reads counted")
    finally:
        capture.stop()
    status = capture.status()
    assert status.frames == 3
    assert status.last_frame_at is not None
    live = status.describe(status.last_frame_at + 0.1, 1.0)
    assert "NOT DELIVERING" not in live
    stale = status.describe(status.last_frame_at + 2.5, 1.0)
    assert "NOT DELIVERING (none for 2.5 s" in stale
    assert "/dev/video7" in stale


def test_pictures_go_through_the_decoder_as_the_robots_frames(tmp_path: Path) -> None:
    profile = with_camera(load_profile(None), "usb")
    local = len(profile.link.camera_names)
    decoded: list[DecodedFrame] = []
    decoder = VideoDecoder(len(profile.cameras), Corrector(profile.cameras), decoded.append)
    decoder.set_display(local, (80, 60))  # its cell shows it at half size
    decoder.start()
    capture = CameraCapture(OpenCvSource(str(clip(tmp_path / "c.avi"))), local)
    capture.set_sink(decoder.submit)
    capture.start()
    try:
        wait_for(lambda: bool(decoded), "a decoded picture")
    finally:
        capture.stop()
        decoder.stop()
    frame = decoded[0]
    assert frame.slot == local
    assert (frame.width, frame.height) == (80, 60)  # sized for its cell
    assert frame.source_px == (160, 120)
    assert frame.pixels.shape[2] == 4  # BGRA, as the view paints
    full = decoder.decode_now(frame.source, local, learn=False)  # a snapshot: whole
    assert full is not None
    assert (full.width, full.height) == (160, 120)


def test_the_extra_camera_stays_out_of_the_robots_protocol() -> None:
    engineer = load_profile(None)
    profile = with_camera(engineer, "usb")
    assert profile.link.camera_names == engineer.link.camera_names
    assert video_names(profile) == (*engineer.link.camera_names, "usb")
    local = len(engineer.cameras)
    assert profile.cameras[local].index == local
    assert is_local(profile, local)
    assert not is_local(profile, 0)
    assert with_camera(profile, "usb").cameras[-1].name == "usb 2"


def test_targets_and_errors_name_the_device(tmp_path: Path) -> None:
    assert camera_target("0") == 0
    assert camera_target("/dev/video2") == "/dev/video2"
    with pytest.raises(CameraError, match="give a device"):
        camera_target(" ")
    with pytest.raises(CameraError, match=r"camera /dev/video42: no such device or file"):
        OpenCvSource("/dev/video42")
    with pytest.raises(CameraError, match=r"camera 63: OpenCV cannot open it"):
        OpenCvSource(63)
    text = tmp_path / "x.txt"
    text.write_text("x")
    with pytest.raises(CameraError, match=r"x\.txt: OpenCV cannot open it"):
        OpenCvSource(str(text))
