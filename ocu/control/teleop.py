"""The operator model: what the operator asks of every channel, and why (no Qt).

Every velocity channel holds one command with its source: a slider, a text box, a hotkey, a
switch or the position controller. The latest manual input on a channel wins and takes the
joint back from the position controller. Views subscribe to `events` and write the
operator's input back through the methods below; the console sends `command()` to the link
whenever `events.command_changed` fires.

Stops come in two strengths. `emergency_stop()` asks the link for its e-stop burst, zeroes
everything and latches: the model commands nothing until the operator acts again (a key
press, a slider move, Accept, a switch, a new target). `halt()` zeroes everything without the
burst, for focus loss, minimising, a stalled GUI thread, a lost or closed link.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from enum import Enum
from typing import Generic, ParamSpec

from ocu.control.commands import (
    Command,
    CommandError,
    JointReading,
    VelocityLimits,
)
from ocu.control.drive import DriveBounds, scale_drive
from ocu.control.position import PositionController
from ocu.profile import RobotProfile

log = logging.getLogger("ocu.teleop")

P = ParamSpec("P")

DEFAULT_FINE_FACTOR = 0.25


class Event(Generic[P]):
    """A list of callbacks called in order; one failing callback does not skip the others."""

    def __init__(self) -> None:
        self._callbacks: list[Callable[P, None]] = []

    def connect(self, callback: Callable[P, None]) -> None:
        """Call `callback` on every emit."""
        self._callbacks.append(callback)

    def disconnect(self, callback: Callable[P, None]) -> None:
        """Stop calling `callback`; no error if it was not connected."""
        if callback in self._callbacks:
            self._callbacks.remove(callback)

    def emit(self, *args: P.args, **kwargs: P.kwargs) -> None:
        """Call every callback; the first error is raised after all have run."""
        error: BaseException | None = None
        for callback in list(self._callbacks):
            try:
                callback(*args, **kwargs)
            except Exception as err:  # an e-stop must reach every subscriber
                log.exception("event callback %r failed", callback)
                error = error or err
        if error is not None:
            raise error


class Source(Enum):
    """What set a channel's velocity."""

    NONE = "none"
    SLIDER = "slider"
    TEXT = "text"
    HOTKEY = "hotkey"
    SWITCH = "switch"
    POSITION = "position"


MANUAL_SOURCES = (Source.SLIDER, Source.TEXT, Source.HOTKEY, Source.SWITCH)


@dataclass(frozen=True)
class ChannelCommand:
    """One channel's commanded velocity (m/s or rad/s) and its source."""

    velocity: float = 0.0
    source: Source = Source.NONE


class TeleopEvents:
    """Everything a view may subscribe to."""

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
        self.message: Event[[str]] = Event()
        self.position_message: Event[[str]] = Event()
        # Before any operator input or emergency stop takes effect (a host hands control back
        # from another commander, e.g. ROS, before the operator's command is sent).
        self.operator_acted: Event[[]] = Event()


def _check_finite(channel: str, value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CommandError(f"{channel}: velocity must be a finite number, got {value!r}")
    return float(value)


class TeleopModel:
    """Per-channel commands, held hotkeys, Shift fine mode, e-stop latch, position targets."""

    def __init__(
        self,
        profile: RobotProfile,
        *,
        fine_factor: float = DEFAULT_FINE_FACTOR,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not 0.0 < fine_factor <= 1.0:
            raise ValueError(f"fine_factor must be in (0, 1], got {fine_factor!r}")
        self.profile = profile
        self.clock = clock
        self.events = TeleopEvents()
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
        self._estopped = False
        self._estop_reason = ""
        self._connected = True
        self._help_visible = False
        self._targets: dict[str, float] = {}
        self._published: tuple[dict[str, float], bool] = ({}, False)

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

    def command(self, base: Command | None = None) -> Command:
        """The command for the link: `base` (camera, bitrate) with our velocities and torch."""
        base = base if base is not None else Command()
        return replace(base, velocities=self.velocities(), torch=self._torch)

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
        """Names of the hotkeys held now."""
        return frozenset(self._held)

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

    def hotkey_up(self, key: str) -> bool:
        """A hold-to-move key went up; its channel stops unless another key still holds it."""
        held = self._held.pop(key, None)
        if held is None:
            return False
        self._apply_hotkeys(held[0])
        self._publish()
        self.events.held_changed.emit(self.held_keys)
        return True

    def release_hotkeys(self, reason: str = "") -> bool:
        """Release every held key (focus lost); True if any was held."""
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
        self._zero_all()
        self._estop_reason = reason
        if not self._estopped:
            self._estopped = True
            self.events.estop_changed.emit(True, reason)
        self._publish()
        self.events.message.emit(f"EMERGENCY STOP ({reason})")

    def halt(self, reason: str) -> bool:
        """Stop all motion without the e-stop burst; True if anything was moving or held."""
        active = bool(self._held) or self.is_moving or bool(self._targets)
        self._zero_all()
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

    def on_telemetry(
        self,
        readings: Mapping[str, JointReading],
        received_at: float,
        delay_s: float | None = None,
    ) -> None:
        """Feed a telemetry packet (and the round trip it took) to the position controller."""
        self.controller.on_telemetry(readings, received_at, delay_s)

    def predicted_angles(self, now: float | None = None) -> dict[str, float]:
        """Where the joints are now by the prediction (readings advanced by what was sent)."""
        return self.controller.predicted_angles(self.clock() if now is None else now)

    def update(self, now: float | None = None) -> None:
        """One position-control step: merge the controller's velocities into the channels."""
        now = self.clock() if now is None else now
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
        self._publish(now)

    # ---- internals -------------------------------------------------------------------------

    def _check_channel(self, channel: str) -> None:
        if channel not in self._channels:
            raise CommandError(f"unknown velocity channel {channel!r}")

    def _operator_acted(self) -> None:
        self.events.operator_acted.emit()
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
        """A manual input on a channel: the position controller lets go of its joint."""
        joint = self._joint_of(channel)
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
        self._store(linear_name, ChannelCommand(v, linear.source if v else Source.NONE))
        self._store(turn_name, ChannelCommand(w, turn.source if w else Source.NONE))

    def _zero_all(self) -> None:
        had_keys = bool(self._held)
        self._held.clear()
        self.controller.cancel()
        self._sync_targets()
        for channel in self._channels:
            self._set_channel(channel, 0.0, Source.NONE)
        if had_keys:
            self.events.held_changed.emit(self.held_keys)

    def _sync_targets(self) -> None:
        targets = self.controller.targets
        if targets != self._targets:
            self._targets = targets
            self.events.targets_changed.emit(dict(targets))

    def _publish(self, now: float | None = None) -> None:
        state = (self.velocities(), self._torch)
        if state != self._published:
            self._published = state
            # The predictor integrates what is sent, whoever sent it.
            self.controller.note_sent(self.clock() if now is None else now, state[0])
            self.events.command_changed.emit()
