"""ROS message contents to the robot's terms and back, without ROS or Qt.

The bridge's settings (`BridgeSettings`, `BridgeError`) and the pure conversions it makes:
a Twist to drive channel velocities (`twist_to_drive`, `bound_drive`), a twist of tool0 to the
arm's jog (`bound_arm_twist`), quaternions to rotations and back, a JointState goal to joint
targets (`parse_joint_goal`) and readings to a JointState (`joint_state`), a camera's name;
the cmd_vel timeout (`CmdVelTimeout`); and the two helpers for log lines about bad messages
(`Throttle`, `quoted`).

cmd_vel mapping: `linear.x` drives `drive_linear` (m/s, forward positive) and `angular.z`
drives `drive_turn` (rad/s, counter-clockwise positive). A crawler cannot move sideways, up,
or roll: the other four Twist components are ignored. Both speeds are bounded and lifted to
the servos' starting speed with one common factor, so the turn radius is kept
(`ocu.control.drive.scale_drive`, seed 002 eq. 5.1-5.4).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ocu.control.commands import VelocityLimits
from ocu.control.drive import DriveBounds, DriveError, scale_drive
from ocu.control.position import PositionController, PositionError
from ocu.kinematics.arm import ArmError
from ocu.kinematics.chain import Vector
from ocu.model.tree import Matrix
from ocu.profile import RobotProfile
from ocu.records import JointReading

__all__ = [
    "DEFAULT_CMD_VEL_TIMEOUT_S",
    "DEFAULT_RATE_HZ",
    "MAX_CMD_VEL_TIMEOUT_S",
    "NO_DRIVE",
    "QUOTE_CHARS",
    "RATE_RANGE_HZ",
    "UNKNOWN_CAMERA",
    "WARNING_INTERVAL_S",
    "BridgeError",
    "BridgeSettings",
    "CmdVelTimeout",
    "JointStateData",
    "Throttle",
    "bound_arm_twist",
    "bound_drive",
    "camera_name",
    "drive_bounds",
    "joint_state",
    "parse_joint_goal",
    "quaternion_xyzw",
    "quoted",
    "rotation_of",
    "twist_to_drive",
]

DEFAULT_CMD_VEL_TIMEOUT_S = 0.5
# A longer silence would let a dead planner's last command run on for too long: the robot's
# own watchdog is 1 s, and the timeout also sets how long cmd_vel must be quiet after a
# link loss before ROS may drive again.
MAX_CMD_VEL_TIMEOUT_S = 2.0
DEFAULT_RATE_HZ = 50.0
RATE_RANGE_HZ = (5.0, 500.0)
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


NO_DRIVE = (
    "this robot has no chassis (no channels with the roles drive_linear and drive_turn): "
    "cmd_vel refused"
)


class BridgeError(ValueError):
    """A bridge setting or a velocity command that cannot be used."""


@dataclass(frozen=True)
class BridgeSettings:
    """The bridge's tunables; the node reads them from its private ROS parameters.

    The minima are robot facts: `from_profile` takes them from the drive channels, and the
    channels themselves from their roles (`drive`: the linear and the turn channel; None for
    a robot without a chassis, a UR arm: cmd_vel is refused).
    """

    min_linear_m_s: float
    min_angular_rad_s: float
    drive: tuple[str, str] | None
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
        """Defaults from the profile: the thresholds are the drive channels' min_speed (0 and
        no drive when the profile has no chassis: cmd_vel is then refused)."""
        drive = profile.drive_channels
        values: dict[str, float | bool | tuple[str, str] | None] = {
            "min_linear_m_s": profile.channels[drive[0]].min_speed if drive else 0.0,
            "min_angular_rad_s": profile.channels[drive[1]].min_speed if drive else 0.0,
            "drive": drive,
        }
        values.update(overrides)
        return cls(**values)  # type: ignore[arg-type]

    @property
    def drive_zero(self) -> dict[str, float]:
        """Both drive channels at zero (none without a chassis)."""
        return dict.fromkeys(self.drive or (), 0.0)

    def drive_channels(self) -> tuple[str, str]:
        """The linear and the turn channel; BridgeError when the robot has none."""
        if self.drive is None:
            raise BridgeError(NO_DRIVE)
        return self.drive


def drive_bounds(settings: BridgeSettings, limits: VelocityLimits) -> DriveBounds:
    """The chassis bounds now: maxima from the link's limits, minima from the settings."""
    linear, turn = settings.drive_channels()
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
    return dict(zip(settings.drive_channels(), (linear, angular), strict=True))


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
