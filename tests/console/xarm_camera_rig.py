"""The xArm simulator, its link, the console's control core and a scene camera on its gripper,
for closed-loop tracking tests and bench/bench_xarm_tracking.py.

The picture comes from `SceneCamera` (ocu.sim.xarm_camera): the simulated shafts through the
URDF, a disc where the object is; it is delivered by `CameraCapture` on its own thread, as a
USB camera is, and fed to the console model's tracking as the Video dock feeds it.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import cv2
import numpy as np

from ocu.console.model import ConsoleModel
from ocu.control.reach_tracking import ReachOptions, ServoModel
from ocu.hardware.xarm import SimulatedXarm
from ocu.headless import HeadlessConsole
from ocu.link.xarm import XarmLink
from ocu.profile import CameraMount, RobotProfile
from ocu.profile.xarm import XarmProfile, load_xarm_profile
from ocu.profile.xarm_robot import xarm_robot_profile
from ocu.records import LinkState, VideoFrame
from ocu.sim.xarm import XarmSimulator
from ocu.sim.xarm_camera import LOOKING_AHEAD_DEG, OBJECT_AHEAD, Point, SceneCamera
from ocu.video.capture import CameraCapture, CapturedFrame, with_camera

DEADLINE_S = 20.0


def wait_for(check: Callable[[], bool], what: str, deadline_s: float = DEADLINE_S) -> None:
    deadline = time.monotonic() + deadline_s
    pause = threading.Event()
    while not check():
        if time.monotonic() > deadline:
            raise AssertionError(f"not {what} within {deadline_s} s")
        pause.wait(0.005)


def camera_profile(arm: XarmProfile) -> RobotProfile:
    """The xArm's profile with a camera on its gripper (tool0), as `ocu --camera` adds it."""
    return with_camera(
        xarm_robot_profile(arm), "usb", mount=CameraMount((0.0, 0.0, 0.0), link="tool0")
    )


@dataclass
class CameraRig:
    arm: XarmProfile
    profile: RobotProfile
    sim: XarmSimulator
    headless: HeadlessConsole
    model: ConsoleModel
    scene: SceneCamera
    capture: CameraCapture
    object_at: Callable[[float], Point]
    frames: list[CapturedFrame] = field(default_factory=list)

    def latest(self) -> CapturedFrame:
        wait_for(lambda: bool(self.frames), "a picture")
        return self.frames[-1]

    def start_tracking(self) -> None:
        """Click the object where the newest picture shows it (the red disc's middle)."""
        pixels = self.latest().pixels
        assert pixels is not None
        hsv = cv2.cvtColor(pixels, cv2.COLOR_BGR2HSV)
        red = (hsv[:, :, 1] > 120) & ((hsv[:, :, 0] < 10) | (hsv[:, :, 0] > 170))
        rows, columns = np.nonzero(red)
        assert rows.size, "the object is not in the picture"
        height, width = pixels.shape[:2]
        point = ((float(columns.mean()) + 0.5) / width, (float(rows.mean()) + 0.5) / height)
        self.headless.call(lambda: self.model.start_tracking(0, pixels, point))

    def error(self) -> tuple[float, float, float]:
        """Ground truth now: the object's distance from the picture's centre (pixels), from
        the optical axis (m), and its depth (m)."""
        now = time.monotonic()
        pose = self.scene.camera_pose()
        local = pose[:3, :3].T @ (np.array(self.object_at(now)) - pose[:3, 3])
        seen = self.scene.project(self.object_at(now))
        assert seen is not None
        cx, cy = self.scene.calibration.centre_px
        return (
            math.hypot(seen[0] - cx, seen[1] - cy),
            math.hypot(float(local[1]), float(local[2])),
            float(local[0]),
        )


def camera_rig(
    object_at: Callable[[float], Point] | None = None,
    *,
    latency_ms: float = 0.0,
    options: ReachOptions | None = None,
) -> Iterator[CameraRig]:
    arm = load_xarm_profile("xarm1s")
    profile = camera_profile(arm)
    initial = {
        arm.joint(name).servo: arm.raw_units(arm.joint(name), math.radians(deg))
        for name, deg in LOOKING_AHEAD_DEG.items()
    }
    sim = XarmSimulator(arm, initial=initial, latency_ms=latency_ms, seed=4)
    hardware = SimulatedXarm(sim, XarmLink(arm, sim.start(), profile=profile))
    model = ConsoleModel(profile)
    model.servo_model = ServoModel(arm.servo.damping_ratio, arm.servo.natural_frequency_rad_s)
    if options is not None:
        model.reach_options = options
    headless = HeadlessConsole(model, hardware, control_period_s=0.02)
    where = object_at or (lambda _now: OBJECT_AHEAD)
    scene = SceneCamera(arm, profile, lambda: sim.snapshot().positions, where)
    capture = CameraCapture(scene, 0)
    rig = CameraRig(arm, profile, sim, headless, model, scene, capture, where)

    def deliver(frame: VideoFrame) -> None:
        # As the Video dock does with each decoded frame of the tracked camera.
        assert isinstance(frame, CapturedFrame)
        assert frame.pixels is not None
        rig.frames.append(frame)
        del rig.frames[:-3]
        pixels = frame.pixels
        headless.call(lambda: model.on_tracking_frame(0, pixels, frame.received_at))

    capture.set_sink(deliver)
    headless.start()
    try:
        wait_for(lambda: headless.link.state is LinkState.CONNECTED, "connected")
        wait_for(lambda: len(headless.call(model.predicted_angles)) >= 4, "angles known")
        capture.start()
        yield rig
    finally:
        capture.stop()
        headless.stop()
