"""`ocu --camera DEVICE|INDEX|FILE|scene`: cameras of the OCU's own machine in the Video dock.

Any robot: the cameras are added to the profile after the robot's own (ocu.video.capture:
`with_camera`; the robot's protocol never hears of them), each read by a `CameraCapture` on
its own thread and fed to the link adapter's decoder, so the Video dock shows, corrects,
snapshots and tracks them as the robot's cameras. On the xArm the first camera rides on the
gripper (tool0, looking along the tool: seed 003's rig), so click-to-track moves the base,
the height and the reach. `scene` is the synthetic camera on the simulated xArm's gripper
(ocu.sim.xarm_camera): the in-process simulator starts with the arm looking ahead at a red
disc that sways in front of it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

from ocu.control.reach_tracking import ServoModel
from ocu.hardware.xarm import ConsoleLinks
from ocu.profile import CameraMount, RobotProfile
from ocu.profile.xarm import XarmProfile
from ocu.sim.xarm import XarmSimulator
from ocu.sim.xarm_camera import LOOKING_AHEAD_DEG, OBJECT_AHEAD, SceneCamera, swaying
from ocu.video.capture import (
    CameraCapture,
    CameraError,
    FrameSource,
    OpenCvSource,
    camera_target,
    with_camera,
)

if TYPE_CHECKING:
    from ocu.windows.main_window import MainWindow

SCENE = "scene"
# The demo scene's object: about the point ahead, 30 mm each way across, 15 up and down.
SCENE_SWAY_M = (0.015, 0.03, 0.015)
SCENE_PERIOD_S = 12.0


def camera_name(text: str) -> str:
    """The name the Video dock shows: 'usb' for a device or an index, a file's stem."""
    if text == SCENE:
        return SCENE
    target = camera_target(text)
    if isinstance(target, int) or target.startswith("/dev/"):
        return "usb"
    return Path(target).stem or "file"


def add_cameras(
    profile: RobotProfile, texts: list[str], *, tool_link: str | None = None
) -> RobotProfile:
    """The profile with the cameras given; the first on `tool_link` (the xArm's gripper)."""
    for index, text in enumerate(texts):
        mount = None
        if tool_link is not None and index == 0:
            mount = CameraMount((0.0, 0.0, 0.0), link=tool_link)
        profile = with_camera(profile, camera_name(text), mount=mount)
    return profile


class SceneLinks(ConsoleLinks):
    """The xArm simulator in this process, its arm looking ahead at the scene's object."""

    def __init__(self, arm: XarmProfile, profile: RobotProfile) -> None:
        # Not ConsoleLinks.__init__: the same attributes, a simulator started bent.
        self.arm = arm
        self.profile = profile
        initial = {
            arm.joint(name).servo: arm.raw_units(arm.joint(name), math.radians(deg))
            for name, deg in LOOKING_AHEAD_DEG.items()
        }
        self.simulator: XarmSimulator | None = XarmSimulator(arm, initial=initial)
        self.path = self.simulator.start()
        self.where = f"xArm simulator on {self.path}, scene camera"
        # Where the scene's object is at any moment (every camera of the scene sees the same).
        self.object_at = swaying(OBJECT_AHEAD, SCENE_SWAY_M, SCENE_PERIOD_S)

    def scene_camera(self) -> SceneCamera:
        """The synthetic camera on the simulated gripper."""
        simulator = self.simulator
        assert simulator is not None
        return SceneCamera(
            self.arm,
            self.profile,
            lambda: simulator.snapshot().positions,
            self.object_at,
        )


class LocalCameras:
    """The captures of `--camera`, opened before the window (a camera that cannot be opened
    stops the start, named); attached to the window's Video dock, stopped at the end."""

    def __init__(
        self,
        profile: RobotProfile,
        texts: list[str],
        *,
        scene: SceneLinks | None = None,
        servo: ServoModel | None = None,
    ) -> None:
        self.servo = servo
        self.captures: list[CameraCapture] = []
        first = len(profile.cameras) - len(texts)
        try:
            for index, text in enumerate(texts):
                source: FrameSource
                if text == SCENE:
                    if scene is None:
                        raise CameraError(
                            "camera scene: only on the xArm's simulator in this process "
                            "(--profile xarm1s without --robot)"
                        )
                    source = scene.scene_camera()
                else:
                    source = OpenCvSource(camera_target(text))
                self.captures.append(CameraCapture(source, first + index))
        except CameraError:
            self.stop()
            raise

    def attach(self, window: MainWindow) -> None:
        """Show the cameras in the window's Video dock and start reading them."""
        if not self.captures:
            return
        if self.servo is not None:
            window.model.servo_model = self.servo  # the tracking's gains know the servo
        for capture in self.captures:
            window.video_panel.add_capture(capture)
            capture.start()

    def stop(self) -> None:
        """Stop every capture; idempotent."""
        for capture in self.captures:
            capture.stop()
