"""Click-to-track while the robot turns: the tracking error in pixels, ours against a baseline.

    python bench/bench_tracking.py                 # 0 and 150 ms one way, ~20 s per run
    python bench/bench_tracking.py --latency-ms 0 --seconds 10

The real console model (ocu.headless) over a real UDP link to the real simulator in a world
with one box, the head camera streaming (the zoom camera, mounted on the arm's head: the waist
pans it, the neck tilts it). The bench starts tracking on the box, then turns the chassis at
0.3 rad/s (the simulator's place(): the robot refuses to move its waist while the tracks
drive, so the turn is imposed, not driven) for the run's length, one way: the waist starts
turned 2.4 rad left, the box 1.7 m ahead of the head camera, and the waist must sweep right
at about the turn's rate (a step from rest to 0.3 rad/s at the start, then steady).

The error is ground truth, not the tracker's opinion: the box's centre projected into the
head camera's ideal pinhole image (640x480, the simulator's focal length) from the
simulator's true pose and joint angles, at every physics snapshot; its distance from the
image centre in pixels (the calibrated focal length: what the console's undistorted view
shows), RMS and p95 over the turn, and the horizontal part alone (the axis the turn disturbs;
the vertical part is mostly the constant offset between the box's middle in 3D and the middle
of its visible faces, which the tracker centres).

Ours: gains adapted to the measured delay, rate feed-forward, Smith-predicted error
(ocu.control.tracking). Baseline, same run: the paper's PID on the last frame's image error
with the gains tuned for no delay (TrackingOptions.baseline()).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import queue
import statistics
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ocu.console.model import ConsoleModel
from ocu.console.tracking import camera_axes
from ocu.control.tracking import TrackingOptions
from ocu.hardware.engineer import engineer_component
from ocu.headless import HeadlessConsole
from ocu.kinematics.arm import ArmKinematics
from ocu.link.live import UdpLink
from ocu.model.urdf import load_urdf
from ocu.nav.geometry import Pose
from ocu.nav.world import parse_world
from ocu.profile import CameraSettings, RobotProfile, load_profile
from ocu.records import CameraRequest, LinkEvent, LinkState, VideoFrame
from ocu.sim.faults import FaultConfig
from ocu.sim.scene import CameraLinks, camera_position, camera_rotation
from ocu.sim.simulator import RobotSimulator, SimState, StateRecorder
from ocu.video.decoder import decode_jpeg

TURN_RAD_S = 0.3
# The waist starts turned this far left and ends about as far right after a 15 s turn: one
# steady turn fits in its +-170 degrees.
PAN_START_RAD = 2.4
# The box stands this far ahead of the head camera at the start.
BOX_AHEAD_M = 1.7
PLACE_HZ = 50.0
SETTLE_S = 3.0
# A small cube: the middle of its outline (what the tracker centres) is its middle in 3D from
# any side, so the ground truth measures the tracking, not where a big box's faces lie.
BOX_SIZE_M = 0.12
BOX_HEIGHT_M = 0.12
IMAGE_PX = (640, 480)
STREAM_PX = (320, 240)
STREAM_FPS = 30
TELEMETRY_HZ = 20.0


@dataclass
class Run:
    """One run's outcome."""

    name: str
    latency_ms: float
    errors_px: list[float]
    pan_errors_px: list[float]
    lost_s: float
    ended: str

    @property
    def rms_px(self) -> float:
        return math.sqrt(statistics.fmean(e * e for e in self.errors_px))

    @property
    def p95_px(self) -> float:
        return float(np.percentile(self.errors_px, 95))

    @property
    def pan_rms_px(self) -> float:
        return math.sqrt(statistics.fmean(e * e for e in self.pan_errors_px))


class GroundTruth:
    """Where the box's centre is in the head camera's ideal image, from the simulator's truth."""

    def __init__(
        self, profile: RobotProfile, camera: CameraSettings, box_centre_m: tuple[float, float]
    ) -> None:
        assert camera.mount is not None
        assert camera.mount.link is not None
        assert camera.calibration is not None
        self.mount = camera.mount
        base = profile.arm.base_link if profile.arm is not None else "base_link"
        self.links = CameraLinks(load_urdf(meshes=False).tree, base)
        # The camera's own focal length: the simulator's lens maps its picture onto the
        # calibrated model (what the console's undistortion shows), whatever focal length it
        # renders the scene at before the lens.
        scale = IMAGE_PX[0] / camera.calibration.size_px[0]
        self.focal_px = camera.calibration.focal_px[0] * scale
        self.point = np.array([*box_centre_m, BOX_HEIGHT_M / 2.0])

    def pixel(self, state: SimState) -> tuple[float, float] | None:
        """The box centre in pixels of the 640x480 image (None: behind the camera)."""
        assert self.mount.link is not None
        link = self.links.transform(self.mount.link, state.joints_rad)
        pose = Pose(*state.pose)
        rotation = camera_rotation(pose, self.mount, link)
        seen = rotation @ (self.point - camera_position(pose, self.mount, link))
        if seen[2] <= 0.05:
            return None
        return (
            self.focal_px * seen[0] / seen[2] + IMAGE_PX[0] / 2.0,
            self.focal_px * seen[1] / seen[2] + IMAGE_PX[1] / 2.0,
        )

    def pan_error_px(self, state: SimState) -> float:
        """The horizontal part (the axis the turn disturbs), at most half the image's width
        (a box out of the picture counts as at its edge)."""
        pixel = self.pixel(state)
        half = IMAGE_PX[0] / 2.0
        return half if pixel is None else max(-half, min(half, pixel[0] - half))

    def error_px(self, state: SimState) -> float:
        """Distance of the box centre from the image centre, at most the image's half
        diagonal (out of the picture, or behind the camera)."""
        limit = math.hypot(*IMAGE_PX) / 2.0
        pixel = self.pixel(state)
        if pixel is None:
            return limit
        return min(limit, math.hypot(pixel[0] - IMAGE_PX[0] / 2.0, pixel[1] - IMAGE_PX[1] / 2.0))


def box_ahead(profile: RobotProfile, camera: CameraSettings, pan_joint: str) -> tuple[float, float]:
    """Where the box goes: BOX_AHEAD_M along the head camera's view, the waist at the start."""
    assert camera.mount is not None
    assert camera.mount.link is not None
    base = profile.arm.base_link if profile.arm is not None else "base_link"
    links = CameraLinks(load_urdf(meshes=False).tree, base)
    link = links.transform(camera.mount.link, {pan_joint: PAN_START_RAD})
    pose = Pose(0.0, 0.0, 0.0)
    forward = camera_rotation(pose, camera.mount, link)[2]
    origin = camera_position(pose, camera.mount, link)
    heading = math.atan2(forward[1], forward[0])
    return (
        float(origin[0] + BOX_AHEAD_M * math.cos(heading)),
        float(origin[1] + BOX_AHEAD_M * math.sin(heading)),
    )


def wait(condition: Callable[[], bool], timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError(what)
        time.sleep(0.02)


class FrameFeed:
    """The head camera's frames, decoded off the link's thread, into the console's thread."""

    def __init__(self, headless: HeadlessConsole, camera: int) -> None:
        self.headless = headless
        self.camera = camera
        self.latest: tuple[np.ndarray, float] | None = None
        self._frames: queue.Queue[VideoFrame] = queue.Queue(maxsize=2)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="bench-frames", daemon=True)
        self._thread.start()

    def on_event(self, event: LinkEvent) -> None:
        if isinstance(event, VideoFrame) and event.camera == self.camera:
            # The tracker takes the newest it can, like the console's mailbox.
            with contextlib.suppress(queue.Full):
                self._frames.put_nowait(event)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                frame = self._frames.get(timeout=0.2)
            except queue.Empty:
                continue
            pixels = decode_jpeg(frame.jpeg)
            if pixels is None:
                continue
            self.latest = (pixels, frame.received_at)
            self._track(pixels, frame.received_at)

    def _track(self, pixels: np.ndarray, received_at: float) -> None:
        model = self.headless.model
        self.headless.call(lambda: model.on_tracking_frame(self.camera, pixels, received_at))

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)


def _ask(headless: HeadlessConsole, model: ConsoleModel, request: CameraRequest) -> None:
    headless.call(lambda: model.set_stream_request(request))


def run(
    profile: RobotProfile, name: str, options: TrackingOptions, latency_ms: float, seconds: float
) -> Run:
    camera = next(
        i for i, c in enumerate(profile.cameras) if c.mount is not None and c.mount.link is not None
    )
    assert profile.arm is not None
    axes = camera_axes(
        profile.cameras[camera], ArmKinematics(load_urdf(meshes=False), profile.arm), {}
    )
    box_centre = box_ahead(profile, profile.cameras[camera], axes.pan_joint)
    truth = GroundTruth(profile, profile.cameras[camera], box_centre)
    world = parse_world(
        {
            "box": [
                {
                    "centre_m": list(box_centre),
                    "size_m": [BOX_SIZE_M, BOX_SIZE_M],
                    "height_m": BOX_HEIGHT_M,
                    "colour": [230, 40, 40],
                }
            ]
        }
    )
    sim = RobotSimulator(
        profile,
        extended=True,
        world=world,
        telemetry_hz=TELEMETRY_HZ,
        video_fps=0.0,
        faults=FaultConfig(latency_ms=latency_ms),
        seed=7,
        initial_joints={axes.pan_joint: PAN_START_RAD},
    )
    sim.start()
    model = ConsoleModel(profile)
    model.tracking_options = options
    link = UdpLink(profile, sim.address, extension=True)
    headless = HeadlessConsole(model, engineer_component(link))
    feed = FrameFeed(headless, camera)
    link.subscribe(feed.on_event)
    messages: list[str] = []
    model.events.message.connect(messages.append)
    headless.start()
    recorder: StateRecorder | None = None
    try:
        wait(
            lambda: headless.call(lambda: model.robot.link_state) is LinkState.CONNECTED, 10, "link"
        )
        for index in range(len(profile.cameras)):
            width, height = STREAM_PX
            fps = STREAM_FPS if index == camera else 0
            request = CameraRequest(camera=index, width_px=width, height_px=height, fps=fps)
            _ask(headless, model, request)
        joints = set(profile.arm.joints) if profile.arm is not None else set()
        wait(lambda: joints <= set(headless.call(model.predicted_angles)), 10, "readings")
        wait(lambda: feed.latest is not None, 10, "frames")
        start = truth.pixel(sim.state())
        assert start is not None, "the box is not in front of the head camera"
        pixels, _ = feed.latest  # type: ignore[misc]
        point = (start[0] / IMAGE_PX[0], start[1] / IMAGE_PX[1])
        headless.call(lambda: model.start_tracking(camera, pixels, point))
        # Settle on the box, then turn.
        time.sleep(SETTLE_S)
        recorder = StateRecorder(sim)
        began = time.monotonic()
        period = 1.0 / PLACE_HZ
        next_at = began
        while (now := time.monotonic()) - began < seconds:
            sim.place(Pose(0.0, 0.0, TURN_RAD_S * (now - began)))
            next_at += period
            time.sleep(max(0.0, next_at - time.monotonic()))
        recorder.stop()
        samples = [s for s in recorder.samples if s.time_s >= sim.state().time_s - seconds - 0.1]
        errors = [truth.error_px(s) for s in samples]
        pan_errors = [truth.pan_error_px(s) for s in samples]
        ended = headless.call(lambda: "running" if model.tracking is not None else "stopped")
        lost = sum(1 for m in messages if "LOST" in m)
        return Run(name, latency_ms, errors, pan_errors, float(lost), ended)
    finally:
        if recorder is not None:
            recorder.stop()
        feed.stop()
        headless.stop()
        sim.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--latency-ms", type=float, action="append", help="one way; repeatable")
    parser.add_argument("--seconds", type=float, default=15.0, help="length of the turn")
    args = parser.parse_args()
    latencies = args.latency_ms or [0.0, 150.0]
    profile = load_profile()
    runs = []
    for latency in latencies:
        for name, options in (
            ("ours", TrackingOptions()),
            ("baseline", TrackingOptions.baseline()),
        ):
            result = run(profile, name, options, latency, args.seconds)
            runs.append(result)
            print(
                f"  {name:8s} {latency:5.0f} ms: RMS {result.rms_px:6.1f} px  "
                f"p95 {result.p95_px:6.1f} px  horizontal RMS {result.pan_rms_px:6.1f} px  "
                f"({len(result.errors_px)} samples, "
                f"object lost {result.lost_s:.0f}x, tracking {result.ended} at the end)",
                flush=True,
            )
    print()
    print(
        f"Tracking error while the chassis turns at {TURN_RAD_S} rad/s "
        f"for {args.seconds:.0f} s, pixels of a 640x480 image"
    )
    print(
        "latency one way | ours RMS (horiz.) | ours p95 | baseline RMS (horiz.) | baseline p95 "
        "| baseline / ours"
    )
    for latency in latencies:
        ours = next(r for r in runs if r.latency_ms == latency and r.name == "ours")
        base = next(r for r in runs if r.latency_ms == latency and r.name == "baseline")
        print(
            f"{latency:12.0f} ms | {ours.rms_px:6.1f} ({ours.pan_rms_px:5.1f})    | "
            f"{ours.p95_px:8.1f} | {base.rms_px:6.1f} ({base.pan_rms_px:5.1f})        | "
            f"{base.p95_px:12.1f} | {base.rms_px / ours.rms_px:5.2f}x"
        )


if __name__ == "__main__":
    main()
