"""What the ROS bridge decides, without ROS or Qt: drive scaling, timeouts, link loss, goals.

`BridgeCore` turns velocity commands (cmd_vel) and joint position goals into channel
velocities for a velocity sink (a `Link`, or the console model), and stops what it started
when cmd_vel stops coming or the link is lost. The rospy wrapper (`ocu.ros.rosbridge`) only
converts messages and calls it; the console can host the same core and take control back
from ROS at once (`override`).

cmd_vel mapping: `linear.x` drives `drive_linear` (m/s, forward positive) and `angular.z`
drives `drive_turn` (rad/s, counter-clockwise positive). A crawler cannot move sideways, up,
or roll: the other four Twist components are ignored. Both speeds are bounded and lifted to
the servos' starting speed with one common factor, so the turn radius is kept
(`ocu.control.drive.scale_drive`, seed 002 eq. 5.1-5.4).

Link loss: while the link is LOST the bridge sends zeros whatever cmd_vel says; once it is
CONNECTED again, cmd_vel must have been zero or silent for the cmd_vel timeout before a
non-zero one drives again, so a planner still streaming its old command does not restart
the robot the moment the link comes back (the console's rule: nothing resumes by itself).

The arm (profile [arm], ocu.control.arm): a pose goal (tool0's position and pitch in the
base frame) or a stored pose by name is one synchronized move; a twist (tool0's linear
velocity and pitch rate in the base frame) jogs it and stops `twist_timeout_s` after the last
one. They share the position controller's prediction, and stop with everything else when the
link is lost, ROS is overridden or the bridge detaches.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from enum import Enum, IntEnum
from pathlib import Path
from typing import Protocol

import numpy as np

from ocu.console.poses import MAX_NAME_LENGTH, PoseError, PoseStore
from ocu.control.arm import ArmController
from ocu.control.commands import VelocityLimits
from ocu.control.drive import DriveBounds, DriveError, scale_drive
from ocu.control.position import PositionController, PositionError
from ocu.kinematics.arm import ArmError, ArmKinematics, ToolPose, pitch_axis, pitch_of
from ocu.kinematics.chain import Vector
from ocu.link.history import UPLINK_LOSS_UNMEASURABLE
from ocu.model.tree import Matrix
from ocu.model.urdf import UrdfError, load_urdf
from ocu.profile import RobotProfile
from ocu.records import JointReading, LinkState, LinkStats

log = logging.getLogger("ocu.ros")

DEFAULT_CMD_VEL_TIMEOUT_S = 0.5
# A longer silence would let a dead planner's last command run on for too long: the robot's
# own watchdog is 1 s, and the timeout also sets how long cmd_vel must be quiet after a
# link loss before ROS may drive again.
MAX_CMD_VEL_TIMEOUT_S = 2.0
DEFAULT_RATE_HZ = 50.0
RATE_RANGE_HZ = (5.0, 500.0)
# Telemetry loss above this fraction makes the link diagnostics a warning.
LOSS_WARNING = 0.2
UNKNOWN_CAMERA = "unknown"
# At most one line per kind of complaint and this interval: a bad publisher can send 100 Hz.
WARNING_INTERVAL_S = 2.0
# A text from a message (a pose name, a frame) is quoted in a log line up to this length.
QUOTE_CHARS = 60


class Throttle:
    """At most one log line per key and interval (a bad publisher can send 100 Hz)."""

    def __init__(self, interval_s: float = WARNING_INTERVAL_S) -> None:
        self.interval_s = interval_s
        self._lock = threading.Lock()
        self._last: dict[str, float] = {}

    def allow(self, key: str) -> bool:
        now = time.monotonic()
        with self._lock:
            last = self._last.get(key)
            if last is not None and now - last < self.interval_s:
                return False
            self._last[key] = now
            return True


def quoted(text: str, limit: int = QUOTE_CHARS) -> str:
    """`text` for a log line: repr'd, cut to `limit` characters with its full length said."""
    if len(text) <= limit:
        return repr(text)
    return f"{text[:limit]!r}... ({len(text)} characters)"


class BridgeError(ValueError):
    """A bridge setting or a velocity command that cannot be used."""


@dataclass(frozen=True)
class BridgeSettings:
    """The bridge's tunables; the node reads them from its private ROS parameters.

    The minima are robot facts: `from_profile` takes them from the drive channels, and the
    channels themselves from their roles (`drive`: the linear and the turn channel).
    """

    min_linear_m_s: float
    min_angular_rad_s: float
    drive: tuple[str, str]
    cmd_vel_timeout_s: float = DEFAULT_CMD_VEL_TIMEOUT_S
    rate_hz: float = DEFAULT_RATE_HZ
    twist_stamped: bool = False

    def __post_init__(self) -> None:
        for name in ("min_linear_m_s", "min_angular_rad_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise BridgeError(f"{name} must be finite and >= 0, got {value!r}")
        timeout_s = self.cmd_vel_timeout_s
        if not (math.isfinite(timeout_s) and 0.0 < timeout_s <= MAX_CMD_VEL_TIMEOUT_S):
            raise BridgeError(
                f"cmd_vel_timeout_s must be > 0 and at most {MAX_CMD_VEL_TIMEOUT_S:g} s, "
                f"got {timeout_s!r}"
            )
        low, high = RATE_RANGE_HZ
        if not (math.isfinite(self.rate_hz) and low <= self.rate_hz <= high):
            raise BridgeError(f"rate_hz must be within {low:g}-{high:g}, got {self.rate_hz!r}")

    @classmethod
    def from_profile(cls, profile: RobotProfile, **overrides: float | bool) -> BridgeSettings:
        """Defaults from the profile: the thresholds are the drive channels' min_speed."""
        drive = profile.drive_channels
        if drive is None:
            raise BridgeError(
                "the profile has no chassis (no channels with the roles drive_linear and "
                "drive_turn): cmd_vel cannot drive it"
            )
        values: dict[str, float | bool | tuple[str, str]] = {
            "min_linear_m_s": profile.channels[drive[0]].min_speed,
            "min_angular_rad_s": profile.channels[drive[1]].min_speed,
            "drive": drive,
        }
        values.update(overrides)
        return cls(**values)  # type: ignore[arg-type]

    @property
    def drive_zero(self) -> dict[str, float]:
        """Both drive channels at zero."""
        return dict.fromkeys(self.drive, 0.0)


def drive_bounds(settings: BridgeSettings, limits: VelocityLimits) -> DriveBounds:
    """The chassis bounds now: maxima from the link's limits, minima from the settings."""
    linear, turn = settings.drive
    return DriveBounds(
        max_linear_m_s=limits.get(linear),
        max_angular_rad_s=limits.get(turn),
        min_linear_m_s=settings.min_linear_m_s,
        min_angular_rad_s=settings.min_angular_rad_s,
    )


def bound_drive(
    linear_m_s: float, angular_rad_s: float, bounds: DriveBounds
) -> tuple[float, float, bool]:
    """(v, ω) divided by one factor so that neither exceeds its maximum, and whether it was.

    The same rule as `scale_drive`'s eq. 5.1-5.2, computed without overflow: v / v_max of a
    finite but huge v (1e308 / 0.3) is infinite, which `scale_drive` reads as "a maximum of
    zero" and stops the tracks. Non-finite speeds and zero maxima are left to `scale_drive`.
    """
    v, w = linear_m_s, angular_rad_s
    if not (math.isfinite(v) and math.isfinite(w)) or (v == 0.0 and w == 0.0):
        return v, w, False
    v_max, w_max = bounds.max_linear_m_s, bounds.max_angular_rad_s
    if (v != 0.0 and v_max <= 0.0) or (w != 0.0 and w_max <= 0.0):
        return v, w, False
    # Divided by the larger magnitude first, every quotient below is finite.
    scale = max(abs(v), abs(w))
    unit_v, unit_w = v / scale, w / scale
    ratio = max(
        abs(unit_v) / v_max if v_max > 0.0 else 0.0,
        abs(unit_w) / w_max if w_max > 0.0 else 0.0,
    )
    if scale * ratio <= 1.0:
        return v, w, False
    return unit_v / ratio, unit_w / ratio, True


def twist_to_drive(
    linear_x: float, angular_z: float, settings: BridgeSettings, limits: VelocityLimits
) -> dict[str, float]:
    """Drive channel velocities for a Twist, scaled by one factor (the turn radius kept).

    Speeds below `ocu.control.drive.ZERO_EPSILON` are zero; a non-finite one is a BridgeError;
    a huge one is brought down to its maximum like any other above it.
    """
    bounds = drive_bounds(settings, limits)
    linear_x, angular_z, _ = bound_drive(linear_x, angular_z, bounds)
    try:
        linear, angular = scale_drive(linear_x, angular_z, bounds)
    except DriveError as err:
        raise BridgeError(str(err)) from err
    return dict(zip(settings.drive, (linear, angular), strict=True))


def bound_arm_twist(
    linear: Sequence[float],
    angular: Sequence[float],
    axis: Vector,
    max_linear_m_s: float,
    max_pitch_rad_s: float,
) -> tuple[list[float], bool]:
    """A twist of tool0 as the arm's jog (vx, vy, vz, pitch rate), bounded before any
    kinematics sees it: the linear velocity to `max_linear_m_s` (its direction kept), the
    pitch rate (the angular velocity about `axis`, a unit vector) to ±`max_pitch_rad_s`.
    Returns the jog and whether it was bounded; ArmError unless six finite numbers."""
    values = [float(v) for v in (*linear, *angular)]
    if len(values) != 6 or not all(math.isfinite(v) for v in values):
        raise ArmError("a twist needs six finite numbers")
    clamped = False
    velocity = np.array(values[:3])
    scale = float(np.max(np.abs(velocity)))
    if scale > 0.0:
        unit = velocity / scale  # finite whatever the scale: no overflow in the norm
        norm = float(np.linalg.norm(unit))
        speed = scale * norm  # may be inf: only compared
        if speed > max_linear_m_s:
            velocity = unit / norm * max_linear_m_s
            clamped = True
    spin = np.array(values[3:])
    scale = float(np.max(np.abs(spin)))
    pitch_rate = 0.0
    if scale > 0.0:
        pitch_rate = scale * float(np.dot(spin / scale, axis))  # may be ±inf: clamped next
        if abs(pitch_rate) > max_pitch_rad_s:
            pitch_rate = math.copysign(max_pitch_rad_s, pitch_rate)
            clamped = True
    return [*(float(v) for v in velocity), pitch_rate], clamped


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


def quaternion_xyzw(rotation: Matrix) -> tuple[float, float, float, float]:
    """A rotation matrix (3x3 or 4x4) as a unit quaternion (x, y, z, w), w >= 0."""
    r = np.asarray(rotation, dtype=float)[:3, :3]
    w = math.sqrt(max(0.0, 1.0 + r[0, 0] + r[1, 1] + r[2, 2])) / 2.0
    x = math.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2])) / 2.0
    y = math.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2])) / 2.0
    z = math.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2])) / 2.0
    x = math.copysign(x, r[2, 1] - r[1, 2])
    y = math.copysign(y, r[0, 2] - r[2, 0])
    z = math.copysign(z, r[1, 0] - r[0, 1])
    return x, y, z, w


def rotation_of(x: float, y: float, z: float, w: float) -> Matrix:
    """The 3x3 rotation of a quaternion (normalised first); BridgeError if it is zero."""
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not math.isfinite(norm) or norm < 1e-9:
        raise BridgeError("the orientation quaternion must be finite and not zero")
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


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


def _ms(value_s: float | None) -> float | None:
    return None if value_s is None else value_s * 1e3


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
        ("state", state.label),
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
        ("round trip (ms)", _optional(_ms(stats.delay_s), ".0f")),
        ("delay jitter (ms)", _optional(_ms(stats.jitter_s), ".0f")),
        ("scan rate (Hz)", f"{stats.scan_rate_hz:.1f}"),
        (
            "command loss",
            UPLINK_LOSS_UNMEASURABLE
            if stats.uplink_loss is None
            else format(stats.uplink_loss, ".3f"),
        ),
        *(
            (f"frame age camera {index} (s)", _optional(age, ".2f"))
            for index, age in enumerate(stats.frame_age_s)
        ),
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


class VelocitySink(Protocol):
    """Where the bridge sends velocities: a Link (ocu-ros), or the console model (the window)."""

    def set_velocities(self, **velocities: float) -> None: ...


StateCallback = Callable[[BridgeState, str], None]


class LinkGate(Enum):
    """Whether the link lets ROS move the robot (the Link's state, seen by the bridge)."""

    OPEN = "open"
    # LOST or CLOSED: zeros whatever cmd_vel says; joint goals cancelled and refused.
    LOST = "link lost"
    # CONNECTED again: a non-zero cmd_vel is refused until cmd_vel has been zero or silent
    # for the cmd_vel timeout, so recovery never resumes motion by itself.
    RECOVERING = "recovering"


def gate_text(gate: LinkGate, timeout_s: float) -> str:
    """What the gate means for cmd_vel, for logs and diagnostics."""
    if gate is LinkGate.LOST:
        return "LINK LOST: cmd_vel refused, zeros sent"
    if gate is LinkGate.RECOVERING:
        return f"link back: cmd_vel refused until it has been zero or silent for {timeout_s:.2f} s"
    return "link up: cmd_vel obeyed"


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
    link_gate: LinkGate = LinkGate.OPEN
    link_refused_count: int = 0
    cmd_vel_timeout_s: float = DEFAULT_CMD_VEL_TIMEOUT_S


def bridge_report(status: BridgeStatus, hardware_id: str) -> DiagnosticReport:
    """Bridge health: who commands, the link gate, cmd_vel age, goals, rejections, timeouts."""
    level = DiagnosticLevel.OK
    message = STATE_TEXT[status.state]
    if status.state in (BridgeState.OFF, BridgeState.OVERRIDDEN):
        level = DiagnosticLevel.WARN
    if status.link_gate is not LinkGate.OPEN:
        level = DiagnosticLevel.ERROR if status.link_gate is LinkGate.LOST else DiagnosticLevel.WARN
        message = f"{message}; {gate_text(status.link_gate, status.cmd_vel_timeout_s)}"
    goals = ", ".join(f"{j}={math.degrees(a):.1f}°" for j, a in status.goals_rad.items())
    values = (
        ("state", status.state.value),
        ("link gate", status.link_gate.value),
        *(
            (f"{name} ({unit})", f"{status.drive.get(name, 0.0):.3f}")
            for name, unit in zip(status.drive, ("m/s", "rad/s"), strict=False)
        ),
        ("last cmd_vel age (s)", _optional(status.cmd_vel_age_s, ".2f")),
        ("cmd_vel timeout (s)", f"{status.cmd_vel_timeout_s:g}"),
        ("cmd_vel received", str(status.cmd_vel_count)),
        ("cmd_vel timeouts", str(status.timeouts)),
        ("cmd_vel refused (link)", str(status.link_refused_count)),
        ("joint goals", goals or "none"),
        ("rejected commands", str(status.rejected_count)),
    )
    return DiagnosticReport("ocu: ROS bridge", level, message, hardware_id, values)


class BridgeCore:
    """cmd_vel and joint goals to channel velocities; thread-safe, no ROS, no Qt.

    Every entry point takes one lock, and velocities are sent while holding it: once
    `override()` or `detach()` has returned, the bridge sends nothing more, so an operator
    command sent afterwards is never replaced by a late ROS command. The link's state
    arrives through `on_link_state` (the link thread): see `LinkGate`.
    """

    def __init__(
        self,
        profile: RobotProfile,
        settings: BridgeSettings | None = None,
        *,
        clock: Callable[[], float] = time.monotonic,
        on_state_changed: StateCallback | None = None,
        arm: ArmKinematics | None = None,
        arm_poses_path: Path | None = None,
    ) -> None:
        self.profile = profile
        self.settings = settings if settings is not None else BridgeSettings.from_profile(profile)
        self.clock = clock
        # Runs under the bridge's lock on the calling thread: it must not block.
        self.on_state_changed = on_state_changed
        self._lock = threading.RLock()
        self._sink: VelocitySink | None = None
        self._limits = VelocityLimits(profile)
        self._controller = PositionController(profile, self._limits)
        self._timeout = CmdVelTimeout(self.settings.cmd_vel_timeout_s)
        self._state = BridgeState.OFF
        self._drive = self.settings.drive_zero
        self._goal_channels: set[str] = set()
        self._cmd_vel_count = 0
        self._rejected = 0
        self._timeouts = 0
        self._ignored_logged = False
        # The link as last reported; a new link starts CONNECTING, which lets ROS drive.
        self._link_state = LinkState.CONNECTING
        self._gate = LinkGate.OPEN
        self._link_refused = 0
        # When the last cmd_vel asking for motion arrived (obeyed or not): the recovery
        # rule measures the quiet time from it.
        self._last_motion_at: float | None = None
        # The arm in Cartesian space (None: no [arm] in the profile, or no URDF for it).
        self.arm_kinematics: ArmKinematics | None = arm
        self.arm_error = ""
        if arm is None and profile.arm is not None:
            try:
                self.arm_kinematics = ArmKinematics(load_urdf(meshes=False), profile.arm)
            except (ArmError, UrdfError) as err:
                self.arm_error = f"arm topics off: {err}"
                log.warning("%s", self.arm_error)
        self.poses: PoseStore | None = None
        if self.arm_kinematics is not None:
            kin = self.arm_kinematics
            limits = {
                joint: (float(kin.chain.lower[i]), float(kin.chain.upper[i]))
                for i, joint in enumerate(kin.joints)
            }
            builtin = profile.arm.poses if profile.arm is not None else {}
            self.poses = PoseStore(builtin, kin.joints, limits, arm_poses_path)
            if self.poses.error:
                log.warning("stored arm poses: %s", self.poses.error)
        self._arm: ArmController | None = None
        self._arm_owned = False
        self._throttle = Throttle()

    # ---- life --------------------------------------------------------------------------

    def attach(
        self,
        sink: VelocitySink,
        limits: VelocityLimits | None = None,
        *,
        link_state: Callable[[], LinkState] | None = None,
    ) -> None:
        """Start commanding `sink`, bounded by `limits` (the link's; the profile's defaults
        if None); `link_state` reads the link's state now (else the last one reported)."""
        with self._lock:
            self._sink = sink
            self._limits = limits if limits is not None else VelocityLimits(self.profile)
            self._controller = PositionController(self.profile, self._limits)
            if self.arm_kinematics is not None:
                self._arm = ArmController(
                    self.profile, self._limits, self.arm_kinematics, self._controller
                )
            self._goal_channels = set()
            self._drive = self.settings.drive_zero
            self._timeout = CmdVelTimeout(self.settings.cmd_vel_timeout_s)
            # Read under the bridge's lock: a change the link makes meanwhile is reported
            # to on_link_state afterwards, which waits for this lock, so none is missed.
            if link_state is not None:
                self._link_state = link_state()
            if _is_lost(self._link_state):
                self._gate = LinkGate.LOST
            elif self._gate is not LinkGate.OPEN:
                # Off and on again while the link recovers: the recovery rule still holds.
                self._gate = LinkGate.RECOVERING
                self._open_if_quiet(self.clock())
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
        """ROS may command again after an override (the link gate still applies)."""
        with self._lock:
            if self._state is BridgeState.OVERRIDDEN and self._sink is not None:
                self._timeout = CmdVelTimeout(self.settings.cmd_vel_timeout_s)
                self._set_state(BridgeState.LISTENING)

    def _release(self) -> None:
        self._controller.cancel()
        self._goal_channels = set()
        self._drive = self.settings.drive_zero
        if self._arm is not None:
            self._arm.stop("ROS released the arm")
            self._arm.pop_messages()
        self._arm_owned = False

    def _owned_channels(self) -> list[str]:
        owned = [name for name, value in self._drive.items() if value != 0.0]
        arm = list(self._arm.channels) if self._arm is not None and self._arm_owned else []
        return owned + sorted(self._goal_channels | set(arm))

    @property
    def _in_control(self) -> bool:
        return self._sink is not None and self._state in (
            BridgeState.LISTENING,
            BridgeState.COMMANDING,
        )

    # ---- the link (link thread) --------------------------------------------------------

    def on_link_state(self, state: LinkState, reason: str = "") -> None:
        """The link changed state: LOST or CLOSED stops what ROS moves and closes the gate."""
        with self._lock:
            self._link_state = state
            if _is_lost(state):
                if self._gate is LinkGate.LOST:
                    return
                self._gate = LinkGate.LOST
                stopped = self._owned_channels() if self._in_control else []
                if stopped:
                    assert self._sink is not None
                    self._sink.set_velocities(**dict.fromkeys(stopped, 0.0))
                    # The prediction integrates what is sent: the zeros too.
                    self._controller.note_sent(self.clock(), {})
                if self._in_control:
                    self._release()
                    self._update_state()
                # A closed link is the normal end of a run: worth a line, not a warning.
                log.log(
                    logging.WARNING if state is LinkState.LOST else logging.INFO,
                    "%s%s: ROS commands refused, zeros sent%s",
                    "LINK LOST" if state is LinkState.LOST else "link closed",
                    f" ({reason})" if reason else "",
                    f" (stopped {', '.join(stopped)})" if stopped else "",
                )
            elif state is LinkState.CONNECTED and self._gate is LinkGate.LOST:
                self._gate = LinkGate.RECOVERING
                log.warning("%s", gate_text(LinkGate.RECOVERING, self.settings.cmd_vel_timeout_s))
                self._open_if_quiet(self.clock())

    def _open_if_quiet(self, now: float) -> None:
        """RECOVERING -> OPEN once cmd_vel has been zero or silent for the timeout."""
        if self._gate is not LinkGate.RECOVERING or self._link_state is not LinkState.CONNECTED:
            return
        quiet_s = None if self._last_motion_at is None else now - self._last_motion_at
        if quiet_s is not None and quiet_s < self.settings.cmd_vel_timeout_s:
            return
        self._gate = LinkGate.OPEN
        log.info(
            "cmd_vel zero or silent for %.2f s since the link came back: ROS may drive again",
            self.settings.cmd_vel_timeout_s,
        )

    # ---- inputs (any thread) -----------------------------------------------------------

    def on_cmd_vel(
        self, linear_x: float, angular_z: float, ignored: Sequence[float] = ()
    ) -> dict[str, float] | None:
        """A Twist arrived: returns the drive velocities sent, or None if not obeyed.

        Not obeyed: ROS is not in control (see `refusal()`), or the link gate is closed and
        the Twist asks for motion (zeros are sent instead). `ignored` are the other four
        Twist components, only to warn once that they do nothing. A non-finite component
        stops the tracks and raises BridgeError.
        """
        with self._lock:
            if not self._in_control:
                self._rejected += 1
                return None
            assert self._sink is not None
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
                bounds = drive_bounds(self.settings, self._limits)
                if bound_drive(linear_x, angular_z, bounds)[2] and self._throttle.allow("cmd_vel"):
                    linear, turn = self.settings.drive
                    log.warning(
                        "cmd_vel linear.x %.4g m/s, angular.z %.4g rad/s above the maxima "
                        "(%.2f m/s, %.2f rad/s): scaled to %.3f m/s, %.3f rad/s",
                        linear_x,
                        angular_z,
                        bounds.max_linear_m_s,
                        bounds.max_angular_rad_s,
                        drive[linear],
                        drive[turn],
                    )
            except BridgeError:
                # A broken publisher is no quiet one: it does not open the gate.
                self._last_motion_at = now
                self._rejected += 1
                self._send_drive(self.settings.drive_zero)
                self._update_state()
                raise
            motion = any(v != 0.0 for v in drive.values())
            if motion:
                # Checked before this Twist counts: it may be the first after a quiet spell.
                self._open_if_quiet(now)
                self._last_motion_at = now
            if motion and self._gate is not LinkGate.OPEN:
                self._link_refused += 1
                self._send_drive(self.settings.drive_zero)
                self._update_state()
                return None
            self._send_drive(drive)
            self._update_state()
            return drive

    def refusal(self) -> str:
        """Why cmd_vel is not obeyed now ('' when it is)."""
        with self._lock:
            if not self._in_control:
                return f"ROS control {self._state.value}"
            if self._gate is not LinkGate.OPEN:
                return gate_text(self._gate, self.settings.cmd_vel_timeout_s)
            return ""

    def set_goals(self, names: Sequence[str], positions: Sequence[float]) -> dict[str, float]:
        """Joint position goals (rad); all or none apply. PositionError if one is bad.

        An empty goal cancels every joint goal (their joints stop). While the link is lost,
        goals are refused: no telemetry, and recovery must not start motion by itself.
        """
        with self._lock:
            if not self._in_control:
                self._rejected += 1
                raise PositionError("joint goal ignored: ROS is not in control")
            if not names and not positions:
                self._stop_goals()
                self._update_state()
                return {}
            if self._gate is LinkGate.LOST:
                self._rejected += 1
                raise PositionError(f"joint goal ignored: {self._link_state.label}")
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
            self._controller.note_sent(self.clock(), self._drive)

    def on_telemetry(
        self,
        readings: Mapping[str, JointReading],
        received_at: float,
        delay_s: float | None = None,
    ) -> None:
        """Measured joint angles (and the round trip they took) for the position controller."""
        with self._lock:
            self._controller.on_telemetry(readings, received_at, delay_s)
            if self._arm is not None:
                self._arm.observe(readings)

    # ---- the arm (any thread) ----------------------------------------------------------

    @property
    def arm_available(self) -> bool:
        """Whether the arm topics work (the profile's [arm] and its URDF)."""
        return self.arm_kinematics is not None

    def _arm_ready(self, what: str) -> ArmController:
        """The arm controller when ROS may move it; ArmError (counted) otherwise."""
        if self._arm is None or not self._in_control:
            self._rejected += 1
            reason = self.arm_error or f"ROS control {self._state.value}"
            raise ArmError(f"{what} ignored: {reason}")
        if self._gate is LinkGate.LOST:
            self._rejected += 1
            raise ArmError(f"{what} ignored: {self._link_state.label}")
        return self._arm

    def _arm_takes_over(self) -> None:
        """Joint goals on the arm's joints end: the arm commands them now."""
        assert self._arm is not None
        for joint in self._arm.joints:
            self._controller.cancel(joint)
        self._goal_channels -= set(self._arm.channels)
        self._arm_owned = True

    def on_pose_goal(self, target: ToolPose) -> dict[str, float]:
        """Move tool0 to a position and pitch (base frame): IK, path check, one synchronized
        move. Returns the joint goal; ArmError with the reason when refused."""
        with self._lock:
            arm = self._arm_ready("pose goal")
            now = self.clock()
            try:
                _, start = arm.estimate(now)
                kin = arm.kinematics
                q = kin.solve(target, current=start)
                move = arm.plan_move(q, now)
            except ArmError:
                self._rejected += 1
                raise
            self._arm_takes_over()
            arm.start(move, now, target.describe())
            self._update_state()
            return kin.mapping(q)

    def on_named_pose(self, name: str) -> dict[str, float]:
        """Move to a stored pose (the profile's or the operator's file) by name."""
        with self._lock:
            arm = self._arm_ready("named pose")
            assert self.poses is not None
            now = self.clock()
            try:
                if len(name) > MAX_NAME_LENGTH:
                    # Not looked up (nor echoed whole by the store's message): no name is longer.
                    raise PoseError(
                        f"no stored pose is named {quoted(name)}: names are at most "
                        f"{MAX_NAME_LENGTH} characters"
                    )
                goal = self.poses.get(name)
                move = arm.plan_move(goal, now)
            except (ArmError, PoseError) as err:
                self._rejected += 1
                raise ArmError(str(err)) from err
            self._arm_takes_over()
            arm.start(move, now, name)
            self._update_state()
            return goal

    def on_arm_twist(self, linear: Sequence[float], angular: Sequence[float]) -> bool:
        """A twist of tool0 in the base frame: its linear velocity, and the angular velocity's
        part about the tool's pitch axis. Motion stops `twist_timeout_s` after the last one.
        Returns whether it was obeyed; a non-finite value stops the arm and raises ArmError."""
        with self._lock:
            arm = self._arm_ready("twist")
            now = self.clock()
            values = [float(v) for v in (*linear, *angular)]
            if len(values) != 6 or not all(math.isfinite(v) for v in values):
                arm.stop("a bad twist")
                self._rejected += 1
                raise ArmError("a twist needs six finite numbers")
            moving = any(values)
            if moving and self._gate is not LinkGate.OPEN:
                self._link_refused += 1
                return False
            try:
                current, _ = arm.estimate(now)
            except ArmError:
                self._rejected += 1
                raise
            tool = arm.kinematics.tool_matrix(current)
            settings = arm.settings
            # Bounded here, before the kinematics: a finite 1e308 overflows the Jacobian's
            # products into nan, and the chain refuses it in the control step.
            jog, clamped = bound_arm_twist(
                values[:3],
                values[3:],
                pitch_axis(tool, arm.kinematics.axis_xy),
                settings.max_linear_speed_m_s,
                settings.max_pitch_speed_rad_s,
            )
            if clamped and self._throttle.allow("arm twist"):
                log.warning(
                    "arm twist above the maxima (%.3f m/s, %.1f°/s): bounded to "
                    "(%.3f, %.3f, %.3f) m/s, %.1f°/s",
                    settings.max_linear_speed_m_s,
                    math.degrees(settings.max_pitch_speed_rad_s),
                    *jog[:3],
                    math.degrees(jog[3]),
                )
            if moving:
                self._arm_takes_over()
            arm.jog(jog, "base", now, expires_after_s=settings.twist_timeout_s)
            self._update_state()
            return True

    def goal_from_pose(
        self, position: Sequence[float], orientation_xyzw: Sequence[float]
    ) -> ToolPose:
        """A PoseStamped's content as the arm's goal: the position, and the pitch of the
        orientation's x axis (its yaw and roll are the arm's to choose)."""
        if self.arm_kinematics is None:
            raise ArmError(self.arm_error or "this robot has no arm profile")
        values = [float(v) for v in position]
        if len(values) != 3 or not all(math.isfinite(v) for v in values):
            raise ArmError("the goal's position must be three finite numbers")
        try:
            rotation = rotation_of(*(float(v) for v in orientation_xyzw))
        except (BridgeError, TypeError) as err:
            raise ArmError(str(err)) from err
        pose = np.eye(4)
        pose[:3, :3] = rotation
        pose[:3, 3] = values
        return ToolPose(
            values[0], values[1], values[2], pitch_of(pose, self.arm_kinematics.axis_xy)
        )

    def arm_tool_matrix(self, readings: Mapping[str, JointReading]) -> Matrix | None:
        """tool0's pose in the base frame from readings (None: an arm joint not read)."""
        kin = self.arm_kinematics
        if kin is None:
            return None
        angles = {
            name: r.angle_rad
            for name, r in readings.items()
            if r.angle_rad is not None and r.fault is None
        }
        if not all(joint in angles for joint in kin.joints):
            return None
        with self._lock:
            kin.hold(angles)
            return kin.tool_matrix(kin.vector(angles))

    # ---- periodic work -----------------------------------------------------------------

    def step(self, now: float | None = None) -> list[str]:
        """cmd_vel timeout and one position-control step; returns the controller's messages."""
        with self._lock:
            now = self.clock() if now is None else now
            self._open_if_quiet(now)
            if not self._in_control:
                return []
            assert self._sink is not None
            if self._timeout.expired(now):
                moving = any(v != 0.0 for v in self._drive.values())
                self._timeouts += 1
                if moving:
                    log.warning(
                        "no cmd_vel for %.2f s: tracks stopped", self.settings.cmd_vel_timeout_s
                    )
                    self._send_drive(self.settings.drive_zero)
            messages: list[str] = []
            velocities: dict[str, float] = {}
            # A controller that raises halts its own motion with the reason; the loop, the
            # other controllers and the node go on (MoveIt Servo halts, it does not exit).
            if self._goal_channels:
                try:
                    velocities = self._controller.update(now)
                except Exception as err:
                    velocities = {}
                    self._controller.cancel()
                    self._controller_failed("joint goals", err)
                for channel in self._goal_channels:
                    velocities.setdefault(channel, 0.0)
                self._goal_channels = {
                    self._controller.channel_of(j) for j in self._controller.targets
                }
                messages += self._controller.pop_messages()
            if self._arm is not None and (self._arm_owned or self._arm.active):
                try:
                    arm_velocities = self._arm.update(now)
                except Exception as err:
                    arm_velocities = {}
                    self._arm.stop(self._controller_failed("arm", err))
                for channel in self._arm.channels:
                    velocities[channel] = arm_velocities.get(channel, 0.0)
                self._arm_owned = self._arm.active
                messages += self._arm.pop_messages()
            if velocities:
                self._sink.set_velocities(**velocities)
                # The controller's prediction integrates what the bridge sent (delay-aware).
                self._controller.note_sent(now, {**self._drive, **velocities})
            self._update_state()
            return messages

    def _controller_failed(self, what: str, err: Exception) -> str:
        """Log (throttled) that a controller raised and was stopped; returns the reason."""
        reason = f"the {what} controller failed ({type(err).__name__}: {err})"
        if self._throttle.allow(f"failed {what}"):
            log.error("%s: %s stopped, ROS control goes on", reason, what, exc_info=err)
        return reason

    def halt(self, reason: str) -> list[str]:
        """Zero everything ROS moves and drop its goals, keeping control (the next command is
        obeyed); returns the channels zeroed. For a failure in the host's loop."""
        with self._lock:
            stopped = self._owned_channels() if self._in_control else []
            if stopped:
                assert self._sink is not None
                self._sink.set_velocities(**dict.fromkeys(stopped, 0.0))
                self._controller.note_sent(self.clock(), {})
            if self._in_control:
                self._release()
                self._update_state()
        if stopped:
            log.error("ROS motion halted (%s): %s zeroed", reason, ", ".join(stopped))
        return stopped

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
    def link_gate(self) -> LinkGate:
        """Whether the link lets ROS drive now."""
        with self._lock:
            return self._gate

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
                link_gate=self._gate,
                link_refused_count=self._link_refused,
                cmd_vel_timeout_s=self.settings.cmd_vel_timeout_s,
            )

    def _update_state(self) -> None:
        if self._state not in (BridgeState.LISTENING, BridgeState.COMMANDING):
            return
        arm = self._arm is not None and self._arm.active
        moving = any(v != 0.0 for v in self._drive.values()) or bool(self._goal_channels) or arm
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


def _is_lost(state: LinkState) -> bool:
    return state in (LinkState.LOST, LinkState.CLOSED)
