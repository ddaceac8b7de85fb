"""The console model: the whole command and what is known of the robot (no Qt, napari-style).

It owns the one command the link sends — every channel's velocity with its source (a slider, a
text box, a hotkey, a switch, the game controller, the position controller, a planner through
ROS, an assisted mode), the torch, the selected camera, the video bit-rate, the per-camera
stream request — bounded by the one set of velocity limits; and the robot's state (`robot`,
ocu.console.robot). The latest manual input on a channel wins: it takes the joint back from the
position controller and the channel back from ROS. Views subscribe to `events` and
`robot.events` and write the operator's input back through the methods below; the window sends
`command()` to the link whenever `events.command_changed` fires and never reads a command back
from the link.

The arm (`arm`, ocu.console.arm) moves its joints' channels as one more automatic source,
`ARM`: Cartesian jogs, pose goals and stored poses. Space, a lost link and any manual input on
an arm channel stop it at once; a move (not a jog, which is the operator's own keys) also
stops for any other operator motion input.

Stops come in two strengths. `emergency_stop()` asks the link for its e-stop burst, zeroes
everything and latches: the model commands nothing until the operator acts again (a key
press, a slider move, Accept, a switch, a new target). `halt()` zeroes everything without the
burst, for focus loss, minimising, a stalled GUI thread, a lost or closed link.

Driving with a map (`nav`, ocu.nav.navigator): odometry, scans and the occupancy grid are
fed from the link; the drive pair, composed from whichever source commands it, passes the
safety zones last, so every input is slowed near an obstacle; the assisted modes are one more
automatic source, run in `update()` (driving.py says more).

This module holds the core: the state, the channels and how a command is composed and
published, the operator's sliders, typed values, switches and hotkeys, position targets, the
stops and `update()`. `ConsoleModel` inherits its parts, one module each: driving.py (the
drive pair through the zones, waypoints, the assisted modes), clicktrack.py (click-to-track),
inputs.py (the game controller, a planner through ROS, the arm's channels) and video.py (the
camera, bit-rate and streams asked for); part.py declares what the parts use of the core,
channels.py what they all share (`Source`, `ChannelCommand`, `ConsoleEvents`, imported here
too).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from pathlib import Path

from ocu.console.arbitration import Arbitration
from ocu.console.arm import ArmConsole
from ocu.console.channels import (
    MANUAL_SOURCES,
    PAD_AT_REST,
    ChannelCommand,
    ConsoleEvents,
    PadWish,
    Source,
    check_finite,
)
from ocu.console.clicktrack import ClickToTrack
from ocu.console.driving import Driving
from ocu.console.inputs import InputSources
from ocu.console.robot import RobotState
from ocu.console.tracking import TrackSession
from ocu.console.video import VideoRequest
from ocu.control.arm import ArmController
from ocu.control.commands import VelocityLimits
from ocu.control.mux import InputMux
from ocu.control.position import PositionController, PositionError
from ocu.control.tracking import TrackingOptions
from ocu.kinematics.arm import ArmError, ArmKinematics
from ocu.model.urdf import UrdfError, load_urdf
from ocu.nav.navigator import Navigator
from ocu.profile import RobotProfile
from ocu.records import (
    CameraRequest,
    Command,
    CommandError,
    LinkState,
    LinkStats,
    ScanFrame,
    StatusFrame,
    TelemetryFrame,
)

__all__ = [
    "DEFAULT_FINE_FACTOR",
    "MANUAL_SOURCES",
    "PAD_AT_REST",
    "ChannelCommand",
    "ConsoleEvents",
    "ConsoleModel",
    "PadWish",
    "Source",
]

log = logging.getLogger("ocu.console")

DEFAULT_FINE_FACTOR = 0.25


class ConsoleModel(Arbitration, Driving, ClickToTrack, InputSources, VideoRequest):
    """The command (channels, switches, camera, bit-rate, streams), e-stop latch, targets,
    hotkeys and Shift, the velocity limits, and the robot's state."""

    def __init__(
        self,
        profile: RobotProfile,
        *,
        fine_factor: float = DEFAULT_FINE_FACTOR,
        clock: Callable[[], float] = time.monotonic,
        arm: ArmKinematics | None = None,
        arm_poses_path: Path | None = None,
        mux: InputMux | None = None,
    ) -> None:
        if not 0.0 < fine_factor <= 1.0:
            raise ValueError(f"fine_factor must be in (0, 1], got {fine_factor!r}")
        self.profile = profile
        self.clock = clock
        self.events = ConsoleEvents()
        self.robot = RobotState(profile, clock=clock)
        self.limits = VelocityLimits(profile)
        self.controller = PositionController(profile, self.limits)
        self.fine_factor = fine_factor
        self._channels = {name: ChannelCommand() for name in profile.channels}
        # What the operator asked of the two drive channels; `_channels` holds what is sent:
        # both scaled by one factor so the turn radius is kept (ocu.control.drive).
        self._drive = profile.drive_channels
        self._drive_request = {name: ChannelCommand() for name in self._drive or ()}
        self._hotkey_speed: dict[str, float | None] = dict.fromkeys(profile.channels)
        self._held: dict[str, tuple[str, int]] = {}
        self._fine = False
        self._torch = False
        # The video the robot is asked for: the selected camera (the vendor protocol streams
        # one), the RCP's bit-rate field, and per camera what an extended robot sends.
        self._camera: int | None = None
        self._bitrate = profile.link.default_video_bitrate
        extension = profile.extension
        self._streams: tuple[CameraRequest, ...] = (
            tuple(
                CameraRequest(
                    camera=index,
                    width_px=extension.stream_width_px,
                    height_px=extension.stream_height_px,
                    fps=extension.stream_fps,
                )
                for index in range(len(profile.link.camera_names))
            )
            if extension is not None
            else ()
        )
        # The game controller's wish per channel it maps, and the channels it must leave
        # alone until its wish is back at rest (another input took them meanwhile).
        self._pad: dict[str, PadWish] = {}
        self._pad_blocked: set[str] = set()
        self._estopped = False
        self._estop_reason = ""
        self._connected = True
        self._help_visible = False
        self._targets: dict[str, float] = {}
        self.nav = Navigator(profile, clock=clock)
        # A new connection starts without range data: zones off until a scan, not blind.
        self.robot.events.link_state_changed.connect(
            lambda state, _reason: (
                self.nav.forget_scans() if state is LinkState.CONNECTING else None
            ),
            direct=True,
        )
        self._waypoints: tuple[tuple[float, float], ...] = ()
        self._shuttle: tuple[tuple[float, float], ...] = ()
        self._zone_text = ""
        self._zone_limiting = False
        self._published: tuple[dict[str, float], bool, int | None, float] = (
            {},
            False,
            None,
            self._bitrate,
        )
        self._published_ends: dict[str, float] = {}
        self._tracking: TrackSession | None = None
        # What of the tracking controller acts (the benchmark's baseline switches parts off).
        self.tracking_options = TrackingOptions()
        # The arm in Cartesian space; None when the profile has no [arm] table, or its URDF
        # cannot carry it (`arm_error` says why).
        self.arm: ArmConsole | None = None
        self.arm_error = ""
        if profile.arm is not None:
            try:
                kinematics = arm or ArmKinematics(
                    load_urdf(profile.urdf, meshes=False), profile.arm
                )
                controller = ArmController(profile, self.limits, kinematics, self.controller)
            except (ArmError, UrdfError) as err:
                self.arm_error = f"the arm's Cartesian control is off: {err}"
                log.warning("%s", self.arm_error)
            else:
                self.arm = ArmConsole(controller, self, arm_poses_path)
                self.arm.events.message.connect(self.events.message.emit, direct=True)
        # Who may command a channel and what stops whom: the table ocu/control/mux.md.
        self._init_mux(mux)

    # ---- state -----------------------------------------------------------------------------

    def channel(self, name: str) -> ChannelCommand:
        """The command of one channel."""
        return self._channels[name]

    @property
    def channels(self) -> dict[str, ChannelCommand]:
        """A copy of every channel's command."""
        return dict(self._channels)

    def velocities(self) -> dict[str, float]:
        """The non-zero commanded velocities (empty while e-stopped)."""
        if self._estopped:
            return {}
        return {name: c.velocity for name, c in self._channels.items() if c.velocity != 0.0}

    def command(self) -> Command:
        """The command for the link: every channel's velocity and the switches, and when
        the link is to end the position controller's motions by itself."""
        velocities = self.velocities()
        ends = self._ends(velocities)
        goals = dict(self.arm.controller.goals) if self.arm is not None else {}
        goals.update(g for _, timed in self._source_ends.values() for g in timed.items())
        return Command(
            velocities=velocities,
            torch=self._torch,
            camera=self._camera,
            video_bitrate=self._bitrate,
            until=ends,
            goals={channel: goal for channel, goal in goals.items() if channel in ends},
        )

    def _ends(self, velocities: Mapping[str, float]) -> dict[str, float]:
        """The position controller's and the arm's channels that end by themselves, and when
        (the arm's timed move: ocu.control.arm_timed)."""
        timed = [(Source.POSITION, self.controller.until)]
        timed += [(Source.ARM, self.arm.controller.until)] if self.arm is not None else []
        timed += [(source, until) for source, (until, _) in self._source_ends.items()]
        return {
            channel: at
            for source, ends in timed
            for channel, at in ends.items()
            if channel in velocities and self._channels[channel].source is source
        }

    @property
    def is_moving(self) -> bool:
        """Whether any channel is commanded to move."""
        return bool(self.velocities())

    @property
    def estopped(self) -> bool:
        """Whether an emergency stop holds until the operator acts again."""
        return self._estopped

    @property
    def estop_reason(self) -> str:
        """What triggered the latched emergency stop ('' when none)."""
        return self._estop_reason

    @property
    def torch(self) -> bool:
        """Whether the headlight is asked to be on."""
        return self._torch

    @property
    def fine(self) -> bool:
        """Whether hotkeys move at the fine fraction of their speed (Shift held)."""
        return self._fine

    @property
    def held_keys(self) -> frozenset[str]:
        """Names of the hotkeys held now (the arm's jog keys included)."""
        jog = self.arm.held_keys if self.arm is not None else frozenset()
        return frozenset(self._held) | jog

    @property
    def targets(self) -> dict[str, float]:
        """Joint name to target angle (rad) for every joint under position control."""
        return dict(self._targets)

    @property
    def connected(self) -> bool:
        """Whether the operator wants the link up."""
        return self._connected

    @property
    def help_visible(self) -> bool:
        """Whether the hotkey help overlay is shown."""
        return self._help_visible

    def max_velocity(self, channel: str) -> float:
        """Current maximum of a channel (bounds its slider and its hotkey speed)."""
        return self.limits.get(channel)

    def hotkey_speed(self, channel: str) -> float:
        """Speed of a channel's hotkeys: the set value, or the maximum by default."""
        speed = self._hotkey_speed[channel]
        limit = self.limits.get(channel)
        return limit if speed is None else min(speed, limit)

    def fine_speed(self, channel: str) -> float:
        """Hotkey speed with Shift: a fraction, but not below the speed that moves the servo.

        The drive channels are lifted as a pair when the command is composed (the turn
        radius is kept), not one by one here.
        """
        speed = self.hotkey_speed(channel)
        if channel in self._drive_request:
            return speed * self.fine_factor
        floor = min(self.profile.channels[channel].min_speed, speed)
        return max(speed * self.fine_factor, floor)

    # ---- operator input --------------------------------------------------------------------

    def set_velocity(self, channel: str, value: float, source: Source = Source.SLIDER) -> float:
        """A manual velocity for one channel, bounded by its maximum; returns the value kept."""
        return self.set_velocities({channel: value}, source)[channel]

    def set_velocities(
        self, values: Mapping[str, float], source: Source = Source.TEXT
    ) -> dict[str, float]:
        """Several manual velocities at once (Accept); all are checked before any applies."""
        if source not in (Source.SLIDER, Source.TEXT):
            raise ValueError(f"set_velocities takes slider or text input, not {source.value}")
        checked = {}
        for channel, raw in values.items():
            self._check_channel(channel)
            value = check_finite(channel, raw)
            # The drive pair is bounded together when it is composed (turn radius kept).
            drive = channel in self._drive_request
            checked[channel] = value if drive else self.limits.clamp(channel, value)
        self._operator_acted()
        for channel, value in checked.items():
            self._take_manual(channel)
            self._set_channel(channel, value, source)
        self._publish()
        return {channel: self._channels[channel].velocity for channel in checked}

    def set_switch(self, channel: str, direction: int) -> None:
        """Flipper/gripper switch: move at the hotkey speed in a direction (+1, -1) or stop (0)."""
        self._check_channel(channel)
        if direction not in (-1, 0, 1):
            raise ValueError(f"switch direction must be -1, 0 or 1, got {direction!r}")
        self._operator_acted()
        self._take_manual(channel)
        if direction:
            self._set_channel(channel, direction * self.hotkey_speed(channel), Source.SWITCH)
        else:
            self._set_channel(channel, 0.0, Source.NONE)
        self._publish()

    def hotkey_down(self, key: str, channel: str, direction: int) -> bool:
        """A hold-to-move key went down; False if it was already held."""
        self._check_channel(channel)
        if direction not in (-1, 1):
            raise ValueError(f"hotkey direction must be -1 or 1, got {direction!r}")
        if key in self._held:
            return False
        self._operator_acted()
        self._take_manual(channel, keep_keys=True)
        self._held[key] = (channel, direction)
        self._apply_hotkeys(channel)
        self._publish()
        self.events.held_changed.emit(self.held_keys)
        return True

    def arm_jog_down(self, key: str, axis: str, direction: int) -> bool:
        """A Cartesian jog key went down (Cartesian mode); False if it was already held."""
        if self.arm is None or key in self._held:
            return False
        if not self.arm.jog_key_down(key, axis, direction):
            return False
        self.events.held_changed.emit(self.held_keys)
        return True

    def hotkey_up(self, key: str) -> bool:
        """A hold-to-move key went up; its channel stops unless another key still holds it."""
        if self.arm is not None and self.arm.jog_key_up(key):
            self.events.held_changed.emit(self.held_keys)
            return True
        held = self._held.pop(key, None)
        if held is None:
            return False
        self._apply_hotkeys(held[0])
        self._publish()
        self.events.held_changed.emit(self.held_keys)
        return True

    def release_hotkeys(self, reason: str = "") -> bool:
        """Release every held key (focus lost); True if any was held."""
        jogging = self.arm is not None and self.arm.release_keys()
        if jogging and not self._held:
            self.events.held_changed.emit(self.held_keys)
            if reason:
                self.events.message.emit(f"keys released: {reason}")
            return True
        if not self._held:
            return False
        channels = {channel for channel, _ in self._held.values()}
        self._held.clear()
        for channel in channels:
            self._apply_hotkeys(channel)
        self._publish()
        self.events.held_changed.emit(self.held_keys)
        if reason:
            self.events.message.emit(f"keys released: {reason}")
        return True

    def set_fine(self, fine: bool) -> None:
        """Shift held or released: hotkeys move at the fine speed."""
        if fine == self._fine:
            return
        self._fine = fine
        for channel in {channel for channel, _ in self._held.values()}:
            self._apply_hotkeys(channel)
        if self.arm is not None:
            self.arm.refresh()
        self._publish()
        self.events.fine_changed.emit(fine)

    def set_torch(self, on: bool) -> None:
        """Headlight on or off."""
        if on == self._torch:
            return
        self._torch = on
        self.events.torch_changed.emit(on)
        self._publish()

    def set_max_velocity(self, channel: str, value: float) -> float:
        """A channel's maximum, clipped to [0, hard max]; commands above it are cut down."""
        self._check_channel(channel)
        kept = self.limits.set(channel, value)
        self.events.max_changed.emit(channel, kept)
        self.events.hotkey_speed_changed.emit(channel, self.hotkey_speed(channel))
        self._rebound(channel)
        self._publish()
        return kept

    def set_hotkey_speed(self, channel: str, value: float | None) -> float:
        """Speed of a channel's hotkeys and switch (None: follow the maximum); returns it."""
        self._check_channel(channel)
        if value is not None:
            value = min(max(check_finite(channel, value), 0.0), self.limits.get(channel))
        self._hotkey_speed[channel] = value
        speed = self.hotkey_speed(channel)
        self.events.hotkey_speed_changed.emit(channel, speed)
        self._rebound(channel)
        self._publish()
        return speed

    def set_targets(self, targets_rad: Mapping[str, float]) -> None:
        """Move joints to angles (rad) at once; PositionError and nothing applied if one is bad."""
        probe = PositionController(self.profile, self.limits)
        for joint, angle_rad in targets_rad.items():
            probe.set_target(joint, angle_rad)
        if not targets_rad:
            return
        if self.arm is not None:
            # The same collision, ground and driving checks as the arm's own moves.
            try:
                self.arm.controller.check_targets(targets_rad, self.clock())
            except ArmError as err:
                raise PositionError(str(err)) from err
        self._operator_acted()
        for joint, angle_rad in targets_rad.items():
            self.controller.set_target(joint, angle_rad)
            channel = self.controller.channel_of(joint)
            self._drop_keys(channel)
            self._set_channel(channel, 0.0, Source.POSITION)
        self._sync_targets()
        self._publish()

    def set_target(self, joint: str, angle_rad: float) -> None:
        """Move one joint to an angle (rad)."""
        self.set_targets({joint: angle_rad})

    def cancel_targets(self, joint: str | None = None) -> None:
        """Drop one joint's target, or all; their channels stop."""
        self.controller.cancel(joint)
        self._sync_targets()
        for channel, command in self._channels.items():
            if command.source is Source.POSITION and self._joint_of(channel) not in self._targets:
                self._set_channel(channel, 0.0, Source.NONE)
        self._publish()

    def emergency_stop(self, reason: str = "operator") -> None:
        """Link e-stop at once, everything to zero, targets cancelled, latched until acted."""
        self.events.operator_acted.emit()
        self.events.estop_requested.emit(reason)
        self._zero_all(lock="e-stop", reason=f"EMERGENCY STOP ({reason})")
        self._estop_reason = reason
        if not self._estopped:
            self._estopped = True
            self.events.estop_changed.emit(True, reason)
        self._publish()
        self.events.message.emit(f"EMERGENCY STOP ({reason})")

    def halt(self, reason: str, *, lock: str | None = None, pad_background: bool = False) -> bool:
        """Stop motion without the e-stop burst; True if anything was moving or held.

        `lock` names a column of the mux's table (ocu/control/mux.md): "focus lost" (a
        planner the operator watches in rviz goes on, and so does the pad when
        `pad_background`: its deadman is held and its mapping lets it drive in the
        background, docs/gamepad.md), "GUI silent" (what the GUI feeds stops; position
        targets, the arm's moves, the pad and planners go on), "LINK LOST", "robot stop" (the
        robot's controller refuses motion). None: every
        source stops (the window hidden or closed, a disconnect, a stalled control thread,
        the link's own stops).
        """
        active = (
            bool(self.held_keys)
            or self.is_moving
            or bool(self._targets)
            or self._tracking is not None
        )
        self._zero_all(lock=lock, pad_background=pad_background, reason=reason)
        self._publish()
        if active:
            self.events.message.emit(f"motion stopped: {reason}")
        return active

    def set_connected(self, connected: bool) -> None:
        """The operator connects or disconnects; disconnecting stops all motion first."""
        if connected == self._connected:
            return
        if not connected:
            self.halt("disconnected")
        self._connected = connected
        self.events.connection_changed.emit(connected)

    def set_help_visible(self, visible: bool) -> None:
        """Show or hide the hotkey help overlay."""
        if visible != self._help_visible:
            self._help_visible = visible
            self.events.help_changed.emit(visible)

    # ---- robot input -----------------------------------------------------------------------

    def on_telemetry(self, frame: TelemetryFrame) -> None:
        """A telemetry frame: the robot's state, the position controller and odometry."""
        self.controller.on_telemetry(frame.readings, frame.received_at, frame.delay_s)
        if self.arm is not None:
            self.arm.controller.observe(frame.readings)
        self.nav.on_telemetry(frame)
        self.robot.on_telemetry(frame)

    def on_status(self, status: StatusFrame) -> None:
        """An extension status packet: the robot's state, and the IMU heading for odometry."""
        self.nav.on_status(status)
        self.robot.on_status(status)

    def on_stats(self, stats: LinkStats) -> None:
        """The link's statistics (its round trip goes to odometry)."""
        self.nav.on_round_trip(stats.delay_s)
        self.robot.on_stats(stats)

    def on_scan(self, scan: ScanFrame) -> None:
        """A range scan (from the robot, or from ROS): the zones and the map take it."""
        if self.nav.on_scan(scan):
            self._apply_drive_now()

    def on_command_sent(self, command: Command, sent_at: float) -> None:
        """A command the link put on the wire: odometry integrates what was sent."""
        self.nav.on_command(command, sent_at)

    def predicted_angles(self, now: float | None = None) -> dict[str, float]:
        """Where the joints are now by the prediction (readings advanced by what was sent)."""
        return self.controller.predicted_angles(self.clock() if now is None else now)

    def update(self, now: float | None = None) -> None:
        """One position-control step: merge the controller's velocities into the channels."""
        now = self.clock() if now is None else now
        self._expire_sources(now)
        self._assist_tick(now)
        self._tracking_tick(now)
        # The robot moves, scans come: the zones judge the drive command again.
        self._apply_drive_now()
        output = self.controller.update(now)
        for channel, command in self._channels.items():
            if command.source is not Source.POSITION:
                continue
            if channel in output:
                self._set_channel(channel, output[channel], Source.POSITION)
            else:
                self._set_channel(channel, 0.0, Source.NONE)
        for message in self.controller.pop_messages():
            self.events.position_message.emit(message)
        self._sync_targets()
        if self.arm is not None:
            self.arm.step(now)
        self._publish(now)

    # ---- internals -------------------------------------------------------------------------

    def _check_channel(self, channel: str) -> None:
        if channel not in self._channels:
            raise CommandError(f"unknown velocity channel {channel!r}")

    def release_estop(self) -> None:
        """The operator acts again: the e-stop latch lets commands through once more."""
        if self._estopped:
            self._estopped = False
            self._estop_reason = ""
            self.events.estop_changed.emit(False, "")

    def _joint_of(self, channel: str) -> str | None:
        motor = self.profile.motor_for_channel(channel)
        return motor.name if motor is not None else None

    def _drop_keys(self, channel: str) -> None:
        dropped = [key for key, (ch, _) in self._held.items() if ch == channel]
        for key in dropped:
            del self._held[key]
        if dropped:
            self.events.held_changed.emit(self.held_keys)

    def _take_manual(self, channel: str, *, keep_keys: bool = False) -> None:
        """A manual input on a channel: the position controller lets go of its joint, and the
        arm of all of its channels."""
        joint = self._joint_of(channel)
        if (
            self.arm is not None
            and channel in self.arm.channels
            and (self.arm.controller.active or self._channels[channel].source is Source.ARM)
        ):
            self._stop_arm(f"manual command on the {joint or channel}")
        if joint is not None and joint in self._targets:
            self.controller.cancel(joint)
            self._sync_targets()
            self.events.message.emit(f"{joint}: position target cancelled by manual command")
        if not keep_keys:
            self._drop_keys(channel)

    def _apply_hotkeys(self, channel: str) -> None:
        directions = [d for ch, d in self._held.values() if ch == channel]
        if directions:
            net = sum(directions)
            speed = self.fine_speed(channel) if self._fine else self.hotkey_speed(channel)
            velocity = math.copysign(speed, net) if net else 0.0
            self._set_channel(channel, velocity, Source.HOTKEY)
        elif self._requested(channel).source is Source.HOTKEY:
            self._set_channel(channel, 0.0, Source.NONE)

    def _requested(self, channel: str) -> ChannelCommand:
        """What the operator asked of a channel (the drive pair is sent scaled)."""
        if channel in self._drive_request:
            return self._drive_request[channel]
        return self._channels[channel]

    def _rebound(self, channel: str) -> None:
        """Re-apply a channel's command after its maximum or hotkey speed changed."""
        command = self._requested(channel)
        if command.source is Source.HOTKEY:
            self._apply_hotkeys(channel)
        elif command.source is Source.SWITCH:
            direction = 1.0 if command.velocity > 0 else -1.0
            self._set_channel(channel, direction * self.hotkey_speed(channel), Source.SWITCH)
        elif command.source is Source.GAMEPAD:
            self._set_channel(channel, self._pad_velocity(channel), Source.GAMEPAD)
        elif command.source in (Source.SLIDER, Source.TEXT):
            if channel in self._drive_request:
                self._apply_drive()  # the pair is bounded again from the operator's request
            else:
                clamped = self.limits.clamp(channel, command.velocity)
                self._set_channel(channel, clamped, command.source)

    def _set_channel(self, channel: str, velocity: float, source: Source) -> None:
        if channel in self._drive_request:
            self._drive_request[channel] = ChannelCommand(float(velocity), source)
            self._apply_drive()
            return
        self._store(channel, ChannelCommand(float(velocity), source))

    def _store(self, channel: str, command: ChannelCommand) -> None:
        if command != self._channels[channel]:
            self._channels[channel] = command
            self.events.channel_changed.emit(channel, command)

    def _sync_targets(self) -> None:
        targets = self.controller.targets
        if targets != self._targets:
            self._targets = targets
            self.events.targets_changed.emit(dict(targets))

    def _publish(self, now: float | None = None) -> None:
        velocities = self.velocities()
        state = (velocities, self._torch, self._camera, self._bitrate)
        ends = self._ends(velocities)
        if state != self._published or ends != self._published_ends:
            # The predictor integrates what is sent, whoever sent it, and knows where the
            # link ends a motion by itself.
            self._published_ends = ends
            self.controller.note_sent(self.clock() if now is None else now, velocities, ends)
        if state != self._published:
            self._published = state
            self.events.command_changed.emit()
        # A new end alone is written by the control cycle (it writes every cycle).
