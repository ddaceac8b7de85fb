"""Click-to-track, a part of the console model: the operator clicks an object in a camera's
picture and the joints that carry that camera keep it centred (`Source.TRACK`); any operator
input, an e-stop, a halt, LINK LOST or the object lost for too long ends it. The session
itself (tracker, controller, what to draw) is ocu.console.tracking's `TrackSession`; a camera
on the tool of the seed's arm (the xArm 1S) gets ocu.console.reach_tracking's, which moves the
base, the height and the reach as seed 003 does."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from ocu.console.channels import Source
from ocu.console.part import ModelPart
from ocu.console.reach_tracking import ReachTrackSession, camera_model, reach_camera
from ocu.console.tracking import (
    FRAME_TIMEOUT_S,
    LOST_TIMEOUT_S,
    TrackSession,
    TrackView,
    camera_axes,
    click_box,
)
from ocu.control.reach_tracking import ReachOptions, ServoModel
from ocu.profile import CameraSettings
from ocu.records import CommandError, LinkState
from ocu.video.tracker import TrackState


class ClickToTrack(ModelPart):
    """Start, feed, step and stop a tracking session (the video view calls these)."""

    # Seed 003's tracking with a camera on the tool (ocu.control.reach_tracking): the
    # servo's model its gains account for (the xArm's: set by whoever builds the console),
    # and what of the controller acts (the benchmark's baseline switches parts off).
    servo_model: ServoModel | None = None
    reach_options: ReachOptions = ReachOptions()

    # ---- click-to-track (ocu.console.tracking; the video view calls these) -----------------

    @property
    def tracking(self) -> TrackView | None:
        """What is tracked and where it was last seen (None: not tracking)."""
        return None if self._tracking is None else self._tracking.view()

    @property
    def tracking_session(self) -> TrackSession | None:
        """The tracking session (for its numbers: frames, update time); None when idle."""
        return self._tracking

    def start_tracking(
        self, camera: int, pixels: npt.NDArray[np.uint8], point: tuple[float, float]
    ) -> None:
        """Follow the object at a normalised point (0..1) of a camera's frame (BGR or BGRA)
        by turning the joints that carry the camera; CommandError, nothing changed, if it
        cannot be done (a camera on the chassis, no arm, no readings yet, a bad point)."""
        if self.arm is None:
            raise CommandError(self.arm_error or "this robot has no arm to turn a camera")
        if not 0 <= camera < len(self.profile.cameras):
            raise CommandError(f"no camera {camera}")
        if not all(0.0 <= v <= 1.0 and math.isfinite(v) for v in point):
            raise CommandError(f"point {point!r} outside the frame")
        now = self.clock()
        angles = self.controller.predicted_angles(now)
        settings = self.profile.cameras[camera]
        kinematics = self.arm.controller.kinematics
        session: TrackSession
        if reach_camera(settings, kinematics):
            # Seed 003's rig: the camera on the tool; base, height and reach follow.
            session = self._reach_session(camera, settings, angles)
            joints = session.reach.kinematics.joints
            text = "the base, the height and the reach"
        else:
            axes = camera_axes(settings, kinematics, angles)
            joints = (axes.pan_joint, axes.tilt_joint)
            pan, tilt = (self.controller.channel_of(joint) for joint in joints)
            session = TrackSession(
                camera,
                axes,
                (pan, tilt),
                (self.limits.get(pan), self.limits.get(tilt)),
                self.tracking_options,
            )
            text = f"the {axes.pan_joint} and {axes.tilt_joint}"
        missing = [j for j in joints if j not in angles]
        if missing:
            raise CommandError(f"no reading of {', '.join(missing)} yet")
        channels = session.channels
        height, width = pixels.shape[:2]
        session.start(pixels, click_box(point, (width, height)), now)
        self._end_tracking("a new object was clicked", quiet=True)
        # Starting is the operator's act: it ends an e-stop latch, a planner, an assisted mode.
        self._operator_acted()
        for channel in channels:
            self._take_manual(channel)
            self._set_channel(channel, 0.0, Source.TRACK)
        self._tracking = session
        name = self.profile.cameras[camera].name
        self.events.tracking_changed.emit(session.view())
        self.events.message.emit(
            f"tracking in the {name} camera with {text}: any motion input, Space or Esc takes over"
        )
        self._publish()

    def _reach_session(
        self, camera: int, settings: CameraSettings, angles: Mapping[str, float]
    ) -> ReachTrackSession:
        """Seed 003's session for a camera on the tool (ocu.console.reach_tracking)."""
        assert self.arm is not None
        kinematics = self.arm.controller.kinematics
        channels = {joint: self.controller.channel_of(joint) for joint in kinematics.joints}
        link = self.profile.link
        return ReachTrackSession(
            camera,
            kinematics,
            camera_model(settings),
            channels,
            {joint: self.limits.get(channel) for joint, channel in channels.items()},
            servo=self.servo_model,
            options=self.reach_options,
            # The link turns velocities into moves at its send rate (the xArm: its jog period).
            move_period_s=1.0 / link.send_rate_hz,
        )

    def on_tracking_frame(
        self, camera: int, pixels: npt.NDArray[np.uint8], received_at: float
    ) -> None:
        """A decoded frame of a camera: the tracker follows the object in it."""
        session = self._tracking
        if session is None or camera != session.camera:
            return
        now = self.clock()
        # The picture was taken about half a round trip before it arrived.
        taken_at = received_at - (self.controller.delay_s or 0.0) / 2.0
        was = session.result.state
        result = session.on_frame(pixels, taken_at, self.controller.predicted_angles(taken_at), now)
        if result.state is not was:
            if result.state is TrackState.LOST:
                self.events.message.emit("tracking: object LOST, searching the whole frame")
            elif result.refound:
                self.events.message.emit("tracking: object found again")
        self.events.tracking_changed.emit(session.view())

    def stop_tracking(self, reason: str = "operator") -> bool:
        """End the tracking; its channels stop. True if it was running."""
        ended = self._end_tracking(reason)
        self._publish()
        return ended

    def _end_tracking(self, reason: str, *, quiet: bool = False) -> bool:
        session = self._tracking
        if session is None:
            return False
        self._tracking = None
        for channel in session.channels:
            if self._requested(channel).source is Source.TRACK:
                self._set_channel(channel, 0.0, Source.NONE)
        self.events.tracking_changed.emit(None)
        if not quiet:
            self.events.message.emit(f"tracking stopped: {reason}")
        return True

    def _tracking_tick(self, now: float) -> None:
        session = self._tracking
        if session is None:
            return
        if self.robot.link_state is LinkState.LOST:
            self._end_tracking("LINK LOST")
            return
        if session.frame_age(now) > FRAME_TIMEOUT_S:
            session.mark_lost(now)  # no pictures: nothing to steer by
        lost_s = session.lost_for(now)
        if lost_s >= LOST_TIMEOUT_S:
            self._end_tracking(f"object lost for {lost_s:.1f} s")
            return
        eventual = self.controller.eventual_angles(now)
        for channel, velocity in session.velocities(now, eventual, self.controller.delay_s).items():
            if self._requested(channel).source is Source.TRACK:
                self._set_channel(channel, self.limits.clamp(channel, velocity), Source.TRACK)
        if isinstance(session, ReachTrackSession) and session.reach.reason != session.said:
            # Why the arm stopped following in height and reach (out of reach, the table).
            session.said = session.reach.reason
            self.events.message.emit(
                f"tracking: the base only: {session.said}"
                if session.said
                else "tracking: height and reach follow again"
            )
