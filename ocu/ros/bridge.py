"""What the ROS bridge decides, without ROS or Qt: the 0.2 rule, cmd_vel timeout, joint goals.

`BridgeCore` turns velocity commands (cmd_vel) and joint position goals into channel
velocities for a command sink (a `LinkCore`), and stops what it started when cmd_vel stops
coming. The rospy wrapper (`ocu.ros.rosbridge`) only converts messages and calls it; the
console can host the same core and take control back from ROS at once (`override`).

cmd_vel mapping: `linear.x` drives `drive_linear` (m/s, forward positive) and `angular.z`
drives `drive_turn` (rad/s, counter-clockwise positive). A crawler cannot move sideways, up,
or roll: the other four Twist components are ignored.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from enum import Enum, IntEnum
from typing import Protocol

from ocu.control.commands import JointReading, VelocityLimits
from ocu.control.position import PositionController, PositionError
from ocu.link.core import LinkState
from ocu.link.stats import LinkStats
from ocu.profile import RobotProfile

log = logging.getLogger("ocu.ros")

DRIVE_LINEAR = "drive_linear"
DRIVE_TURN = "drive_turn"
DRIVE_CHANNELS = (DRIVE_LINEAR, DRIVE_TURN)
DEFAULT_CMD_VEL_TIMEOUT_S = 0.5
DEFAULT_RATE_HZ = 50.0
RATE_RANGE_HZ = (5.0, 500.0)
# Telemetry loss above this fraction makes the link diagnostics a warning.
LOSS_WARNING = 0.2
UNKNOWN_CAMERA = "unknown"


class BridgeError(ValueError):
    """A bridge setting or a velocity command that cannot be used."""


def raise_to_minimum(value: float, minimum: float) -> float:
    """The paper's rule: a speed with 0 < |value| < minimum becomes ±minimum, sign kept.

    Zero stays zero (stop), and speeds at or above the minimum pass unchanged: below it the
    Engineer's servos do not start moving.
    """
    if not math.isfinite(value):
        raise BridgeError(f"speed must be a finite number, got {value!r}")
    if not (math.isfinite(minimum) and minimum >= 0.0):
        raise BridgeError(f"minimum speed must be finite and >= 0, got {minimum!r}")
    if value == 0.0 or abs(value) >= minimum:
        return value
    return math.copysign(minimum, value)


@dataclass(frozen=True)
class BridgeSettings:
    """The bridge's tunables; the node reads them from its private ROS parameters.

    The minima are robot facts: `from_profile` takes them from the drive channels.
    """

    min_linear_m_s: float
    min_angular_rad_s: float
    cmd_vel_timeout_s: float = DEFAULT_CMD_VEL_TIMEOUT_S
    rate_hz: float = DEFAULT_RATE_HZ
    twist_stamped: bool = False

    def __post_init__(self) -> None:
        for name in ("min_linear_m_s", "min_angular_rad_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise BridgeError(f"{name} must be finite and >= 0, got {value!r}")
        if not (math.isfinite(self.cmd_vel_timeout_s) and self.cmd_vel_timeout_s > 0.0):
            raise BridgeError(f"cmd_vel_timeout_s must be > 0, got {self.cmd_vel_timeout_s!r}")
        low, high = RATE_RANGE_HZ
        if not (math.isfinite(self.rate_hz) and low <= self.rate_hz <= high):
            raise BridgeError(f"rate_hz must be within {low:g}-{high:g}, got {self.rate_hz!r}")

    @classmethod
    def from_profile(cls, profile: RobotProfile, **overrides: float | bool) -> BridgeSettings:
        """Defaults from the profile: the thresholds are the drive channels' min_speed."""
        values: dict[str, float | bool] = {
            "min_linear_m_s": profile.channels[DRIVE_LINEAR].min_speed,
            "min_angular_rad_s": profile.channels[DRIVE_TURN].min_speed,
        }
        values.update(overrides)
        return cls(**values)  # type: ignore[arg-type]


def twist_to_drive(
    linear_x: float, angular_z: float, settings: BridgeSettings, limits: VelocityLimits
) -> dict[str, float]:
    """Drive channel velocities for a Twist: the minimum rule, then the channel maxima."""
    linear = raise_to_minimum(linear_x, settings.min_linear_m_s)
    angular = raise_to_minimum(angular_z, settings.min_angular_rad_s)
    return {
        DRIVE_LINEAR: limits.clamp(DRIVE_LINEAR, linear),
        DRIVE_TURN: limits.clamp(DRIVE_TURN, angular),
    }


class CmdVelTimeout:
    """Says once when no cmd_vel has arrived for the timeout; the next cmd_vel re-arms it."""

    def __init__(self, timeout_s: float) -> None:
        self.timeout_s = timeout_s
        self._last_at: float | None = None
        self._tripped = False

    def feed(self, now: float) -> None:
        """A cmd_vel arrived."""
        self._last_at = now
        self._tripped = False

    def expired(self, now: float) -> bool:
        """True exactly once per silence longer than the timeout."""
        if self._last_at is None or self._tripped or now - self._last_at <= self.timeout_s:
            return False
        self._tripped = True
        return True

    def age(self, now: float) -> float | None:
        """Seconds since the last cmd_vel, None before the first."""
        return None if self._last_at is None else now - self._last_at


def parse_joint_goal(
    profile: RobotProfile,
    limits: VelocityLimits,
    names: Sequence[str],
    positions: Sequence[float],
) -> dict[str, float]:
    """Joint name to target angle (rad) from a JointState goal; all checked, or PositionError."""
    if len(names) != len(positions):
        raise PositionError(
            f"joint goal: {len(names)} names but {len(positions)} positions; "
            "give one position (rad) per name"
        )
    if len(set(names)) != len(names):
        raise PositionError(f"joint goal: a joint is named twice in {list(names)}")
    goals = {str(name): float(position) for name, position in zip(names, positions, strict=True)}
    probe = PositionController(profile, limits)
    for joint, angle_rad in goals.items():
        probe.set_target(joint, angle_rad)
    return goals


@dataclass(frozen=True)
class JointStateData:
    """The contents of a sensor_msgs/JointState: radians, rad/s and motor current (A)."""

    names: tuple[str, ...]
    positions_rad: tuple[float, ...]
    velocities_rad_s: tuple[float, ...]
    currents_a: tuple[float, ...]


def joint_state(profile: RobotProfile, readings: Mapping[str, JointReading]) -> JointStateData:
    """Every motor that reports an angle, in profile order (the tracks report none)."""
    chosen = [
        readings[name]
        for name in profile.motors
        if name in readings and readings[name].angle_rad is not None
    ]
    return JointStateData(
        names=tuple(r.name for r in chosen),
        positions_rad=tuple(float(r.angle_rad) for r in chosen if r.angle_rad is not None),
        velocities_rad_s=tuple(r.speed_rad_s for r in chosen),
        currents_a=tuple(r.current_a for r in chosen),
    )


def camera_name(profile: RobotProfile, camera: int | None) -> str:
    """The profile's name of a camera index ('unknown' when the robot did not say)."""
    names = profile.link.camera_names
    if camera is None or not 0 <= camera < len(names):
        return UNKNOWN_CAMERA
    return names[camera]


class DiagnosticLevel(IntEnum):
    """diagnostic_msgs/DiagnosticStatus levels."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


@dataclass(frozen=True)
class DiagnosticReport:
    """One diagnostic_msgs/DiagnosticStatus, ROS-free."""

    name: str
    level: DiagnosticLevel
    message: str
    hardware_id: str
    values: tuple[tuple[str, str], ...]


def _optional(value: float | None, fmt: str) -> str:
    return "n/a" if value is None else format(value, fmt)


def link_report(state: LinkState, stats: LinkStats, hardware_id: str) -> DiagnosticReport:
    """Link health: state, rates, loss, malformed/foreign counts, e-stop latch."""
    if state is LinkState.CONNECTED:
        level, message = DiagnosticLevel.OK, "connected"
        if stats.estop_latched:
            level, message = DiagnosticLevel.WARN, "connected, emergency stop latched"
        elif stats.loss_estimate is not None and stats.loss_estimate > LOSS_WARNING:
            level = DiagnosticLevel.WARN
            message = f"connected, telemetry loss {stats.loss_estimate:.0%}"
    elif state is LinkState.CONNECTING:
        level, message = DiagnosticLevel.WARN, "connecting: no packet from the robot yet"
    elif state is LinkState.LOST:
        level, message = DiagnosticLevel.ERROR, "LINK LOST: no valid packet from the robot"
    else:
        level, message = DiagnosticLevel.ERROR, "link closed"
    values = (
        ("state", state.value),
        ("datagrams sent", str(stats.sent)),
        ("valid packets received", str(stats.received)),
        ("telemetry packets", str(stats.telemetry)),
        ("video frames", str(stats.video)),
        ("malformed datagrams", str(stats.malformed)),
        ("foreign datagrams", str(stats.foreign)),
        ("send errors", str(stats.send_errors)),
        ("command rate (Hz)", f"{stats.rcp_rate_hz:.1f}"),
        ("telemetry rate (Hz)", f"{stats.telemetry_rate_hz:.1f}"),
        ("video rate (Hz)", f"{stats.video_rate_hz:.1f}"),
        ("telemetry loss", _optional(stats.loss_estimate, ".3f")),
        ("duplicates", str(stats.duplicates)),
        ("reordered", str(stats.reordered)),
        ("last valid packet age (s)", _optional(stats.last_valid_age_s, ".2f")),
        ("send rate setting (Hz)", f"{stats.send_rate_hz:g}"),
        ("emergency stop latched", str(stats.estop_latched).lower()),
    )
    return DiagnosticReport("ocu: robot link", level, message, hardware_id, values)


class BridgeState(Enum):
    """Who may move the robot through the bridge."""

    OFF = "off"
    LISTENING = "listening"
    COMMANDING = "commanding"
    OVERRIDDEN = "overridden"


STATE_TEXT = {
    BridgeState.OFF: "ROS control off",
    BridgeState.LISTENING: "ROS control on: waiting for commands",
    BridgeState.COMMANDING: "ROS is commanding the robot",
    BridgeState.OVERRIDDEN: "ROS control overridden by the operator",
}


class CommandSink(Protocol):
    """Where the bridge sends velocities (LinkCore satisfies it)."""

    def set_velocities(self, **velocities: float) -> None: ...


StateCallback = Callable[[BridgeState, str], None]


@dataclass(frozen=True)
class BridgeStatus:
    """A snapshot of the bridge for diagnostics and the console."""

    state: BridgeState
    drive: dict[str, float]
    goals_rad: dict[str, float]
    cmd_vel_age_s: float | None
    cmd_vel_count: int
    rejected_count: int
    timeouts: int


def bridge_report(status: BridgeStatus, hardware_id: str) -> DiagnosticReport:
    """Bridge health: who commands, the last cmd_vel's age, goals, rejections, timeouts."""
    level = DiagnosticLevel.OK
    if status.state in (BridgeState.OFF, BridgeState.OVERRIDDEN):
        level = DiagnosticLevel.WARN
    goals = ", ".join(f"{j}={math.degrees(a):.1f}°" for j, a in status.goals_rad.items())
    values = (
        ("state", status.state.value),
        ("drive_linear (m/s)", f"{status.drive.get(DRIVE_LINEAR, 0.0):.3f}"),
        ("drive_turn (rad/s)", f"{status.drive.get(DRIVE_TURN, 0.0):.3f}"),
        ("last cmd_vel age (s)", _optional(status.cmd_vel_age_s, ".2f")),
        ("cmd_vel received", str(status.cmd_vel_count)),
        ("cmd_vel timeouts", str(status.timeouts)),
        ("joint goals", goals or "none"),
        ("rejected commands", str(status.rejected_count)),
    )
    return DiagnosticReport("ocu: ROS bridge", level, STATE_TEXT[status.state], hardware_id, values)


class BridgeCore:
    """cmd_vel and joint goals to channel velocities; thread-safe, no ROS, no Qt.

    Every entry point takes one lock, and velocities are sent while holding it: once
    `override()` or `detach()` has returned, the bridge sends nothing more, so an operator
    command sent afterwards is never replaced by a late ROS command.
    """

    def __init__(
        self,
        profile: RobotProfile,
        settings: BridgeSettings | None = None,
        *,
        clock: Callable[[], float] = time.monotonic,
        on_state_changed: StateCallback | None = None,
    ) -> None:
        self.profile = profile
        self.settings = settings if settings is not None else BridgeSettings.from_profile(profile)
        self.clock = clock
        # Runs under the bridge's lock on the calling thread: it must not block.
        self.on_state_changed = on_state_changed
        self._lock = threading.RLock()
        self._sink: CommandSink | None = None
        self._limits = VelocityLimits(profile)
        self._controller = PositionController(profile, self._limits)
        self._timeout = CmdVelTimeout(self.settings.cmd_vel_timeout_s)
        self._state = BridgeState.OFF
        self._drive = dict.fromkeys(DRIVE_CHANNELS, 0.0)
        self._goal_channels: set[str] = set()
        self._cmd_vel_count = 0
        self._rejected = 0
        self._timeouts = 0
        self._ignored_logged = False

    # ---- life --------------------------------------------------------------------------

    def attach(self, sink: CommandSink, limits: VelocityLimits | None = None) -> None:
        """Start commanding `sink`, bounded by `limits` (the link's; the profile's defaults
        if None)."""
        with self._lock:
            self._sink = sink
            self._limits = limits if limits is not None else VelocityLimits(self.profile)
            self._controller = PositionController(self.profile, self._limits)
            self._goal_channels = set()
            self._drive = dict.fromkeys(DRIVE_CHANNELS, 0.0)
            self._timeout = CmdVelTimeout(self.settings.cmd_vel_timeout_s)
            self._set_state(BridgeState.LISTENING)

    def detach(self, *, stop: bool = True) -> None:
        """Stop commanding; with `stop`, zero first the channels the bridge was moving."""
        with self._lock:
            if self._sink is not None and stop:
                zeros = self._owned_channels()
                if zeros:
                    self._sink.set_velocities(**dict.fromkeys(zeros, 0.0))
            self._release()
            self._sink = None
            self._set_state(BridgeState.OFF)

    def override(self, reason: str = "operator") -> bool:
        """The operator takes over: ROS is ignored until `enable()`; sends nothing itself.

        Returns True if ROS was in control (listening or commanding). The host then sends its
        own command, which replaces every channel the bridge was driving.
        """
        with self._lock:
            if self._state not in (BridgeState.LISTENING, BridgeState.COMMANDING):
                return False
            was_commanding = self._state is BridgeState.COMMANDING
            self._release()
            self._set_state(BridgeState.OVERRIDDEN)
        if was_commanding:
            log.info("ROS control overridden (%s)", reason)
        return True

    def enable(self) -> None:
        """ROS may command again after an override."""
        with self._lock:
            if self._state is BridgeState.OVERRIDDEN and self._sink is not None:
                self._timeout = CmdVelTimeout(self.settings.cmd_vel_timeout_s)
                self._set_state(BridgeState.LISTENING)

    def _release(self) -> None:
        self._controller.cancel()
        self._goal_channels = set()
        self._drive = dict.fromkeys(DRIVE_CHANNELS, 0.0)

    def _owned_channels(self) -> list[str]:
        owned = [name for name, value in self._drive.items() if value != 0.0]
        return owned + sorted(self._goal_channels)

    # ---- inputs (any thread) -----------------------------------------------------------

    def on_cmd_vel(
        self, linear_x: float, angular_z: float, ignored: Sequence[float] = ()
    ) -> dict[str, float] | None:
        """A Twist arrived: returns the drive velocities sent, or None if not in control.

        `ignored` are the other four Twist components, only to warn once that they do
        nothing. A non-finite component stops the tracks and raises BridgeError.
        """
        with self._lock:
            if self._sink is None or self._state is BridgeState.OVERRIDDEN:
                self._rejected += 1
                return None
            now = self.clock()
            self._timeout.feed(now)
            self._cmd_vel_count += 1
            if any(v != 0.0 for v in ignored) and not self._ignored_logged:
                self._ignored_logged = True
                log.warning(
                    "cmd_vel: only linear.x and angular.z move a crawler; "
                    "linear.y/z and angular.x/y are ignored"
                )
            try:
                drive = twist_to_drive(linear_x, angular_z, self.settings, self._limits)
            except BridgeError:
                self._rejected += 1
                self._send_drive(dict.fromkeys(DRIVE_CHANNELS, 0.0))
                self._update_state()
                raise
            self._send_drive(drive)
            self._update_state()
            return drive

    def set_goals(self, names: Sequence[str], positions: Sequence[float]) -> dict[str, float]:
        """Joint position goals (rad); all or none apply. PositionError if one is bad.

        An empty goal cancels every joint goal (their joints stop).
        """
        with self._lock:
            if self._sink is None or self._state is BridgeState.OVERRIDDEN:
                self._rejected += 1
                raise PositionError("joint goal ignored: ROS is not in control")
            if not names and not positions:
                self._stop_goals()
                self._update_state()
                return {}
            try:
                goals = parse_joint_goal(self.profile, self._limits, names, positions)
            except PositionError:
                self._rejected += 1
                raise
            for joint, angle_rad in goals.items():
                self._controller.set_target(joint, angle_rad)
                self._goal_channels.add(self._controller.channel_of(joint))
            self._update_state()
            return goals

    def _stop_goals(self) -> None:
        channels = sorted(self._goal_channels)
        self._controller.cancel()
        self._goal_channels = set()
        if channels and self._sink is not None:
            self._sink.set_velocities(**dict.fromkeys(channels, 0.0))

    def on_telemetry(self, readings: Mapping[str, JointReading], received_at: float) -> None:
        """Measured joint angles for the position controller (any thread)."""
        with self._lock:
            self._controller.on_telemetry(readings, received_at)

    # ---- periodic work -----------------------------------------------------------------

    def step(self, now: float | None = None) -> list[str]:
        """cmd_vel timeout and one position-control step; returns the controller's messages."""
        with self._lock:
            now = self.clock() if now is None else now
            if self._sink is None or self._state is BridgeState.OVERRIDDEN:
                return []
            if self._timeout.expired(now):
                moving = any(v != 0.0 for v in self._drive.values())
                self._timeouts += 1
                if moving:
                    log.warning(
                        "no cmd_vel for %.2f s: tracks stopped", self.settings.cmd_vel_timeout_s
                    )
                    self._send_drive(dict.fromkeys(DRIVE_CHANNELS, 0.0))
            messages: list[str] = []
            if self._goal_channels:
                velocities = self._controller.update(now)
                for channel in self._goal_channels:
                    velocities.setdefault(channel, 0.0)
                self._sink.set_velocities(**velocities)
                self._goal_channels = {
                    self._controller.channel_of(j) for j in self._controller.targets
                }
                messages = self._controller.pop_messages()
            self._update_state()
            return messages

    def _send_drive(self, drive: dict[str, float]) -> None:
        assert self._sink is not None
        self._drive = dict(drive)
        self._sink.set_velocities(**drive)

    # ---- state -------------------------------------------------------------------------

    @property
    def state(self) -> BridgeState:
        """Who may move the robot through the bridge now."""
        with self._lock:
            return self._state

    @property
    def commanding(self) -> bool:
        """Whether ROS moves something now (tracks or a joint goal)."""
        return self.state is BridgeState.COMMANDING

    def status(self) -> BridgeStatus:
        """A snapshot for diagnostics."""
        with self._lock:
            return BridgeStatus(
                state=self._state,
                drive=dict(self._drive),
                goals_rad=self._controller.targets,
                cmd_vel_age_s=self._timeout.age(self.clock()),
                cmd_vel_count=self._cmd_vel_count,
                rejected_count=self._rejected,
                timeouts=self._timeouts,
            )

    def _update_state(self) -> None:
        if self._state not in (BridgeState.LISTENING, BridgeState.COMMANDING):
            return
        moving = any(v != 0.0 for v in self._drive.values()) or bool(self._goal_channels)
        self._set_state(BridgeState.COMMANDING if moving else BridgeState.LISTENING)

    def _set_state(self, state: BridgeState) -> None:
        if state is self._state:
            return
        self._state = state
        if self.on_state_changed is not None:
            try:
                self.on_state_changed(state, STATE_TEXT[state])
            except Exception:
                log.exception("bridge state callback failed")
