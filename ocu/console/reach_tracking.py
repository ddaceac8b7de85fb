"""Click-to-track with a camera on the tool of a yaw + three-pitch arm (the xArm 1S), no Qt:
seed 003's base, height and reach (ocu.control.reach_tracking) in a console tracking session.

`reach_camera` tells such a camera from the Engineer's head camera (ocu.console.tracking):
mounted on the arm's tool link, on an arm whose IK is the seed's closed form. The session is
a `TrackSession` (the console model starts, feeds, steps and ends it as the Engineer's: the
same source, `Source.TRACK`, the same stops) whose measurement is the object's colour blob
(ocu.video.blob: its centre and its size) and whose controller moves the four arm joints.
"""

from __future__ import annotations

import time
from collections.abc import Mapping

from ocu.console.tracking import TrackSession
from ocu.control.reach_tracking import CameraModel, ReachController, ReachOptions, ServoModel
from ocu.kinematics.arm import ArmKinematics
from ocu.profile import CameraSettings
from ocu.records import CommandError
from ocu.video.blob import BlobError, ColourBlob
from ocu.video.tracker import Box, Image, TrackResult, TrackState

DEFAULT_FRAME_INTERVAL_S = 1.0 / 30.0
INTERVAL_FILTER = 0.1
# The box drawn around the blob: its diameter times this.
BOX_MARGIN = 1.2


def reach_camera(camera: CameraSettings, kinematics: ArmKinematics) -> bool:
    """Whether the camera sits on the tool of an arm the seed's IK solves (seed 003's rig)."""
    mount = camera.mount
    return (
        mount is not None
        and mount.link == kinematics.settings.tool_link
        and kinematics.analytic is not None
    )


def camera_model(camera: CameraSettings) -> CameraModel:
    """The camera's size and focal lengths (a 90° view when uncalibrated, as the Engineer's)."""
    calibration = camera.calibration
    if calibration is None:
        return CameraModel((640, 480), (320.0, 320.0))
    return CameraModel(calibration.size_px, calibration.focal_px)


class ReachTrackSession(TrackSession):
    """One object followed by the arm carrying the camera (seed 003): four joints' channels."""

    def __init__(
        self,
        camera: int,
        kinematics: ArmKinematics,
        model: CameraModel,
        channels: Mapping[str, str],
        limits_rad_s: Mapping[str, float],
        *,
        servo: ServoModel | None = None,
        options: ReachOptions | None = None,
        move_period_s: float = 0.0,
    ) -> None:
        # Not TrackSession.__init__: no pan and tilt joints here; the attributes it keeps are
        # set below, its controller is this one.
        self.camera = camera
        self.joints = tuple(kinematics.joints)
        self.channels = tuple(channels[joint] for joint in self.joints)
        self.reach = ReachController(kinematics, model, limits_rad_s, servo=servo, options=options)
        self.blob: ColourBlob | None = None
        self.result = TrackResult(TrackState.IDLE, None, 0.0)
        self.lost_since: float | None = None
        self.last_frame_at: float | None = None
        self.frame_interval_s = DEFAULT_FRAME_INTERVAL_S
        self.frames = 0
        self.update_ms = 0.0
        # The link turns velocities into moves this often: a command waits half of it.
        self.move_period_s = move_period_s
        # The controller's reason last told the operator (the console model says it once).
        self.said = ""

    def start(self, pixels: Image, box: Box, now: float) -> None:
        """Follow the coloured object at the box's centre; CommandError if it has no colour."""
        try:
            self.blob = ColourBlob(pixels, box.centre)
        except BlobError as err:
            raise CommandError(str(err)) from err
        blob = self.blob.last
        assert blob is not None
        self.result = TrackResult(TrackState.TRACKING, _box(blob.centre, blob.size, pixels), 1.0)
        self.last_frame_at = now

    def mark_lost(self, now: float) -> None:
        """The object counts as lost from now (no frames); the joints stop."""
        if self.lost_since is None:
            self.lost_since = now
        self.reach.stop()

    def on_frame(
        self,
        pixels: Image,
        taken_at: float,
        angles_at_capture: Mapping[str, float],
        now: float,
    ) -> TrackResult:
        """The blob in one frame; a measurement for the controller when it is seen."""
        started = time.perf_counter()
        assert self.blob is not None
        was = self.result.state
        blob = self.blob.measure(pixels)
        self.update_ms = (time.perf_counter() - started) * 1000.0
        self.frames += 1
        if self.last_frame_at is not None and now > self.last_frame_at:
            interval = now - self.last_frame_at
            self.frame_interval_s += INTERVAL_FILTER * (interval - self.frame_interval_s)
        self.last_frame_at = now
        if blob is None:
            if self.lost_since is None:
                self.lost_since = now
            self.reach.stop()  # nothing to steer by: no stale target chased
            self.result = TrackResult(TrackState.LOST, None, 0.0)
            return self.result
        self.lost_since = None
        if not blob.at_edge:  # cut by the edge: seen, but its size says nothing of its distance
            self.reach.on_measurement(blob.centre, blob.size, taken_at, angles_at_capture)
        self.result = TrackResult(
            TrackState.TRACKING, _box(blob.centre, blob.size, pixels), 1.0, was is TrackState.LOST
        )
        return self.result

    def dead_time_s(self, round_trip_s: float | None) -> float | None:
        """The loop's dead time: the round trip (0 when the link reports none: a serial line's
        is a few ms), a frame interval and half the link's move period."""
        return (round_trip_s or 0.0) + self.frame_interval_s + self.move_period_s / 2.0

    def velocities(
        self, now: float, eventual: Mapping[str, float], round_trip_s: float | None
    ) -> dict[str, float]:
        """The four channels' velocities now (zero without a target)."""
        joint_velocities = self.reach.update(now, eventual, self.dead_time_s(round_trip_s))
        return {
            channel: joint_velocities.get(joint, 0.0)
            for joint, channel in zip(self.joints, self.channels, strict=True)
        }


def _box(centre: tuple[float, float], size: float, pixels: Image) -> Box:
    height, width = pixels.shape[:2]
    side = min(1.0, size * BOX_MARGIN)
    return Box.around(centre, side, width / max(height, 1))
