"""A synthetic camera on the simulated xArm's gripper: what it would see of a coloured disc.

For closed-loop tests, the benchmark and demos of seed 003's tracking, the picture must depend
on the simulated arm: `SceneCamera` reads the simulator's servo positions (the shafts, not
what the link was told), puts the camera on tool0 through the xArm's URDF (the console's own
forward kinematics) and draws a disc of the object's size where a pinhole camera looking along
the tool would see the object, a world point that may move (`object_at(t)`). The camera's
mount follows seed 003, whose camera rides on the arm's end and looks where the gripper points
(its §2.2: the base turns the picture left and right, the tool's height moves it up and down,
the reach changes the object's size); its field of view is the default of an uncalibrated USB
camera (ocu.video.capture). It is a `FrameSource`: `CameraCapture` paces and delivers it as
it does a file, on a thread of its own.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping

import cv2
import numpy as np
import numpy.typing as npt

from ocu.kinematics.arm import ArmKinematics
from ocu.model.urdf import load_urdf
from ocu.profile import CameraCalibration, RobotProfile
from ocu.profile.xarm import XarmProfile
from ocu.profile.xarm_urdf import ARM_JOINTS
from ocu.video.capture import Pixels, default_calibration

Point = tuple[float, float, float]
OBJECT_DIAMETER_M = 0.04
OBJECT_BGR = (40, 40, 210)
SCENE_FPS = 30.0
# A bent arm looking straight ahead (URDF angles, degrees): its tool horizontal, 0.29 m out
# and 0.19 m up; the scene's object starts 0.15 m in front of it.
LOOKING_AHEAD_DEG = {"base": 0.0, "shoulder": 20.0, "elbow": 50.0, "wrist_pitch": 20.0}
OBJECT_AHEAD: Point = (0.44, 0.0, 0.19)


def swaying(
    centre: Point, amplitude: Point, period_s: float, start: float | None = None
) -> Callable[[float], Point]:
    """An object moving about `centre` by `amplitude` (m, each axis) with this period; the
    vertical axis at half the frequency of the others' (a figure of eight)."""
    origin = time.monotonic() if start is None else start

    def at(now: float) -> Point:
        phase = math.tau * (now - origin) / period_s
        return (
            centre[0] + amplitude[0] * math.sin(phase),
            centre[1] + amplitude[1] * math.sin(phase),
            centre[2] + amplitude[2] * math.sin(phase / 2.0),
        )

    return at


class SceneCamera:
    """Pictures of a disc seen from the simulated arm's tool (module docstring)."""

    def __init__(
        self,
        arm: XarmProfile,
        profile: RobotProfile,
        positions: Callable[[], Mapping[int, float]],
        object_at: Callable[[float], Point],
        *,
        calibration: CameraCalibration | None = None,
        diameter_m: float = OBJECT_DIAMETER_M,
        fps: float = SCENE_FPS,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        assert profile.arm is not None
        self.name = "scene"
        self.period_s: float | None = 1.0 / fps
        self.finite = False
        self.arm = arm
        self.positions = positions
        self.object_at = object_at
        self.diameter_m = diameter_m
        self.clock = clock
        self.calibration = calibration if calibration is not None else default_calibration()
        self.kinematics = ArmKinematics(load_urdf(profile.urdf, meshes=False), profile.arm)
        width, height = self.calibration.size_px
        rng = np.random.default_rng(3)
        # A grey wall, lit from above, a little texture: nothing of the object's colour.
        shade = np.linspace(150, 95, height, dtype=np.float64)[:, None, None]
        noise = cv2.GaussianBlur(rng.normal(0.0, 6.0, (height, width, 1)), (0, 0), 3)[:, :, None]
        self._background = np.clip(shade + noise + np.zeros((1, 1, 3)), 0, 255).astype(np.uint8)
        self.closed = False

    def angles(self) -> dict[str, float]:
        """The arm's joint angles from the simulated shafts (rad)."""
        positions = self.positions()
        return {
            name: self.arm.angle_rad(self.arm.joint(name), positions[self.arm.joint(name).servo])
            for name in ARM_JOINTS
        }

    def camera_pose(self) -> npt.NDArray[np.float64]:
        """tool0 (the camera) in the base frame, 4x4: x forward, y left, z up."""
        return self.kinematics.tool_matrix(self.kinematics.vector(self.angles()))

    def project(self, point: Point) -> tuple[float, float, float] | None:
        """Pixel column, row and depth (m) of a world point; None behind the camera."""
        pose = self.camera_pose()
        local = pose[:3, :3].T @ (np.array(point) - pose[:3, 3])
        depth = float(local[0])
        if depth <= 1e-3:
            return None
        fx, fy = self.calibration.focal_px
        cx, cy = self.calibration.centre_px
        return cx - fx * float(local[1]) / depth, cy - fy * float(local[2]) / depth, depth

    def read(self) -> Pixels | None:
        """The picture now."""
        if self.closed:
            return None
        image = self._background.copy()
        seen = self.project(self.object_at(self.clock()))
        if seen is not None:
            u, v, depth = seen
            radius = self.calibration.focal_px[0] * self.diameter_m / 2.0 / depth
            if abs(u) < 1e5 and abs(v) < 1e5:
                centre = (round(u * 16), round(v * 16))  # sub-pixel: 4 fractional bits
                cv2.circle(
                    image, centre, max(1, round(radius * 16)), OBJECT_BGR, -1, cv2.LINE_AA, 4
                )
        return image

    def close(self) -> None:
        """Deliver nothing more."""
        self.closed = True
