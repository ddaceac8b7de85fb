"""What the robot is (its description): motors and their limits, cameras and their mounts, the
chassis, navigation, the arm, and the whole RobotProfile with where each value came from."""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from ocu.profile.hardware import Channel, ExtensionSettings, LinkSettings, VideoSettings
from ocu.profile.keys import DRIVE_LINEAR_ROLE, DRIVE_TURN_ROLE


@dataclass(frozen=True)
class CameraCalibration:
    """Intrinsics of one camera at the resolution it was calibrated at."""

    model: str
    size_px: tuple[int, int]
    focal_px: tuple[float, float]
    centre_px: tuple[float, float]
    distortion: tuple[float, ...]
    balance: float


@dataclass(frozen=True)
class CameraMount:
    """Where a camera sits on the chassis (base_link: x forward, y left, z up) and looks.

    Yaw turns the view left of straight ahead; pitch tilts it down. The simulator draws its
    world from here (ocu.sim.scene). With `link` (a URDF link, e.g. the arm's camera link)
    the offset is in that link's frame and the camera moves with the joints above it.
    """

    xyz_m: tuple[float, float, float]
    yaw_rad: float = 0.0
    pitch_rad: float = 0.0
    link: str | None = None


@dataclass(frozen=True)
class CameraSettings:
    """One camera: its name, calibration (None = not calibrated) and correction defaults."""

    name: str
    index: int
    calibration: CameraCalibration | None = None
    undistort: bool = False
    colour: str = "off"
    fixed_gains_rgb: tuple[float, float, float] = (1.0, 1.0, 1.0)
    mount: CameraMount | None = None


@dataclass(frozen=True)
class Footprint:
    """The chassis outline seen from above, about the turn centre (x forward, y left)."""

    front_m: float
    rear_m: float
    half_width_m: float

    @property
    def corners_m(self) -> tuple[tuple[float, float], ...]:
        """Front-left, rear-left, rear-right, front-right."""
        front, rear, half = self.front_m, -self.rear_m, self.half_width_m
        return ((front, half), (rear, half), (rear, -half), (front, -half))

    @property
    def swing_radius_m(self) -> float:
        """How far the farthest corner is from the turn centre (the circle a turn sweeps)."""
        return math.hypot(max(self.front_m, self.rear_m), self.half_width_m)


@dataclass(frozen=True)
class OdometrySettings:
    """Dead reckoning: when it is stale, and how its uncertainty grows (variance rates)."""

    stale_after_s: float = 2.5
    linear_noise_m2_per_m: float = 0.0004
    heading_noise_rad2_per_rad: float = 0.0025
    heading_drift_rad2_per_m: float = 0.0001
    commanded_noise_factor: float = 4.0
    imu_heading_sigma_rad: float = math.radians(0.5)


@dataclass(frozen=True)
class ZoneSettings:
    """Seed 002's safety zones (Algorithm 5.1), as travel to contact along the motion.

    Inside `stop_m` nothing moves toward the obstacle; inside `within_m[k]` the speeds are
    capped at `max_linear_m_s[k]` and `max_angular_rad_s[k]` with their ratio kept.
    """

    stop_m: float = 0.10
    within_m: tuple[float, ...] = (0.333, 0.633, 0.933)
    max_linear_m_s: tuple[float, ...] = (0.2, 0.25, 0.35)
    max_angular_rad_s: tuple[float, ...] = (0.3, 0.5, 0.8)


@dataclass(frozen=True)
class AssistSettings:
    """Seed 002's assisted modes: linear shuttle gain (eq. 5.5) and Samson's gains (eq. 3.18)."""

    linear_gain_m_per_s2: float = 0.05
    samson_b: float = 40.0
    samson_xi: float = 0.8
    cruise_m_s: float = 0.25
    goal_tolerance_m: float = 0.10
    max_lag_m: float = 0.4


@dataclass(frozen=True)
class NavigationSettings:
    """Driving with a map: footprint, range sensor, odometry, safety zones, assisted modes.

    `footprint` is None for a profile without a [navigation] table: the zones are then off.
    """

    footprint: Footprint | None = None
    scan_mount_xy_m: tuple[float, float] = (0.0, 0.0)
    scan_stale_after_s: float = 0.5
    odometry: OdometrySettings = OdometrySettings()
    zones: ZoneSettings = ZoneSettings()
    assist: AssistSettings = AssistSettings()


@dataclass(frozen=True)
class Measurement:
    """How one profile key was measured on a robot (`[measured."key"]`, by ocu calibrate)."""

    key: str
    how: str
    when: dt.datetime
    residual: float | None = None
    residual_unit: str | None = None
    samples: int | None = None


@dataclass(frozen=True)
class Motor:
    """One telemetry motor record: its device ID and how to read its position."""

    name: str
    device_id: int
    channel: str | None
    track: str | None
    ticks_per_rad: float | None
    zero_offset_ticks: int
    limits_rad: tuple[float, float] | None
    # The limits as the profile writes them: an operator types degrees, and 120° must be
    # compared with 120, not with degrees(radians(120)) = 119.99999999999999.
    limits_deg: tuple[float, float] | None = None

    @property
    def has_position(self) -> bool:
        """Whether this motor reports a shaft position (the tracks do not)."""
        return self.ticks_per_rad is not None


@dataclass(frozen=True)
class ArmSettings:
    """The arm in Cartesian space (docs/arm.md): its frames, jog speeds, safety margins.

    The links are the URDF's; `joints` are the motors that move the arm, from the base to the
    tool. `poses` are the stored poses every robot of this kind has (joint name -> rad).
    """

    base_link: str
    tool_link: str
    camera_link: str | None
    joints: tuple[str, ...]
    linear_speed_m_s: float
    max_linear_speed_m_s: float
    pitch_speed_rad_s: float
    max_pitch_speed_rad_s: float
    acceleration_rad_s2: float
    joint_limit_margin_rad: float
    singularity_slow: float
    singularity_stop: float
    clearance_m: float
    slow_distance_m: float
    ground_z_m: float | None
    twist_timeout_s: float
    poses: dict[str, dict[str, float]]
    # The tool frame's axis it points along, whose pitch the Cartesian task holds: "x" (the
    # Engineer's tool0) or "z" (ROS-Industrial's tool0 on a UR: z out of the flange).
    tool_axis: str = "x"


@dataclass(frozen=True)
class RobotProfile:
    """Everything the OCU knows about one robot model."""

    name: str
    source: str
    link: LinkSettings
    channels: dict[str, Channel]
    motors: dict[str, Motor]
    torch_button: int
    camera_button: int
    track_width_m: float
    telemetry_speed_per_rad_s: float
    telemetry_current_per_amp: float
    linear_axis_per_m_s: float
    rotation_axis_per_rad_s: float
    assumptions: tuple[str, ...]
    extension: ExtensionSettings | None = None
    video: VideoSettings = field(default_factory=VideoSettings)
    cameras: tuple[CameraSettings, ...] = ()
    arm: ArmSettings | None = None
    navigation: NavigationSettings = NavigationSettings()
    # Keys measured on a robot, by dotted name ("channels.shoulder.axis").
    measured: Mapping[str, Measurement] = field(default_factory=dict)
    # The robot's description (URDF) the 3D model and the arm's kinematics are built from;
    # None: the shipped Engineer model (ocu.model.urdf.profile_urdf_path).
    urdf: Path | None = None

    def provenance(self, key: str) -> str:
        """Where a dotted key's value comes from: "measured", "assumption" or "documents"."""
        if key in self.measured:
            return "measured"
        if any(assumption_covers(pattern, key) for pattern in self.assumptions):
            return "assumption"
        return "documents"

    def channel_with_role(self, role: str) -> str | None:
        """The channel that plays a role (e.g. "drive_linear"), or None."""
        for channel in self.channels.values():
            if channel.role == role:
                return channel.name
        return None

    @property
    def drive_channels(self) -> tuple[str, str] | None:
        """The chassis' (linear, turn) channels, or None for a robot without a chassis."""
        linear = self.channel_with_role(DRIVE_LINEAR_ROLE)
        turn = self.channel_with_role(DRIVE_TURN_ROLE)
        return (linear, turn) if linear is not None and turn is not None else None

    @property
    def switch_channels(self) -> list[str]:
        """Channels that have a three-way switch in the console."""
        return [c.name for c in self.channels.values() if c.switch]

    def motor_by_device(self, device_id: int) -> Motor | None:
        """The motor with this telemetry device ID, or None."""
        for motor in self.motors.values():
            if motor.device_id == device_id:
                return motor
        return None

    def motor_for_channel(self, channel: str) -> Motor | None:
        """The positioned motor driven by a velocity channel, or None."""
        for motor in self.motors.values():
            if motor.channel == channel:
                return motor
        return None

    @property
    def positioned_motors(self) -> list[Motor]:
        """Motors that report a position and are driven by a channel."""
        return [m for m in self.motors.values() if m.has_position and m.channel]


def assumption_covers(pattern: str, key: str) -> bool:
    """Whether an `assumptions` entry covers a dotted key.

    `*` stands for one table name ("channels.*.axis" covers "channels.waist.axis") and an
    entry naming a table covers every key in it ("buttons" covers "buttons.torch").
    """
    parts, wanted = pattern.split("."), key.split(".")
    if len(parts) > len(wanted):
        return False
    return all(p in ("*", k) for p, k in zip(parts, wanted, strict=False))
