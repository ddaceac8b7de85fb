"""Click-to-track in the console (seed 003 §2.2), no Qt: which joints turn a camera, and one
tracking session (the tracker on the camera's frames, the controller on the two joints).

The joints come from the robot model, never from names: of the arm's joints above the link the
camera is mounted on (`[cameras.*] mount_link`), the one nearest the base whose axis is
vertical pans the camera (the waist), the one nearest the camera whose axis is horizontal
tilts it (the neck). Their signs come from the same forward kinematics: which way each turns
the camera's view at the angles the joints stand at.

The console model (ocu.console.model) owns the channels (`Source.TRACK`) and ends the session
on any operator input, Space, a halt or LINK LOST; this module only computes.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ocu.control.tracking import CameraAxes, TrackingController, TrackingOptions
from ocu.kinematics.arm import ArmKinematics
from ocu.kinematics.chain import Chain, ChainError
from ocu.profile import CameraSettings
from ocu.records import CommandError
from ocu.video.tracker import Box, Image, Tracker, TrackerError, TrackResult, TrackState

Vector = npt.NDArray[np.float64]
# How long the object may stay lost (re-found by the tracker meanwhile) before tracking ends.
LOST_TIMEOUT_S = 3.0
# No frame for this long: the object counts as lost (the video stopped).
FRAME_TIMEOUT_S = 0.5
# Frame interval assumed until frames have come (the profile's streams ask 30 fps).
DEFAULT_FRAME_INTERVAL_S = 1.0 / 30.0
INTERVAL_FILTER = 0.1
# The box a click starts: this fraction of the frame's width, square in pixels.
CLICK_BOX_FRACTION = 0.1
# |axis . z| above this is a vertical (pan) axis, below 1 - this a horizontal (tilt) one.
VERTICAL_COS = 0.9


@dataclass(frozen=True)
class TrackView:
    """What the views draw of the tracking: the camera, the box (None: lost) and the state."""

    camera: int
    box: Box | None
    state: TrackState
    score: float


def camera_axes(
    camera: CameraSettings, arm: ArmKinematics, angles: Mapping[str, float]
) -> CameraAxes:
    """The pan and tilt joints of a camera on the arm, its focal lengths and the signs;
    CommandError when turning the joints does not move the camera."""
    mount = camera.mount
    if mount is None or mount.link is None:
        raise CommandError(
            f"camera {camera.name} is not on the arm (no [cameras.{camera.name}] mount_link): "
            "turning the joints does not move it"
        )
    try:
        chain = Chain(
            arm.tree,
            arm.settings.base_link,
            mount.link,
            variables=[j for j in arm.settings.joints if _above(arm, mount.link, j)],
        )
    except ChainError as err:
        raise CommandError(f"camera {camera.name}: {err}") from err
    chain.hold(angles)
    q = chain.vector(angles)
    axes, _ = chain.axes(q)
    vertical = [i for i, (_, axis) in enumerate(axes) if abs(float(axis[2])) >= VERTICAL_COS]
    horizontal = [i for i, (_, axis) in enumerate(axes) if abs(float(axis[2])) <= 1 - VERTICAL_COS]
    if not vertical or not horizontal:
        raise CommandError(
            f"camera {camera.name}: no joint above {mount.link} both pans and tilts it"
        )
    pan, tilt = vertical[0], horizontal[-1]
    pan_sign, tilt_sign = _signs(chain, q, (pan, tilt), (mount.yaw_rad, mount.pitch_rad))
    calibration = camera.calibration
    if calibration is not None:
        focal, size = calibration.focal_px, calibration.size_px
    else:
        # Uncalibrated: a 90-degree wide view (the simulator's default) is assumed.
        size = (640, 480)
        focal = (320.0, 320.0)
    return CameraAxes(
        pan_joint=chain.joints[pan],
        tilt_joint=chain.joints[tilt],
        focal_px=focal,
        size_px=size,
        pan_sign=pan_sign,
        tilt_sign=tilt_sign,
    )


def _above(arm: ArmKinematics, link: str, joint: str) -> bool:
    while (parent := arm.tree.parent_joint(link)) is not None:
        if parent.name == joint:
            return True
        link = parent.parent
    return False


def _view(chain: Chain, q: Vector, yaw_rad: float, pitch_rad: float) -> tuple[float, float]:
    """The camera's view direction in the base frame as (yaw left, pitch down)."""
    rotation = chain.forward(q)[:3, :3]
    local = np.array(
        [
            math.cos(yaw_rad) * math.cos(pitch_rad),
            math.sin(yaw_rad) * math.cos(pitch_rad),
            -math.sin(pitch_rad),
        ]
    )
    forward = rotation @ local
    return math.atan2(forward[1], forward[0]), -math.asin(max(-1.0, min(1.0, forward[2])))


def _signs(
    chain: Chain, q: Vector, joints: tuple[int, int], mount: tuple[float, float]
) -> tuple[float, float]:
    """The direction of each joint that turns the view right (pan) and down (tilt)."""
    pan, tilt = joints
    yaw_rad, pitch_rad = mount
    step = 1e-3
    yaw0, pitch0 = _view(chain, q, yaw_rad, pitch_rad)
    moved = q.copy()
    moved[pan] += step
    yaw1, _ = _view(chain, moved, yaw_rad, pitch_rad)
    moved = q.copy()
    moved[tilt] += step
    _, pitch1 = _view(chain, moved, yaw_rad, pitch_rad)
    pan_sign = -1.0 if yaw1 > yaw0 else 1.0  # + turns left: right is -
    tilt_sign = 1.0 if pitch1 > pitch0 else -1.0
    return pan_sign, tilt_sign


class TrackSession:
    """One object followed in one camera: the tracker and the controller of two joints."""

    # A part of the console model: the GUI reaches it under the model's lock (ocu.core.guard).
    guarded = True

    def __init__(
        self,
        camera: int,
        axes: CameraAxes,
        channels: tuple[str, str],
        limits_rad_s: tuple[float, float],
        options: TrackingOptions | None = None,
    ) -> None:
        self.camera = camera
        self.axes = axes
        # The pan and the tilt joint's velocity channels (a ReachTrackSession's: four).
        self.channels: tuple[str, ...] = channels
        self.tracker = Tracker()
        self.controller = TrackingController(axes, limits_rad_s, options)
        self.result = TrackResult(TrackState.IDLE, None, 0.0)
        self.lost_since: float | None = None
        self.last_frame_at: float | None = None
        # Mean time between frames: the loop sees the joints' effect this much later again.
        self.frame_interval_s = DEFAULT_FRAME_INTERVAL_S
        self.frames = 0
        self.update_ms = 0.0

    def start(self, pixels: Image, box: Box, now: float) -> None:
        """Follow what is inside `box` of this frame; CommandError if it cannot be followed."""
        try:
            self.tracker.start(pixels, box)
        except TrackerError as err:
            raise CommandError(str(err)) from err
        self.result = TrackResult(TrackState.TRACKING, self.tracker.box, 1.0)
        self.last_frame_at = now

    def frame_age(self, now: float) -> float:
        """Time since the last frame was tracked."""
        return 0.0 if self.last_frame_at is None else max(0.0, now - self.last_frame_at)

    def mark_lost(self, now: float) -> None:
        """The object counts as lost from now (no frames); the joints stop."""
        if self.lost_since is None:
            self.lost_since = now
        self.controller.stop()

    def on_frame(
        self,
        pixels: Image,
        taken_at: float,
        angles_at_capture: Mapping[str, float],
        now: float,
    ) -> TrackResult:
        """The tracker on one frame; a measurement for the controller when the object is seen."""
        started = time.perf_counter()
        result = self.tracker.update(pixels)
        self.update_ms = (time.perf_counter() - started) * 1000.0
        self.result = result
        self.frames += 1
        if self.last_frame_at is not None and now > self.last_frame_at:
            interval = now - self.last_frame_at
            self.frame_interval_s += INTERVAL_FILTER * (interval - self.frame_interval_s)
        self.last_frame_at = now
        if result.box is not None:
            self.lost_since = None
            self.controller.on_measurement(result.box.centre, taken_at, angles_at_capture)
        else:
            if self.lost_since is None:
                self.lost_since = now
            # Nothing to steer by: the joints stop where they are (no stale target chased).
            self.controller.stop()
        return result

    def lost_for(self, now: float) -> float:
        """How long the object has been lost (0 while it is seen)."""
        return 0.0 if self.lost_since is None else max(0.0, now - self.lost_since)

    def dead_time_s(self, round_trip_s: float | None) -> float | None:
        """The loop's dead time: the link's round trip (command up, picture down) plus a
        frame interval (a picture is a sample; it waits for the next one on average half an
        interval, and the command for the control tick); None while the round trip is unknown."""
        if round_trip_s is None:
            return None
        return round_trip_s + self.frame_interval_s

    def velocities(
        self, now: float, eventual: Mapping[str, float], round_trip_s: float | None
    ) -> dict[str, float]:
        """The two channels' velocities now (zero without a target)."""
        joint_velocities = self.controller.update(now, eventual, self.dead_time_s(round_trip_s))
        pan_channel, tilt_channel = self.channels
        return {
            pan_channel: joint_velocities.get(self.axes.pan_joint, 0.0),
            tilt_channel: joint_velocities.get(self.axes.tilt_joint, 0.0),
        }

    def view(self) -> TrackView:
        """What to draw."""
        return TrackView(self.camera, self.result.box, self.result.state, self.result.score)


def click_box(point: tuple[float, float], frame_size_px: tuple[int, int]) -> Box:
    """The box a click at a normalised point starts: square in pixels, a tenth of the width."""
    width, height = frame_size_px
    return Box.around(point, CLICK_BOX_FRACTION, width / max(height, 1))
