"""Fragment reassembly: order, loss, duplicates, bounds, stale frames, sequence wrap."""

from __future__ import annotations

import random
from dataclasses import replace

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ocu.link.live import UdpLink
from ocu.link.reassembly import (
    RESTART_GAP,
    Reassembler,
    sequence_behind,
    sequence_newer,
)
from ocu.profile import RobotProfile
from ocu.protocol.extended import VideoFragment, fragment_frame
from ocu.records import CameraRequest
from ocu.sim.extended import jpeg_comment
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator
from ocu.sim.video import parse_comment
from tests.link.test_core import Recorder

MAX_DATAGRAM = 64 + 26  # 64-byte fragments keep the frames small and the counts readable


def jpeg(seed: int, size: int = 600) -> bytes:
    """A byte string shaped like a JPEG (SOI ... EOI), distinct per seed."""
    body = random.Random(seed).randbytes(size)
    return b"\xff\xd8\xff" + body + b"\xff\xd9"


def frame(camera: int, sequence: int, size: int = 600) -> list[VideoFragment]:
    return fragment_frame(
        camera, sequence, sequence * 1000, jpeg(camera * 1000 + sequence, size), MAX_DATAGRAM
    )


def make(max_frames: int = 8, max_bytes: int = 1 << 20, timeout_s: float = 0.5) -> Reassembler:
    return Reassembler(max_frames=max_frames, max_bytes=max_bytes, timeout_s=timeout_s)


def test_in_order_fragments_make_the_frame() -> None:
    reassembler = make()
    fragments = frame(2, 7)
    assert len(fragments) == 10
    results = [reassembler.add(f, now=1.0 + i * 0.001) for i, f in enumerate(fragments)]
    assert results[:-1] == [None] * 9
    done = results[-1]
    assert done is not None
    assert (done.camera, done.sequence, done.capture_time_us) == (2, 7, 7000)
    assert done.jpeg == jpeg(2007)
    assert done.fragments == 10
    assert done.first_at == 1.0
    stats = reassembler.stats()
    assert (stats.completed, stats.fragments, stats.frames_held, stats.bytes_held) == (1, 10, 0, 0)


@settings(max_examples=60, deadline=None)
@given(st.randoms(use_true_random=False))
def test_any_order_with_duplicates_gives_each_frame_once(rng: random.Random) -> None:
    reassembler = make()
    fragments = frame(0, 1) + frame(1, 1) + frame(2, 1)
    stream = fragments + rng.sample(fragments, 7)  # seven duplicates
    rng.shuffle(stream)
    done = [r for f in stream if (r := reassembler.add(f, now=1.0)) is not None]
    assert sorted((d.camera, d.jpeg) for d in done) == [(c, jpeg(c * 1000 + 1)) for c in range(3)]
    stats = reassembler.stats()
    assert stats.duplicates == 7
    assert stats.frames_held == 0


def test_single_fragment_frames_need_no_buffer() -> None:
    reassembler = make()
    (only,) = fragment_frame(0, 5, 0, jpeg(1, 10), 1472)
    done = reassembler.add(only, now=0.0)
    assert done is not None
    assert done.jpeg == jpeg(1, 10)
    assert reassembler.add(only, now=0.0) is None
    assert reassembler.stats().duplicates == 1


def test_lost_fragment_expires_after_the_timeout() -> None:
    reassembler = make(timeout_s=0.5)
    for fragment in frame(0, 1)[1:]:
        assert reassembler.add(fragment, now=10.0) is None
    assert reassembler.stats().frames_held == 1
    assert reassembler.expire(10.4) == 0
    assert reassembler.expire(10.6) == 1
    stats = reassembler.stats()
    assert (stats.expired, stats.frames_held, stats.bytes_held) == (1, 0, 0)


def test_newer_frame_supersedes_incomplete_older_ones() -> None:
    reassembler = make()
    for fragment in frame(0, 1)[:5]:
        reassembler.add(fragment, now=0.0)
    for fragment in frame(1, 1)[:5]:
        reassembler.add(fragment, now=0.0)
    done = [reassembler.add(f, now=0.0) for f in frame(0, 2)]
    assert done[-1] is not None
    stats = reassembler.stats()
    assert stats.truncated == 1  # camera 0 frame 1 given up; camera 1 is untouched
    assert stats.frames_held == 1
    # The rest of camera 0 frame 1 now arrives: older than what was shown, dropped.
    assert all(reassembler.add(f, now=0.0) is None for f in frame(0, 1)[5:])
    assert reassembler.stats().out_of_order == 5


def test_frame_older_than_the_newest_shown_is_dropped() -> None:
    reassembler = make()
    assert [reassembler.add(f, now=0.0) for f in frame(3, 10)][-1] is not None
    assert all(reassembler.add(f, now=0.0) is None for f in frame(3, 9))
    stats = reassembler.stats()
    assert stats.out_of_order == 10
    assert stats.frames_held == 0
    # A late copy of the newest frame is a duplicate, not a new frame.
    assert reassembler.add(frame(3, 10)[0], now=0.0) is None
    assert reassembler.stats().duplicates == 1


def test_bounds_evict_the_oldest_partial_frame() -> None:
    reassembler = make(max_frames=3, max_bytes=1 << 20)
    for sequence in range(5):
        reassembler.add(frame(sequence, 0)[0], now=sequence * 0.01)
    stats = reassembler.stats()
    assert (stats.frames_held, stats.evicted, stats.truncated) == (3, 2, 2)
    by_bytes = make(max_frames=100, max_bytes=2000)
    for camera in range(5):
        by_bytes.add(frame(camera, 0)[0], now=0.0)  # each frame reserves 605 bytes
        assert by_bytes.stats().bytes_held <= 2000
    assert by_bytes.stats().evicted == 2


def test_inconsistent_fragments_are_counted_not_mixed_in() -> None:
    reassembler = make()
    first, second, *_ = frame(0, 1)
    reassembler.add(first, now=0.0)
    liar = VideoFragment(0, 1, 999, second.frame_bytes, second.offset, 1, second.count, b"x" * 64)
    assert reassembler.add(liar, now=0.0) is None
    huge = VideoFragment(1, 1, 0, 2 << 20, 0, 0, 2, b"x")
    assert reassembler.add(huge, now=0.0) is None
    assert reassembler.stats().inconsistent == 2


def test_sequence_wraps_and_a_restart_is_accepted() -> None:
    assert sequence_newer(0, 2**32 - 1)
    assert not sequence_newer(2**32 - 1, 0)
    assert sequence_behind(2**32 - 1, 0) == 1
    reassembler = make()
    assert [reassembler.add(f, now=0.0) for f in frame(0, 2**32 - 1)][-1] is not None
    assert [reassembler.add(f, now=0.0) for f in frame(0, 0)][-1] is not None
    assert [reassembler.add(f, now=0.0) for f in frame(0, 5000)][-1] is not None
    # Far behind: the robot restarted its counter, the stream goes on.
    assert [reassembler.add(f, now=0.0) for f in frame(0, 5000 - RESTART_GAP - 1)][-1] is not None
    assert reassembler.stats().restarts == 1


def complete(reassembler: Reassembler, camera: int, sequence: int, now: float) -> bool:
    return [reassembler.add(f, now=now) for f in frame(camera, sequence)][-1] is not None


def test_a_restarted_stream_after_a_pause_is_accepted() -> None:
    # A robot that rebooted after 20 s of video: its counter starts again 600 numbers behind
    # (less than RESTART_GAP), after a silence longer than the timeout.
    reassembler = make(timeout_s=0.5)
    for sequence in range(590, 601):
        assert complete(reassembler, 0, sequence, now=sequence / 30.0)
    last_s = 600 / 30.0
    assert complete(reassembler, 0, 0, now=last_s + 2.0)
    assert complete(reassembler, 0, 1, now=last_s + 2.033)
    stats = reassembler.stats()
    assert stats.restarts == 1
    assert stats.out_of_order == 0


def test_a_late_frame_in_a_flowing_stream_is_still_out_of_order() -> None:
    reassembler = make(timeout_s=0.5)
    assert complete(reassembler, 0, 10, now=0.0)
    assert complete(reassembler, 0, 12, now=0.066)
    assert not complete(reassembler, 0, 11, now=0.1)  # reordered by the network
    assert complete(reassembler, 0, 13, now=0.1)
    assert reassembler.stats().out_of_order > 0
    assert reassembler.stats().restarts == 0


def test_reset_forgets_the_newest_sequence_of_every_camera() -> None:
    reassembler = make(timeout_s=0.5)
    for camera in (0, 1):
        assert complete(reassembler, camera, 300, now=0.0)
    first, *_ = frame(1, 301)
    reassembler.add(first, now=0.0)
    assert reassembler.stats().frames_held == 1
    reassembler.reset()  # LINK LOST
    assert reassembler.stats().frames_held == 0
    assert reassembler.stats().bytes_held == 0
    # The same instant (no silence to go by): the restarted counters are taken at once.
    assert complete(reassembler, 0, 0, now=0.0)
    assert complete(reassembler, 1, 5, now=0.0)
    assert reassembler.stats().out_of_order == 0


def test_bad_bounds_are_refused() -> None:
    with pytest.raises(ValueError, match="positive"):
        Reassembler(0, 100, 1.0)


# ---- against the real simulator over 127.0.0.1 ----------------------------------------------


def test_real_simulator_with_loss_duplicates_and_reordering(profile: RobotProfile) -> None:
    # Jitter (up to 80 ms) reorders fragments and whole frames (33 ms apart); loss truncates.
    # Datagrams of a 1500-byte link (not the loopback's 64 KiB), so frames are fragmented.
    assert profile.extension is not None
    fixed = replace(profile.extension, fit_datagrams_to_path=False)
    profile = replace(profile, extension=fixed)
    faults = FaultConfig(loss=0.03, duplicate=0.2, jitter_ms=80.0)
    sim = RobotSimulator(profile, extended=True, video_fps=0.0, faults=faults, seed=11)
    sim.start()
    recorder = Recorder()
    link = UdpLink(profile, sim.address, listener=recorder, extension=True)
    link.set_stream_request([CameraRequest(k, 240, 180, 30) for k in range(4)])
    link.start()
    try:
        assert recorder.wait(lambda: len(recorder.video) >= 150, timeout_s=15.0)
    finally:
        link.shutdown()
        sim.stop()
    stats = link.video_stats()
    assert stats.duplicates > 0
    assert stats.truncated + stats.expired > 0
    assert stats.out_of_order > 0
    assert stats.inconsistent == 0
    last: dict[int, int] = {}
    for frame in recorder.video:
        assert frame.camera is not None
        assert frame.sequence is not None
        comment = jpeg_comment(frame.jpeg)
        assert comment is not None
        facts = parse_comment(comment)
        assert facts["index"] == str(frame.camera)
        assert facts["frame"] == str(frame.sequence)
        assert frame.sequence > last.get(frame.camera, -1)  # never an older frame after a newer
        last[frame.camera] = frame.sequence
        image = cv2.imdecode(np.frombuffer(frame.jpeg, np.uint8), cv2.IMREAD_COLOR)
        assert image is not None
        assert image.shape == (180, 240, 3)
    assert set(last) == {0, 1, 2, 3}


def test_datagrams_as_large_as_the_path_allows(profile: RobotProfile) -> None:
    from ocu.link.live import VirtualLink
    from ocu.net.transport import VirtualWire

    assert profile.extension is not None
    loopback = UdpLink(profile, ("127.0.0.1", 9), extension=True)
    wire = VirtualWire()
    virtual = VirtualLink(profile, wire.ocu, extension=True)
    fixed_profile = replace(
        profile, extension=replace(profile.extension, fit_datagrams_to_path=False)
    )
    fixed = UdpLink(fixed_profile, ("127.0.0.1", 9), extension=True)
    try:
        # The loopback's MTU is 64 KiB: one datagram carries a whole 640x480 JPEG.
        assert loopback.stream_request.max_datagram_bytes == 65507
        assert virtual.stream_request.max_datagram_bytes == 65507
        assert fixed.stream_request.max_datagram_bytes == profile.extension.max_datagram_bytes
        # A stream request keeps the size asked for.
        loopback.set_stream_request([CameraRequest(0, 320, 240, 10)])
        assert loopback.stream_request.max_datagram_bytes == 65507
    finally:
        for link in (loopback, virtual, fixed):
            link.shutdown()
        wire.close()
