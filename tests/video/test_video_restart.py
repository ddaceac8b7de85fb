"""Video after a link blip and after a robot reboot: the real simulator over 127.0.0.1.

A 2 s blip used to blank the cameras for as long as they had streamed before it: the
simulator restarted its frame numbers on the fresh hello, and the console dropped every frame
behind the newest one it had shown as out of order.
"""

from __future__ import annotations

import time

from ocu.link.live import UdpLink
from ocu.profile import RobotProfile
from ocu.records import CameraRequest, VideoFrame
from ocu.sim.simulator import RobotSimulator
from tests.link.test_core import Recorder

CAMERAS = (0, 1, 2, 3)
FPS = 30
# Frames each camera streams before the blip: about 3 s, longer than the blip and than the
# ~1 s the cameras may take to come back, so a stream waited out would show.
STREAMED_BEFORE = 90
# A hang guard, not a timing assertion: the measured gap is reported by the assertions' data.
DEADLINE_S = 15.0


def newest(frames: list[VideoFrame]) -> dict[int, int]:
    latest: dict[int, int] = {}
    for frame in frames:
        assert frame.camera is not None
        assert frame.sequence is not None
        latest[frame.camera] = frame.sequence
    return latest


def first_after(frames: list[VideoFrame], since: float) -> dict[int, VideoFrame]:
    first: dict[int, VideoFrame] = {}
    for frame in frames:
        if frame.received_at > since and frame.camera is not None and frame.camera not in first:
            first[frame.camera] = frame
    return first


def stream(profile: RobotProfile, sim: RobotSimulator, recorder: Recorder) -> UdpLink:
    link = UdpLink(
        profile, sim.address, listener=recorder, extension=True, gui_alive_timeout_s=None
    )
    link.set_stream_request([CameraRequest(k, 160, 120, FPS) for k in CAMERAS])
    link.start()
    return link


def streamed(recorder: Recorder, count: int) -> bool:
    latest = newest(recorder.video)
    return set(latest) == set(CAMERAS) and min(latest.values()) >= count


def test_a_link_blip_blanks_the_cameras_only_while_it_lasts(profile: RobotProfile) -> None:
    sim = RobotSimulator(profile, extended=True, video_fps=0.0)
    sim.start()
    recorder = Recorder()
    link = stream(profile, sim, recorder)
    try:
        assert recorder.wait(lambda: streamed(recorder, STREAMED_BEFORE), DEADLINE_S)
        sim.cut_link()
        # Until the robot's 1 s watchdog has stopped its streams: the next hello is fresh,
        # where the simulator used to start counting again at 0.
        assert sim.wait_until(lambda s: s.extended is not None and not s.extended.active, 5.0)
        with recorder.cond:
            before = newest(recorder.video)
        sim.restore_link()
        restored_at = time.monotonic()
        assert recorder.wait(
            lambda: set(first_after(recorder.video, restored_at)) == set(CAMERAS), DEADLINE_S
        )
        with recorder.cond:
            after = first_after(recorder.video, restored_at)
    finally:
        link.shutdown()
        sim.stop()
    gaps = {camera: round(frame.received_at - restored_at, 3) for camera, frame in after.items()}
    # The cameras are back within about a second (the hello goes out on the next tick).
    assert max(gaps.values()) < 1.5, gaps
    # The robot went on counting (docs/protocol.md): nothing restarted, nothing dropped.
    for camera in CAMERAS:
        sequence = after[camera].sequence
        assert sequence is not None
        assert sequence > before[camera], (camera, before, sequence)
    stats = link.video_stats()
    assert stats.restarts == 0
    assert stats.out_of_order == 0


def test_video_comes_back_at_once_from_a_rebooted_robot(profile: RobotProfile) -> None:
    sim = RobotSimulator(profile, extended=True, video_fps=0.0)
    sim.start()
    recorder = Recorder()
    link = stream(profile, sim, recorder)
    rebooted: RobotSimulator | None = None
    try:
        assert recorder.wait(lambda: streamed(recorder, STREAMED_BEFORE), DEADLINE_S)
        sim.stop()
        with recorder.cond:
            before = newest(recorder.video)
        # The same robot address, a new process: its frame numbers start again at 0. The
        # console's link is never declared lost (the reboot is quicker than 3 s).
        rebooted = RobotSimulator(profile, port=sim.address[1], extended=True, video_fps=0.0)
        rebooted.start()
        booted_at = time.monotonic()
        assert recorder.wait(
            lambda: set(first_after(recorder.video, booted_at)) == set(CAMERAS), DEADLINE_S
        )
        with recorder.cond:
            after = first_after(recorder.video, booted_at)
    finally:
        link.shutdown()
        sim.stop()
        if rebooted is not None:
            rebooted.stop()
    # The restarted stream is shown from its first frames, not after it passes the old count.
    for camera in CAMERAS:
        sequence = after[camera].sequence
        assert sequence is not None
        assert sequence < before[camera] // 2, (camera, before, sequence)
    assert link.video_stats().restarts >= len(CAMERAS)
