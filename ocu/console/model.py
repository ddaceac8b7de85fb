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
fed from the link; the drive pair, once composed from whichever source commands it, passes
the safety zones last (`_apply_drive`), so keys, sliders, typed values, ROS, the assisted
modes and any later input are all slowed near an obstacle. The assisted modes (the linear
shuttle, path following) are one more automatic source: they run in `update()` and yield to
any operator input, an emergency stop, a halt, LINK LOST and stale odometry.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

import numpy as np
import numpy.typing as npt

from ocu.console.arm import ArmConsole
from ocu.console.events import Event
from ocu.console.robot import RobotState
from ocu.console.tracking import (
    FRAME_TIMEOUT_S,
    LOST_TIMEOUT_S,
    TrackSession,
    TrackView,
    camera_axes,
    click_box,
)
from ocu.control.arm import ArmController
from ocu.control.commands import VelocityLimits
from ocu.control.drive import DriveBounds, scale_drive
from ocu.control.position import PositionController, PositionError
from ocu.control.tracking import TrackingOptions
from ocu.kinematics.arm import ArmError, ArmKinematics
from ocu.model.urdf import UrdfError, load_urdf
from ocu.nav.assist import AssistError
from ocu.nav.navigator import Navigator, ZoneState
from ocu.nav.tracking import ellipse
from ocu.profile import RobotProfile
from ocu.protocol.extended import CameraRequest
from ocu.records import (
    Command,
    CommandError,
    LinkState,
    LinkStats,
    ScanFrame,
    StatusFrame,
    TelemetryFrame,
)
from ocu.video.tracker import TrackState

log = logging.getLogger("ocu.console")

DEFAULT_FINE_FACTOR = 0.25


class Source(Enum):
    """What set a channel's velocity."""

    NONE = "none"
    SLIDER = "slider"
    TEXT = "text"
    HOTKEY = "hotkey"
    SWITCH = "switch"
    POSITION = "position"
    # A planner through the ROS bridge: any manual input on the channel overrides it.
    ROS = "ros"
    # The arm in Cartesian space (ocu.console.arm): jogs, pose goals, stored poses.
    ARM = "arm"
    # The operator's game controller (ocu.gamepad): a stick or a button held, deadman held.
    GAMEPAD = "gamepad"
    # An assisted mode (linear shuttle, path following): any operator input ends it.
    ASSIST = "assist"
    # Click-to-track (ocu.console.tracking): the pan and tilt joints keep an object centred;
    # any operator input ends it.
    TRACK = "track"


MANUAL_SOURCES = (Source.SLIDER, Source.TEXT, Source.HOTKEY, Source.SWITCH, Source.GAMEPAD)
# What the pad asks of one channel: a stick's fraction of the maximum, a button's direction.
PadWish = tuple[float, int]
PAD_AT_REST: PadWish = (0.0, 0)


@dataclass(frozen=True)
class ChannelCommand:
    """One channel's commanded velocity (m/s or rad/s) and its source."""

    velocity: float = 0.0
    source: Source = Source.NONE


class ConsoleEvents:
    """Everything a view may subscribe to (the robot's own are on `model.robot.events`)."""

    def __init__(self) -> None:
        self.channel_changed: Event[[str, ChannelCommand]] = Event()
        self.command_changed: Event[[]] = Event()
        self.max_changed: Event[[str, float]] = Event()
        self.hotkey_speed_changed: Event[[str, float]] = Event()
        self.estop_requested: Event[[str]] = Event()
        self.estop_changed: Event[[bool, str]] = Event()
        self.torch_changed: Event[[bool]] = Event()
        self.fine_changed: Event[[bool]] = Event()
        self.held_changed: Event[[frozenset[str]]] = Event()
        self.targets_changed: Event[[dict[str, float]]] = Event()
        self.connection_changed: Event[[bool]] = Event()
        self.help_changed: Event[[bool]] = Event()
        self.camera_changed: Event[[int | None]] = Event()
        self.bitrate_changed: Event[[float]] = Event()
        self.stream_request_changed: Event[[tuple[CameraRequest, ...]]] = Event()
        self.message: Event[[str]] = Event()
        self.position_message: Event[[str]] = Event()
        # Before any operator input or emergency stop takes effect (a host hands control back
        # from another commander, e.g. ROS, before the operator's command is sent).
        self.operator_acted: Event[[]] = Event()
        # Driving with a map: what the safety zones say, the assisted mode running (None)
        # with a message, the operator's waypoints and shuttle points, an odometry reset.
        self.zones_changed: Event[[ZoneState]] = Event()
        self.assist_changed: Event[[str | None, str]] = Event()
        self.waypoints_changed: Event[[tuple[tuple[float, float], ...]]] = Event()
        self.shuttle_points_changed: Event[[tuple[tuple[float, float], ...]]] = Event()
        self.odometry_reset: Event[[]] = Event()
        # Click-to-track: what to draw (None: not tracking) after every frame, start and stop.
        self.tracking_changed: Event[[TrackView | None]] = Event()


def _check_finite(channel: str, value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CommandError(f"{channel}: velocity must be a finite number, got {value!r}")
    return float(value)


class ConsoleModel:
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
        self._tracking: TrackSession | None = None
        # What of the tracking controller acts (the benchmark's baseline switches parts off).
        self.tracking_options = TrackingOptions()
        # The arm in Cartesian space; None when the profile has no [arm] table, or its URDF
        # cannot carry it (`arm_error` says why).
        self.arm: ArmConsole | None = None
        self.arm_error = ""
        if profile.arm is not None:
            try:
                kinematics = arm or ArmKinematics(load_urdf(meshes=False), profile.arm)
                controller = ArmController(profile, self.limits, kinematics, self.controller)
            except (ArmError, UrdfError) as err:
                self.arm_error = f"the arm's Cartesian control is off: {err}"
                log.warning("%s", self.arm_error)
            else:
                self.arm = ArmConsole(controller, self, arm_poses_path)
                self.arm.events.message.connect(self.events.message.emit, direct=True)

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
        """The command for the link: every channel's velocity and the switches."""
        return Command(
            velocities=self.velocities(),
            torch=self._torch,
            camera=self._camera,
            video_bitrate=self._bitrate,
        )

    @property
    def camera(self) -> int | None:
        """The camera asked for (None: none selected yet)."""
        return self._camera

    @property
    def video_bitrate(self) -> float:
        """The RCP's video bit-rate field."""
        return self._bitrate

    @property
    def stream_request(self) -> tuple[CameraRequest, ...]:
        """What an extended robot is asked to stream, per camera."""
        return self._streams

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
            value = _check_finite(channel, raw)
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

    def select_camera(self, camera: int) -> None:
        """Ask for a camera's stream (the vendor protocol sends one at a time)."""
        if not 0 <= camera < len(self.profile.link.camera_names):
            raise CommandError(
                f"camera {camera} outside 0-{len(self.profile.link.camera_names) - 1}"
            )
        if camera == self._camera:
            return
        self._camera = camera
        self.events.camera_changed.emit(camera)
        self._publish()

    def set_video_bitrate(self, bitrate: float) -> None:
        """The RCP's video bit-rate field (bits per second, >= 0)."""
        if not (math.isfinite(bitrate) and bitrate >= 0.0):
            raise CommandError(f"video bit-rate must be finite and >= 0, got {bitrate!r}")
        if bitrate == self._bitrate:
            return
        self._bitrate = float(bitrate)
        self.events.bitrate_changed.emit(self._bitrate)
        self._publish()

    def set_stream_request(self, request: CameraRequest) -> None:
        """What an extended robot should stream for one camera (size, rate)."""
        streams = list(self._streams)
        if not 0 <= request.camera < len(streams):
            raise CommandError(f"no stream request for camera {request.camera}")
        if streams[request.camera] == request:
            return
        streams[request.camera] = request
        self._streams = tuple(streams)
        self.events.stream_request_changed.emit(self._streams)

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
            value = min(max(_check_finite(channel, value), 0.0), self.limits.get(channel))
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
        self._zero_all(reason=f"EMERGENCY STOP ({reason})")
        self._estop_reason = reason
        if not self._estopped:
            self._estopped = True
            self.events.estop_changed.emit(True, reason)
        self._publish()
        self.events.message.emit(f"EMERGENCY STOP ({reason})")

    def halt(self, reason: str, *, keep_external: bool = False, keep_gamepad: bool = False) -> bool:
        """Stop all motion without the e-stop burst; True if anything was moving or held.

        With `keep_external`, channels a planner drives (ROS) go on: the console losing focus
        stops the operator's input, not a planner the operator may be watching in rviz. With
        `keep_gamepad`, so do the channels the game controller drives (its deadman is held,
        and it reads the pad whatever window has the focus: docs/gamepad.md).
        """
        active = (
            bool(self.held_keys)
            or self.is_moving
            or bool(self._targets)
            or self._tracking is not None
        )
        self._zero_all(keep_external=keep_external, keep_gamepad=keep_gamepad, reason=reason)
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

    # ---- the game controller (ocu.gamepad, through the window) -----------------------------

    def set_gamepad(
        self, fractions: Mapping[str, float], held: Mapping[str, int] | None = None
    ) -> None:
        """What the pad asks of each channel it maps; a channel left out is at rest.

        `fractions`: a stick's share of the channel's maximum, in [-1, 1]; `held`: a button's
        direction (-1, 0, 1), at the channel's hotkey speed. A channel becomes the pad's when
        its wish leaves rest (the latest manual input wins) and follows the wish while the
        pad holds it. Anything else that takes the channel meanwhile (a key, a slider, a
        target, a halt, an e-stop) keeps it until the pad's wish is back at rest: a stick
        still deflected never takes it back by itself.
        """
        held = held or {}
        wishes: dict[str, PadWish] = {}
        for channel in (*fractions, *held):
            self._check_channel(channel)
            fraction = _check_finite(channel, fractions.get(channel, 0.0))
            direction = held.get(channel, 0)
            if direction not in (-1, 0, 1):
                raise ValueError(f"pad direction must be -1, 0 or 1, got {direction!r}")
            wishes[channel] = (min(max(fraction, -1.0), 1.0), direction)
        for channel in self._pad:
            wishes.setdefault(channel, PAD_AT_REST)
        taking = []
        for channel, wish in wishes.items():
            previous = self._pad.get(channel, PAD_AT_REST)
            self._pad[channel] = wish
            ours = self._requested(channel).source is Source.GAMEPAD
            if wish == PAD_AT_REST:
                self._pad_blocked.discard(channel)
                if ours:
                    self._set_channel(channel, 0.0, Source.NONE)
            elif channel in self._pad_blocked:
                continue
            elif ours:
                self._set_channel(channel, self._pad_velocity(channel), Source.GAMEPAD)
            elif previous == PAD_AT_REST:
                taking.append(channel)
            else:
                # Taken from the pad while its wish was away from rest.
                self._pad_blocked.add(channel)
        if taking:
            self._operator_acted()
            for channel in taking:
                self._take_manual(channel)
                self._set_channel(channel, self._pad_velocity(channel), Source.GAMEPAD)
        self._publish()

    def stop_arm(self, reason: str) -> bool:
        """The arm's automatic motion (a jog, a goal, a stored pose) stops now; True if it
        was moving. For inputs that started a move and let go (the pad's deadman)."""
        if self.arm is None:
            return False
        moving = any(self._channels[c].source is Source.ARM for c in self.arm.channels)
        self._stop_arm(reason)
        self._publish()
        return moving

    def stop_gamepad(self, reason: str) -> bool:
        """The pad lets go (deadman released, unplugged, stalled): its channels stop now.

        True if the pad was moving anything; its wishes are at rest afterwards.
        """
        moving = self.gamepad_channels
        self._pad = dict.fromkeys(self._pad, PAD_AT_REST)
        self._pad_blocked.clear()
        for channel in moving:
            self._set_channel(channel, 0.0, Source.NONE)
        self._publish()
        if moving:
            self.events.message.emit(f"gamepad motion stopped: {reason}")
        return bool(moving)

    @property
    def gamepad_channels(self) -> list[str]:
        """Channels the game controller drives now."""
        return [c for c in self._channels if self._requested(c).source is Source.GAMEPAD]

    def _pad_velocity(self, channel: str) -> float:
        fraction, direction = self._pad.get(channel, PAD_AT_REST)
        if direction:
            return direction * self.hotkey_speed(channel)
        return fraction * self.limits.get(channel)

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

    # ---- driving with a map ----------------------------------------------------------------

    @property
    def waypoints(self) -> tuple[tuple[float, float], ...]:
        """The operator's waypoints (odometry frame, m) for the path mode."""
        return self._waypoints

    def set_waypoints(self, points: Sequence[tuple[float, float]]) -> None:
        """Replace the waypoints (the map's clicks)."""
        checked = tuple((float(x), float(y)) for x, y in points)
        if not all(math.isfinite(v) for point in checked for v in point):
            raise CommandError("waypoints must be finite numbers")
        self._waypoints = checked
        self.events.waypoints_changed.emit(checked)

    def add_waypoint(self, x_m: float, y_m: float) -> None:
        """One more waypoint at the end."""
        self.set_waypoints((*self._waypoints, (x_m, y_m)))

    @property
    def shuttle_points(self) -> tuple[tuple[float, float], ...]:
        """The linear mode's two points (fewer while the operator marks them)."""
        return self._shuttle

    def add_shuttle_point(self, x_m: float, y_m: float) -> None:
        """Mark a point for the linear mode; the last two marked count."""
        if not (math.isfinite(x_m) and math.isfinite(y_m)):
            raise CommandError("a shuttle point must be finite")
        self._shuttle = (*self._shuttle, (float(x_m), float(y_m)))[-2:]
        self.events.shuttle_points_changed.emit(self._shuttle)

    def clear_waypoints(self) -> None:
        """No waypoints nor shuttle points; a running mode stops."""
        self.set_waypoints(())
        self._shuttle = ()
        self.events.shuttle_points_changed.emit(())
        self._end_assist("path cleared")
        self._publish()

    def reset_odometry(self) -> None:
        """The operator's odometry reset: the robot is at the origin again, sure of it."""
        self._end_assist("odometry reset")
        self.nav.reset_odometry()
        self.set_waypoints(())
        self._shuttle = ()
        self.events.shuttle_points_changed.emit(())
        self.events.odometry_reset.emit()
        self.events.message.emit("odometry reset: pose (0, 0, 0°)")

    def override_zones(self) -> None:
        """The deliberate override: the next motion passes the safety zones (pushing a box)."""
        self.nav.override_zones()
        self.events.message.emit(
            "safety zones OVERRIDDEN for the next motion (it ends when the tracks stop)"
        )
        self._apply_drive_now()
        self._emit_zones(self.nav.zones, force=True)

    @property
    def assist_mode(self) -> str | None:
        """The assisted mode running: 'linear', 'path' or None."""
        return self.nav.assist_kind

    def start_linear(
        self,
        start_xy: tuple[float, float] | None = None,
        stop_xy: tuple[float, float] | None = None,
        cycles: int | None = None,
    ) -> None:
        """The linear shuttle between two points (seed 002, Algorithm 5.4), the marked ones
        by default; CommandError if it cannot start."""
        if start_xy is None or stop_xy is None:
            if len(self._shuttle) < 2:
                raise CommandError("linear mode: mark two points on the map first")
            start_xy, stop_xy = self._shuttle
        self._start_assist(
            lambda: self.nav.start_shuttle(
                start_xy, stop_xy, max_linear_m_s=self._max_linear(), cycles=cycles
            ),
            f"linear mode: shuttling between ({start_xy[0]:.2f}, {start_xy[1]:.2f}) and "
            f"({stop_xy[0]:.2f}, {stop_xy[1]:.2f})",
        )

    def start_path(
        self, waypoints: Sequence[tuple[float, float]] | None = None, *, external: bool = False
    ) -> None:
        """Follow waypoints (the operator's when None) with Samson's controller."""
        points = tuple(self._waypoints if waypoints is None else waypoints)
        if not points:
            raise CommandError("no waypoints: click on the map to set some")
        self._start_assist(
            lambda: self.nav.start_path(points, external=external),
            f"path mode: following {len(points)} waypoint(s)",
            external=external,
        )

    def start_ellipse(self) -> None:
        """Seed 002's test: the ellipse of eq. 6.1 (40 s ideal) from where the robot is."""
        pose = self.nav.estimate().pose
        self._start_assist(
            lambda: self.nav.start_trajectory(ellipse(pose)),
            "path mode: the ellipse of seed 002 (3.6 m x 2 m, 40 s)",
        )

    def stop_assist(self, reason: str = "operator") -> None:
        """End the assisted mode; its channels stop."""
        self._end_assist(reason)
        self._publish()

    def _start_assist(
        self, start: Callable[[], None], message: str, *, external: bool = False
    ) -> None:
        if self._drive is None:
            raise CommandError("the profile has no chassis to drive")
        if not external:
            # Starting a mode is the operator's act: it takes over from ROS, ends an e-stop.
            self._operator_acted()
        for channel in self._drive:
            self._take_manual(channel)
        try:
            start()
        except AssistError as err:
            raise CommandError(str(err)) from err
        self.events.assist_changed.emit(self.nav.assist_kind, message)
        self.events.message.emit(message)

    def _end_assist(self, reason: str) -> bool:
        kind = self.nav.assist_kind
        if not self.nav.stop_assist(reason):
            self._zero_assist()
            return False
        self._zero_assist()
        text = f"{kind} mode stopped: {reason}"
        self.events.assist_changed.emit(None, text)
        self.events.message.emit(text)
        return True

    def _zero_assist(self) -> None:
        for channel in self._drive or ():
            if self._requested(channel).source is Source.ASSIST:
                self._set_channel(channel, 0.0, Source.NONE)

    def _max_linear(self) -> float:
        assert self._drive is not None
        return self.limits.get(self._drive[0])

    def _assist_tick(self, now: float) -> None:
        link_ok = self.robot.link_state is LinkState.CONNECTED
        command = self.nav.assist_step(now, link_ok=link_ok)
        if command is None or self._drive is None:
            return
        if command.done:
            self._zero_assist()
            self.events.assist_changed.emit(None, command.message)
            self.events.message.emit(command.message)
            return
        linear_name, turn_name = self._drive
        for name, value in ((linear_name, command.linear_m_s), (turn_name, command.angular_rad_s)):
            # A channel the operator holds stays the operator's.
            if self._requested(name).source in (Source.NONE, Source.ASSIST):
                self._drive_request[name] = ChannelCommand(
                    float(value), Source.ASSIST if value else Source.NONE
                )
        self._apply_drive()

    # ---- a planner (the ROS bridge, through the window) ------------------------------------

    def set_external_velocities(self, values: Mapping[str, float]) -> dict[str, float]:
        """Velocities from a planner (ROS), bounded like every input; what was applied.

        A channel the operator holds (a key, a slider, a typed value, a switch, a position
        target) stays the operator's: the latest manual input wins.
        """
        checked = {}
        for channel, raw in values.items():
            self._check_channel(channel)
            checked[channel] = _check_finite(channel, raw)
        applied: dict[str, float] = {}
        for channel, wanted in checked.items():
            if self._requested(channel).source not in (Source.NONE, Source.ROS):
                continue
            # The drive pair is bounded together when it is composed (turn radius kept).
            drive = channel in self._drive_request
            value = wanted if drive else self.limits.clamp(channel, wanted)
            self._set_channel(channel, value, Source.ROS if value else Source.NONE)
            applied[channel] = self._channels[channel].velocity
        self._publish()
        return applied

    def clear_external(self) -> None:
        """The planner lost control: every channel it drives stops."""
        for channel in self._channels:
            if self._requested(channel).source is Source.ROS:
                self._set_channel(channel, 0.0, Source.NONE)
        self._publish()

    @property
    def external_channels(self) -> list[str]:
        """Channels a planner drives now."""
        return [c for c in self._channels if self._requested(c).source is Source.ROS]

    def predicted_angles(self, now: float | None = None) -> dict[str, float]:
        """Where the joints are now by the prediction (readings advanced by what was sent)."""
        return self.controller.predicted_angles(self.clock() if now is None else now)

    def update(self, now: float | None = None) -> None:
        """One position-control step: merge the controller's velocities into the channels."""
        now = self.clock() if now is None else now
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
        axes = camera_axes(self.profile.cameras[camera], self.arm.controller.kinematics, angles)
        missing = [j for j in (axes.pan_joint, axes.tilt_joint) if j not in angles]
        if missing:
            raise CommandError(f"no reading of {', '.join(missing)} yet")
        channels = (
            self.controller.channel_of(axes.pan_joint),
            self.controller.channel_of(axes.tilt_joint),
        )
        session = TrackSession(
            camera,
            axes,
            channels,
            (self.limits.get(channels[0]), self.limits.get(channels[1])),
            self.tracking_options,
        )
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
            f"tracking in the {name} camera with the {axes.pan_joint} and {axes.tilt_joint}: "
            "any motion input, Space or Esc takes over"
        )
        self._publish()

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

    # ---- the arm (ocu.console.arm calls these) ---------------------------------------------

    def arm_starting(self, *, move: bool) -> None:
        """The arm takes its channels: the operator acted (e-stop latch, ROS), position targets
        and held keys on its joints are dropped."""
        assert self.arm is not None
        self._operator_acted(keep_arm=True)
        for channel in self.arm.channels:
            joint = self._joint_of(channel)
            if joint is not None and joint in self._targets:
                self.controller.cancel(joint)
            self._drop_keys(channel)
            self._set_channel(channel, 0.0, Source.ARM)
        self._sync_targets()
        self._publish()

    def arm_output(self, velocities: Mapping[str, float]) -> None:
        """The arm's velocities now; its channels return to nobody when it commands nothing."""
        assert self.arm is not None
        active = self.arm.controller.active
        for channel in self.arm.channels:
            if self._channels[channel].source is not Source.ARM:
                continue
            if channel in velocities:
                self._set_channel(channel, velocities[channel], Source.ARM)
            else:
                self._set_channel(channel, 0.0, Source.ARM if active else Source.NONE)
        self._publish()

    def _stop_arm(self, reason: str) -> None:
        """The arm stops at once; its channels go to zero."""
        if self.arm is None:
            return
        self.arm.stop(reason)
        for channel in self.arm.channels:
            if self._channels[channel].source is Source.ARM:
                self._set_channel(channel, 0.0, Source.NONE)

    # ---- internals -------------------------------------------------------------------------

    def _check_channel(self, channel: str) -> None:
        if channel not in self._channels:
            raise CommandError(f"unknown velocity channel {channel!r}")

    def _operator_acted(self, *, keep_arm: bool = False) -> None:
        if not keep_arm and self.arm is not None and self.arm.controller.moving_to is not None:
            # A move is automatic: any operator motion input stops it.
            self._stop_arm("operator input")
        self.events.operator_acted.emit()
        self._end_tracking("operator took over")
        # The operator's input wins over a planner's and an assisted mode, at once.
        for channel in self._channels:
            if self._requested(channel).source is Source.ROS:
                self._set_channel(channel, 0.0, Source.NONE)
        self._end_assist("operator took over")
        self.release_estop()

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

    def _apply_drive(self) -> None:
        """Both drive channels from the operator's request, scaled by one factor."""
        assert self._drive is not None
        linear_name, turn_name = self._drive
        linear, turn = self._drive_request[linear_name], self._drive_request[turn_name]
        channels = self.profile.channels
        bounds = DriveBounds(
            max_linear_m_s=self.limits.get(linear_name),
            max_angular_rad_s=self.limits.get(turn_name),
            min_linear_m_s=channels[linear_name].min_speed,
            min_angular_rad_s=channels[turn_name].min_speed,
        )
        v, w = scale_drive(linear.velocity, turn.velocity, bounds)
        # The safety zones come last, whoever commands: keys, sliders, ROS, assisted modes.
        zones = self.nav.guard(v, w)
        if zones.decision is not None:
            v, w = zones.decision.linear_m_s, zones.decision.angular_rad_s
        self._emit_zones(zones)
        self._store(linear_name, ChannelCommand(v, linear.source if v else Source.NONE))
        self._store(turn_name, ChannelCommand(w, turn.source if w else Source.NONE))

    def _apply_drive_now(self) -> None:
        """Compose the drive pair again (a new scan, a tick) if it is asked to move."""
        if self._drive is None:
            return
        if any(self._drive_request[name].velocity for name in self._drive) or any(
            self._channels[name].velocity for name in self._drive
        ):
            self._apply_drive()
            self._publish()
        else:
            self._emit_zones(self.nav.guard(0.0, 0.0))

    def _emit_zones(self, zones: ZoneState, *, force: bool = False) -> None:
        if zones.text != self._zone_text or force:
            self._zone_text = zones.text
            self.events.zones_changed.emit(zones)
        limiting = zones.limiting
        if limiting and not self._zone_limiting:
            self.events.message.emit(zones.text)
        self._zone_limiting = limiting

    def _zero_all(
        self, *, keep_external: bool = False, keep_gamepad: bool = False, reason: str = "stopped"
    ) -> None:
        had_keys = bool(self.held_keys)
        self._held.clear()
        self._end_tracking(reason)
        self._stop_arm(reason)
        self.nav.cancel_override()
        if not (keep_external and self.nav.assist_external):
            self._end_assist(reason)
        self.controller.cancel()
        self._sync_targets()
        for channel in self._channels:
            source = self._requested(channel).source
            if (
                keep_external
                and (source is Source.ROS or (source is Source.ASSIST and self.nav.assist_external))
            ) or (keep_gamepad and source is Source.GAMEPAD):
                continue
            self._set_channel(channel, 0.0, Source.NONE)
        if had_keys:
            self.events.held_changed.emit(self.held_keys)

    def _sync_targets(self) -> None:
        targets = self.controller.targets
        if targets != self._targets:
            self._targets = targets
            self.events.targets_changed.emit(dict(targets))

    def _publish(self, now: float | None = None) -> None:
        state = (self.velocities(), self._torch, self._camera, self._bitrate)
        if state != self._published:
            self._published = state
            # The predictor integrates what is sent, whoever sent it.
            self.controller.note_sent(self.clock() if now is None else now, state[0])
            self.events.command_changed.emit()
