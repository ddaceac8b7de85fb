"""Robot profile: load and validate the TOML file that holds every robot fact."""

from __future__ import annotations

import datetime as dt
import difflib
import itertools
import json
import math
import re
import tomllib
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from ocu.files import write_text_atomically

AXIS_COUNT = 16
BUTTON_COUNT = 16
AXIS_MAX = 32767
SCALE_NAMES = ("linear", "rotation", "joint")
# Roles a channel may play. The chassis is driven by one `drive_linear` channel (m/s) and one
# `drive_turn` channel (rad/s), bounded and lifted as a pair (ocu.control.drive).
DRIVE_LINEAR_ROLE = "drive_linear"
DRIVE_TURN_ROLE = "drive_turn"
CHANNEL_ROLES = (DRIVE_LINEAR_ROLE, DRIVE_TURN_ROLE)


# The keys each table of the profile may hold; any other key is refused by name, so a
# misspelt optional key is not silently ignored and a misspelt required one is named as
# what it is rather than reported as its correct spelling "missing".
TOP_KEYS = (
    "name",
    "assumptions",
    "link",
    "extension",
    "video",
    "cameras",
    "si",
    "chassis",
    "buttons",
    "channels",
    "motors",
    "arm",
    "navigation",
    "measured",
)
LINK_KEYS = (
    "address",
    "port",
    "send_rate_hz",
    "send_rate_min_hz",
    "send_rate_max_hz",
    "robot_watchdog_s",
    "telemetry_rate_hz",
    "telemetry_tick_hz",
    "link_lost_after_s",
    "gui_alive_timeout_s",
    "estop_repeats",
    "estop_window_s",
    "default_video_bitrate",
    "camera_names",
    "frame_types",
)
FRAME_TYPE_KEYS = ("rcp", "telemetry", "video")
EXTENSION_KEYS = (
    "probe",
    "frame_types",
    "max_datagram_bytes",
    "fit_datagrams_to_path",
    "stream_width_px",
    "stream_height_px",
    "stream_fps",
)
EXTENSION_FRAME_TYPE_KEYS = ("hello", "video_fragment", "status")
# Frame types an older profile may leave out; the extension then lacks that packet.
OPTIONAL_EXTENSION_FRAME_TYPE_KEYS = ("scan", "rcp")
VIDEO_KEYS = (
    "no_signal_after_s",
    "battery_warning_percent",
    "reassembly_max_frames",
    "reassembly_max_bytes",
    "reassembly_timeout_s",
    "decode_at_display_size",
    "opencv_threads",
)
CAMERA_KEYS = (
    "model",
    "calibration_size_px",
    "focal_px",
    "centre_px",
    "distortion",
    "balance",
    "undistort",
    "colour",
    "fixed_gains_rgb",
    *("mount_xyz_m", "mount_yaw_deg", "mount_pitch_deg", "mount_link"),
)
SI_KEYS = (
    "linear_axis_per_m_s",
    "rotation_axis_per_rad_s",
    "joint_axis_per_rad_s",
    "telemetry_speed_per_rad_s",
    "telemetry_current_per_amp",
)
CHASSIS_KEYS = ("track_width_m",)
NAVIGATION_KEYS = (
    "footprint_front_m",
    "footprint_rear_m",
    "footprint_half_width_m",
    "scan_mount_xy_m",
    "scan_stale_after_s",
    "odometry",
    "zones",
    "assist",
)
ODOMETRY_KEYS = (
    "stale_after_s",
    "linear_noise_m2_per_m",
    "heading_noise_rad2_per_rad",
    "heading_drift_rad2_per_m",
    "commanded_noise_factor",
    "imu_heading_sigma_deg",
)
ZONE_KEYS = ("stop_m", "within_m", "max_linear_m_s", "max_angular_rad_s")
ASSIST_KEYS = (
    "linear_gain_m_per_s2",
    "samson_b",
    "samson_xi",
    "cruise_m_s",
    "goal_tolerance_m",
    "max_lag_m",
)
BUTTON_KEYS = ("torch", "camera_select")
CHANNEL_KEYS = (
    "axis",
    "scale",
    "unit",
    "min_speed",
    "default_max",
    "hard_max",
    "role",
    "switch",
    "directions",
    "locked_while_driving",
    "axis_sign",
    "axis_per_unit",
)
# A motor's position keys only mean something with ticks_per_rad.
MOTOR_POSITION_KEYS = ("zero_offset_ticks", "limits_deg")
MOTOR_KEYS = ("device_id", "channel", "track", "ticks_per_rad", *MOTOR_POSITION_KEYS)

ARM_KEYS = (
    "base_link",
    "tool_link",
    "camera_link",
    "joints",
    "linear_speed_m_s",
    "max_linear_speed_m_s",
    "pitch_speed_deg_s",
    "max_pitch_speed_deg_s",
    "acceleration_deg_s2",
    "joint_limit_margin_deg",
    "singularity_slow",
    "singularity_stop",
    "clearance_m",
    "slow_distance_m",
    "ground_z_m",
    "twist_timeout_s",
    "poses",
)
# What a `[measured."some.key"]` entry may say about how that key was measured on a robot.
MEASUREMENT_KEYS = ("how", "when", "residual", "residual_unit", "samples")
# Table names are TOML bare keys; the dotted names in `measured` and `assumptions` join them.
_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")
# Arrays longer than this are written one item per line.
TOML_LINE_LENGTH = 96

CAMERA_MODELS = ("fisheye", "standard")
COLOUR_MODES = ("off", "gray_world", "fixed")
# Distortion coefficients per model: cv2.fisheye takes k1..k4; the standard (Brown-Conrady)
# model k1, k2, p1, p2 and optionally k3.
DISTORTION_LENGTHS = {"fisheye": (4,), "standard": (4, 5)}


class ProfileError(ValueError):
    """The robot profile is missing a value or holds a bad one."""


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """A "did you mean 'x'?" hint for a misspelt word, else the list of choices."""
    names = list(choices)
    # Case-blind: "space" is a misspelling of "Space", not an unrelated word.
    by_folded = {name.casefold(): name for name in names}
    close = difflib.get_close_matches(word.casefold(), by_folded, n=1)
    if close:
        return f"did you mean {by_folded[close[0]]!r}?"
    return f"known: {', '.join(names)}" if names else "nothing is expected here"


@dataclass(frozen=True)
class FrameTypes:
    """Wire IDs of the vendor packet types."""

    rcp: int
    telemetry: int
    video: int


@dataclass(frozen=True)
class LinkSettings:
    """Network and timing facts of the link."""

    address: str
    port: int
    send_rate_hz: float
    send_rate_min_hz: float
    send_rate_max_hz: float
    robot_watchdog_s: float
    telemetry_rate_hz: float
    telemetry_tick_hz: float
    link_lost_after_s: float
    gui_alive_timeout_s: float
    estop_repeats: int
    estop_window_s: float
    default_video_bitrate: float
    camera_names: tuple[str, ...]
    frame_types: FrameTypes


@dataclass(frozen=True)
class ExtensionFrameTypes:
    """Wire IDs of our protocol extension's packet types (not vendor facts)."""

    hello: int
    video_fragment: int
    status: int
    # The planar range scan (robot -> OCU); None: this extension has no range sensor.
    scan: int | None = None
    # The sequenced RCP (OCU -> robot); None: the OCU sends vendor RCPs to any robot.
    rcp: int | None = None


@dataclass(frozen=True)
class ExtensionSettings:
    """The open protocol extension: its IDs and what the OCU asks of an extended robot."""

    probe: bool
    frame_types: ExtensionFrameTypes
    max_datagram_bytes: int
    stream_width_px: int
    stream_height_px: int
    stream_fps: int
    # Ask for datagrams as large as the route's MTU carries unfragmented (65507 bytes on the
    # loopback, 1472 on a 1500-byte link); max_datagram_bytes where the MTU is unknown.
    fit_datagrams_to_path: bool = True


@dataclass(frozen=True)
class VideoSettings:
    """OCU-side video settings: no-signal time, battery warning, reassembly bounds."""

    no_signal_after_s: float = 1.0
    battery_warning_percent: float = 20.0
    reassembly_max_frames: int = 16
    reassembly_max_bytes: int = 8 * 1024 * 1024
    reassembly_timeout_s: float = 0.5
    # Decode each JPEG at the size its cell shows it (libjpeg DCT scaling, 1/2 to 1/8).
    decode_at_display_size: bool = True
    # OpenCV's worker threads for decoding and correction; 0: OpenCV's own choice.
    opencv_threads: int = 1


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
class Channel:
    """One velocity channel: which RCP axis carries it, how SI maps to axis units, its role.

    `directions` are the words for + and − ("up", "down"); `switch` gives the channel a
    three-way switch in the console; `locked_while_driving` says the robot refuses to move it
    while the chassis moves (the Engineer's waist). `axis_sign` is -1 when the robot moves the
    channel the negative way for a positive axis value (the OCU then sends the axis negated).
    `axis_per_unit` is the channel's own scale when the profile gives one, else the SI
    constant its `scale` names.
    """

    name: str
    axis: int
    axis_per_unit: float
    unit: str
    min_speed: float
    default_max: float
    hard_max: float
    role: str | None = None
    switch: bool = False
    directions: tuple[str, str] = ("+", "-")
    locked_while_driving: bool = False
    axis_sign: int = 1


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
    video: VideoSettings = VideoSettings()
    cameras: tuple[CameraSettings, ...] = ()
    arm: ArmSettings | None = None
    navigation: NavigationSettings = NavigationSettings()
    # Keys measured on a robot, by dotted name ("channels.shoulder.axis").
    measured: Mapping[str, Measurement] = field(default_factory=dict)

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


def default_profile_path() -> Path:
    """Path of the Engineer profile shipped with the package."""
    return Path(str(resources.files("ocu") / "profiles" / "engineer.toml"))


def load_profile(path: str | Path | None = None) -> RobotProfile:
    """Read and validate a profile; the shipped Engineer profile when path is None."""
    profile_path = Path(path) if path is not None else default_profile_path()
    return parse_profile(load_profile_data(profile_path), source=str(profile_path))


def load_profile_data(path: str | Path | None = None) -> dict[str, Any]:
    """A profile file's TOML document, not yet validated (the shipped one when path is None).

    For tools that write a profile from another one (ocu calibrate, ocu-sim --scramble).
    """
    profile_path = Path(path) if path is not None else default_profile_path()
    try:
        text = profile_path.read_text(encoding="utf-8")
    except OSError as err:
        raise ProfileError(f"cannot read profile {profile_path}: {err.strerror}") from err
    except UnicodeDecodeError as err:
        raise ProfileError(f"{profile_path}: not UTF-8 text: {err}") from err
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ProfileError(f"{profile_path}: not valid TOML: {err}") from err


class _Reader:
    """Typed access to a TOML table with error messages that name the key.

    With `keys`, a key outside them is refused at once, before any value is read.
    """

    def __init__(
        self,
        table: dict[str, Any],
        where: str,
        keys: Collection[str] | None,
        unknown: str = "unknown key",
    ) -> None:
        self.table = table
        self.where = where
        if keys is not None:
            errors = [
                f"{where}.{key}: {unknown}; {did_you_mean(key, keys)}"
                for key in table
                if key not in keys
            ]
            if errors:
                raise ProfileError("; ".join(errors))

    def _get(self, key: str) -> Any:
        if key not in self.table:
            raise ProfileError(f"{self.where}.{key}: missing")
        return self.table[key]

    def sub(self, key: str, keys: Collection[str] | None, unknown: str = "unknown key") -> _Reader:
        value = self._get(key)
        if not isinstance(value, dict):
            raise ProfileError(f"{self.where}.{key}: must be a table")
        return _Reader(value, f"{self.where}.{key}", keys, unknown)

    def number(self, key: str, *, low: float | None = None, high: float | None = None) -> float:
        value = self._get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ProfileError(f"{self.where}.{key}: must be a number, got {value!r}")
        number = float(value)
        if not math.isfinite(number):
            raise ProfileError(f"{self.where}.{key}: must be finite, got {value!r}")
        if low is not None and number < low:
            raise ProfileError(f"{self.where}.{key}: must be >= {low}, got {value!r}")
        if high is not None and number > high:
            raise ProfileError(f"{self.where}.{key}: must be <= {high}, got {value!r}")
        return number

    def integer(self, key: str, *, low: int, high: int) -> int:
        value = self._get(key)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ProfileError(f"{self.where}.{key}: must be an integer, got {value!r}")
        if not low <= value <= high:
            raise ProfileError(f"{self.where}.{key}: must be in [{low}, {high}], got {value}")
        return value

    def string(self, key: str) -> str:
        value = self._get(key)
        if not isinstance(value, str) or not value:
            raise ProfileError(f"{self.where}.{key}: must be a non-empty string")
        return value

    def optional(self, key: str) -> bool:
        return key in self.table

    def boolean(self, key: str) -> bool:
        value = self._get(key)
        if not isinstance(value, bool):
            raise ProfileError(f"{self.where}.{key}: must be true or false, got {value!r}")
        return value

    def choice(self, key: str, choices: tuple[str, ...]) -> str:
        value = self.string(key)
        if value not in choices:
            raise ProfileError(f"{self.where}.{key}: must be one of {choices}, got {value!r}")
        return value

    def numbers(
        self, key: str, lengths: tuple[int, ...], *, low: float | None = None
    ) -> tuple[float, ...]:
        value = self._get(key)
        if (
            not isinstance(value, list)
            or len(value) not in lengths
            or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in value
            )
        ):
            sizes = " or ".join(str(n) for n in lengths)
            raise ProfileError(f"{self.where}.{key}: must be a list of {sizes} finite numbers")
        if low is not None and any(v < low for v in value):
            raise ProfileError(f"{self.where}.{key}: every value must be >= {low}")
        return tuple(float(v) for v in value)


def _parse_channel(name: str, reader: _Reader, scales: dict[str, float]) -> Channel:
    axis = reader.integer("axis", low=0, high=AXIS_COUNT - 1)
    scale = reader.string("scale")
    if scale not in scales:
        raise ProfileError(f"{reader.where}.scale: must be one of {SCALE_NAMES}, got {scale!r}")
    per_unit = scales[scale]
    if reader.optional("axis_per_unit"):
        per_unit = reader.number("axis_per_unit", low=1e-9)
    axis_sign = 1
    if reader.optional("axis_sign"):
        axis_sign = reader.integer("axis_sign", low=-1, high=1)
        if axis_sign == 0:
            raise ProfileError(f"{reader.where}.axis_sign: must be 1 or -1, got 0")
    min_speed = reader.number("min_speed", low=0.0)
    hard_max = reader.number("hard_max", low=0.0)
    default_max = reader.number("default_max", low=0.0, high=hard_max)
    if min_speed > default_max:
        raise ProfileError(f"{reader.where}.min_speed: above default_max ({default_max})")
    if hard_max * per_unit > AXIS_MAX:
        limit = AXIS_MAX / per_unit
        raise ProfileError(
            f"{reader.where}.hard_max: {hard_max} needs axis value {hard_max * per_unit:.0f}, "
            f"over the int16 range; at most {limit:.4f}"
        )
    role = reader.choice("role", CHANNEL_ROLES) if reader.optional("role") else None
    directions: tuple[str, str] = ("+", "-")
    if reader.optional("directions"):
        words = reader.table["directions"]
        if (
            not isinstance(words, list)
            or len(words) != 2
            or not all(isinstance(w, str) and w.strip() for w in words)
        ):
            raise ProfileError(
                f'{reader.where}.directions: two words for + and -, e.g. ["up", "down"]'
            )
        directions = (words[0].strip(), words[1].strip())
    return Channel(
        name=name,
        axis=axis,
        axis_per_unit=per_unit,
        unit=reader.string("unit"),
        min_speed=min_speed,
        default_max=default_max,
        hard_max=hard_max,
        role=role,
        switch=reader.boolean("switch") if reader.optional("switch") else False,
        directions=directions,
        locked_while_driving=(
            reader.boolean("locked_while_driving")
            if reader.optional("locked_while_driving")
            else False
        ),
        axis_sign=axis_sign,
    )


def _parse_motor(name: str, reader: _Reader, channels: dict[str, Channel]) -> Motor:
    device_id = reader.integer("device_id", low=0, high=255)
    channel = reader.string("channel") if reader.optional("channel") else None
    if channel is not None and channel not in channels:
        hint = did_you_mean(channel, channels)
        raise ProfileError(f"{reader.where}.channel: unknown channel {channel!r}; {hint}")
    track = reader.string("track") if reader.optional("track") else None
    if track is not None and track not in ("left", "right"):
        raise ProfileError(f"{reader.where}.track: must be 'left' or 'right'")
    ticks_per_rad: float | None = None
    zero_offset = 0
    limits: tuple[float, float] | None = None
    limits_deg: tuple[float, float] | None = None
    if reader.optional("ticks_per_rad"):
        ticks_per_rad = reader.number("ticks_per_rad", low=1e-9)
        zero_offset = reader.integer("zero_offset_ticks", low=0, high=2**32 - 1)
        raw_limits = reader.table.get("limits_deg")
        if (
            not isinstance(raw_limits, list)
            or len(raw_limits) != 2
            or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in raw_limits
            )
            or not raw_limits[0] < raw_limits[1]
        ):
            raise ProfileError(
                f"{reader.where}.limits_deg: two finite numbers; "
                "must be [low, high] with low < high"
            )
        limits_deg = (float(raw_limits[0]), float(raw_limits[1]))
        limits = (math.radians(limits_deg[0]), math.radians(limits_deg[1]))
    else:
        for key in MOTOR_POSITION_KEYS:
            if reader.optional(key):
                raise ProfileError(
                    f"{reader.where}.{key}: needs ticks_per_rad (without it the motor "
                    "reports no position)"
                )
    return Motor(
        name=name,
        device_id=device_id,
        channel=channel,
        track=track,
        ticks_per_rad=ticks_per_rad,
        zero_offset_ticks=zero_offset,
        limits_rad=limits,
        limits_deg=limits_deg,
    )


def _parse_extension(reader: _Reader, vendor: FrameTypes) -> ExtensionSettings:
    types_reader = reader.sub(
        "frame_types", (*EXTENSION_FRAME_TYPE_KEYS, *OPTIONAL_EXTENSION_FRAME_TYPE_KEYS)
    )
    types = ExtensionFrameTypes(
        hello=types_reader.integer("hello", low=0, high=255),
        video_fragment=types_reader.integer("video_fragment", low=0, high=255),
        status=types_reader.integer("status", low=0, high=255),
        scan=(
            types_reader.integer("scan", low=0, high=255) if types_reader.optional("scan") else None
        ),
        rcp=types_reader.integer("rcp", low=0, high=255) if types_reader.optional("rcp") else None,
    )
    ids = [types.hello, types.video_fragment, types.status, vendor.rcp, vendor.telemetry]
    ids.append(vendor.video)
    ids.extend(extra for extra in (types.scan, types.rcp) if extra is not None)
    if len(set(ids)) != len(ids):
        raise ProfileError(
            f"{types_reader.where}: the IDs must differ from each other and from link.frame_types"
        )
    return ExtensionSettings(
        probe=reader.boolean("probe"),
        frame_types=types,
        # 64 bytes leave room for the fragment header; 65507 is the UDP/IPv4 payload limit.
        max_datagram_bytes=reader.integer("max_datagram_bytes", low=64, high=65507),
        stream_width_px=reader.integer("stream_width_px", low=16, high=4096),
        stream_height_px=reader.integer("stream_height_px", low=16, high=4096),
        stream_fps=reader.integer("stream_fps", low=0, high=255),
        fit_datagrams_to_path=(
            reader.boolean("fit_datagrams_to_path")
            if reader.optional("fit_datagrams_to_path")
            else ExtensionSettings.fit_datagrams_to_path
        ),
    )


def _parse_video(reader: _Reader) -> VideoSettings:
    return VideoSettings(
        no_signal_after_s=reader.number("no_signal_after_s", low=0.01),
        battery_warning_percent=reader.number("battery_warning_percent", low=0.0, high=100.0),
        reassembly_max_frames=reader.integer("reassembly_max_frames", low=1, high=1024),
        reassembly_max_bytes=reader.integer("reassembly_max_bytes", low=65536, high=2**30),
        reassembly_timeout_s=reader.number("reassembly_timeout_s", low=0.001),
        decode_at_display_size=(
            reader.boolean("decode_at_display_size")
            if reader.optional("decode_at_display_size")
            else VideoSettings.decode_at_display_size
        ),
        opencv_threads=(
            reader.integer("opencv_threads", low=0, high=64)
            if reader.optional("opencv_threads")
            else VideoSettings.opencv_threads
        ),
    )


def _parse_camera(name: str, index: int, reader: _Reader) -> CameraSettings:
    model = reader.choice("model", CAMERA_MODELS)
    size = reader.numbers("calibration_size_px", (2,), low=1.0)
    if not all(v.is_integer() for v in size):
        raise ProfileError(f"{reader.where}.calibration_size_px: must be whole pixels")
    focal = reader.numbers("focal_px", (2,), low=1e-6)
    centre = reader.numbers("centre_px", (2,))
    if not (0.0 <= centre[0] <= size[0] and 0.0 <= centre[1] <= size[1]):
        raise ProfileError(f"{reader.where}.centre_px: must lie inside calibration_size_px")
    distortion = reader.numbers("distortion", DISTORTION_LENGTHS[model])
    gains = reader.numbers("fixed_gains_rgb", (3,), low=0.0)
    calibration = CameraCalibration(
        model=model,
        size_px=(int(size[0]), int(size[1])),
        focal_px=(focal[0], focal[1]),
        centre_px=(centre[0], centre[1]),
        distortion=distortion,
        balance=reader.number("balance", low=0.0, high=1.0),
    )
    return CameraSettings(
        name=name,
        index=index,
        calibration=calibration,
        undistort=reader.boolean("undistort"),
        colour=reader.choice("colour", COLOUR_MODES),
        fixed_gains_rgb=(gains[0], gains[1], gains[2]),
        mount=_parse_mount(reader),
    )


def _parse_mount(reader: _Reader) -> CameraMount | None:
    if not reader.optional("mount_xyz_m"):
        for key in ("mount_yaw_deg", "mount_pitch_deg", "mount_link"):
            if reader.optional(key):
                raise ProfileError(f"{reader.where}.{key}: needs mount_xyz_m")
        return None
    xyz = reader.numbers("mount_xyz_m", (3,))
    yaw = reader.number("mount_yaw_deg", low=-180.0, high=180.0)
    pitch = (
        reader.number("mount_pitch_deg", low=-89.0, high=89.0)
        if reader.optional("mount_pitch_deg")
        else 0.0
    )
    link = reader.string("mount_link") if reader.optional("mount_link") else None
    return CameraMount((xyz[0], xyz[1], xyz[2]), math.radians(yaw), math.radians(pitch), link)


def _ascending(reader: _Reader, key: str, count: int | None, low: float) -> tuple[float, ...]:
    value = reader.table.get(key)
    lengths = (count,) if count is not None else tuple(range(1, 9))
    numbers = reader.numbers(key, lengths, low=low)
    if count is None and any(b <= a for a, b in itertools.pairwise(numbers)):
        raise ProfileError(f"{reader.where}.{key}: must grow from zone to zone, got {value!r}")
    return numbers


def _parse_navigation(reader: _Reader) -> NavigationSettings:
    default = NavigationSettings()
    footprint = Footprint(
        front_m=reader.number("footprint_front_m", low=0.01),
        rear_m=reader.number("footprint_rear_m", low=0.01),
        half_width_m=reader.number("footprint_half_width_m", low=0.01),
    )
    mount = reader.numbers("scan_mount_xy_m", (2,)) if reader.optional("scan_mount_xy_m") else None
    odometry = default.odometry
    if reader.optional("odometry"):
        o = reader.sub("odometry", ODOMETRY_KEYS)
        odometry = OdometrySettings(
            stale_after_s=o.number("stale_after_s", low=0.05),
            linear_noise_m2_per_m=o.number("linear_noise_m2_per_m", low=0.0),
            heading_noise_rad2_per_rad=o.number("heading_noise_rad2_per_rad", low=0.0),
            heading_drift_rad2_per_m=o.number("heading_drift_rad2_per_m", low=0.0),
            commanded_noise_factor=o.number("commanded_noise_factor", low=1.0),
            imu_heading_sigma_rad=math.radians(o.number("imu_heading_sigma_deg", low=0.0)),
        )
    zones = default.zones
    if reader.optional("zones"):
        z = reader.sub("zones", ZONE_KEYS)
        within = _ascending(z, "within_m", None, 0.0)
        stop = z.number("stop_m", low=0.0)
        if within[0] <= stop:
            raise ProfileError(f"{z.where}.within_m: the first zone must lie beyond stop_m")
        zones = ZoneSettings(
            stop_m=stop,
            within_m=within,
            max_linear_m_s=_ascending(z, "max_linear_m_s", len(within), 1e-6),
            max_angular_rad_s=_ascending(z, "max_angular_rad_s", len(within), 1e-6),
        )
    assist = default.assist
    if reader.optional("assist"):
        a = reader.sub("assist", ASSIST_KEYS)
        assist = AssistSettings(
            linear_gain_m_per_s2=a.number("linear_gain_m_per_s2", low=1e-6),
            samson_b=a.number("samson_b", low=0.0),
            samson_xi=a.number("samson_xi", low=0.01, high=1.0),
            cruise_m_s=a.number("cruise_m_s", low=0.01),
            goal_tolerance_m=a.number("goal_tolerance_m", low=0.001),
            max_lag_m=a.number("max_lag_m", low=0.01),
        )
    return NavigationSettings(
        footprint=footprint,
        scan_mount_xy_m=(mount[0], mount[1]) if mount is not None else default.scan_mount_xy_m,
        scan_stale_after_s=(
            reader.number("scan_stale_after_s", low=0.01)
            if reader.optional("scan_stale_after_s")
            else default.scan_stale_after_s
        ),
        odometry=odometry,
        zones=zones,
        assist=assist,
    )


def _parse_cameras(root: _Reader, names: tuple[str, ...]) -> tuple[CameraSettings, ...]:
    # A camera without a table has no calibration and no correction by default.
    tables = (
        root.sub("cameras", names, unknown="not in link.camera_names")
        if root.optional("cameras")
        else _Reader({}, "profile.cameras", None)
    )
    return tuple(
        _parse_camera(name, index, tables.sub(name, CAMERA_KEYS))
        if tables.optional(name)
        else CameraSettings(name=name, index=index)
        for index, name in enumerate(names)
    )


def _parse_arm(reader: _Reader, motors: dict[str, Motor]) -> ArmSettings:
    joints = reader.table.get("joints")
    if not isinstance(joints, list) or not joints or not all(isinstance(j, str) for j in joints):
        raise ProfileError(f"{reader.where}.joints: must be a non-empty list of motor names")
    for name in joints:
        motor = motors.get(name)
        if motor is None:
            raise ProfileError(
                f"{reader.where}.joints: unknown motor {name!r}; {did_you_mean(name, motors)}"
            )
        if not motor.has_position or motor.channel is None:
            raise ProfileError(
                f"{reader.where}.joints: {name!r} must report a position and have a channel"
            )
    if len(set(joints)) != len(joints):
        raise ProfileError(f"{reader.where}.joints: a joint is named twice")
    linear = reader.number("linear_speed_m_s", low=1e-6)
    pitch = reader.number("pitch_speed_deg_s", low=1e-6)
    slow = reader.number("singularity_slow", low=1.0)
    poses: dict[str, dict[str, float]] = {}
    if reader.optional("poses"):
        table = reader.sub("poses", None)
        for name in table.table:
            pose = table.sub(name, joints, unknown="not one of arm.joints")
            angles = {}
            for joint in pose.table:
                degrees = pose.number(joint)
                low, high = motors[joint].limits_deg or (-math.inf, math.inf)
                if not low <= degrees <= high:
                    raise ProfileError(
                        f"{pose.where}.{joint}: {degrees}° outside the limits [{low}, {high}]"
                    )
                angles[joint] = math.radians(degrees)
            if set(angles) != set(joints):
                missing = ", ".join(j for j in joints if j not in angles)
                raise ProfileError(f"{pose.where}: every arm joint needs an angle ({missing})")
            poses[name] = angles
    return ArmSettings(
        base_link=reader.string("base_link"),
        tool_link=reader.string("tool_link"),
        camera_link=reader.string("camera_link") if reader.optional("camera_link") else None,
        joints=tuple(joints),
        linear_speed_m_s=linear,
        max_linear_speed_m_s=reader.number("max_linear_speed_m_s", low=linear),
        pitch_speed_rad_s=math.radians(pitch),
        max_pitch_speed_rad_s=math.radians(reader.number("max_pitch_speed_deg_s", low=pitch)),
        acceleration_rad_s2=math.radians(reader.number("acceleration_deg_s2", low=1e-3)),
        joint_limit_margin_rad=math.radians(
            reader.number("joint_limit_margin_deg", low=0.0, high=45.0)
        ),
        singularity_slow=slow,
        singularity_stop=reader.number("singularity_stop", low=slow),
        clearance_m=reader.number("clearance_m", low=0.0),
        slow_distance_m=reader.number("slow_distance_m", low=0.0),
        ground_z_m=reader.number("ground_z_m") if reader.optional("ground_z_m") else None,
        twist_timeout_s=reader.number("twist_timeout_s", low=0.01, high=2.0),
        poses=poses,
    )


def parse_profile(data: dict[str, Any], source: str = "<profile>") -> RobotProfile:
    """Validate a decoded TOML document and build the profile."""
    root = _Reader(data, "profile", TOP_KEYS)
    link = root.sub("link", LINK_KEYS)
    frame_reader = link.sub("frame_types", FRAME_TYPE_KEYS)
    frame_types = FrameTypes(
        rcp=frame_reader.integer("rcp", low=0, high=255),
        telemetry=frame_reader.integer("telemetry", low=0, high=255),
        video=frame_reader.integer("video", low=0, high=255),
    )
    if len({frame_types.rcp, frame_types.telemetry, frame_types.video}) != 3:
        raise ProfileError("profile.link.frame_types: the three IDs must differ")
    rate_min = link.number("send_rate_min_hz", low=0.1)
    rate_max = link.number("send_rate_max_hz", low=rate_min)
    cameras = link.table.get("camera_names")
    if not isinstance(cameras, list) or not cameras or not all(isinstance(c, str) for c in cameras):
        raise ProfileError("profile.link.camera_names: must be a non-empty list of names")
    if len(set(cameras)) != len(cameras) or len(cameras) > 255:
        raise ProfileError("profile.link.camera_names: names must be distinct, at most 255")
    link_settings = LinkSettings(
        address=link.string("address"),
        port=link.integer("port", low=1, high=65535),
        send_rate_hz=link.number("send_rate_hz", low=rate_min, high=rate_max),
        send_rate_min_hz=rate_min,
        send_rate_max_hz=rate_max,
        robot_watchdog_s=link.number("robot_watchdog_s", low=0.01),
        telemetry_rate_hz=link.number("telemetry_rate_hz", low=0.01),
        telemetry_tick_hz=link.number("telemetry_tick_hz", low=1.0),
        link_lost_after_s=link.number("link_lost_after_s", low=0.01),
        gui_alive_timeout_s=link.number("gui_alive_timeout_s", low=0.01),
        estop_repeats=link.integer("estop_repeats", low=1, high=100),
        estop_window_s=link.number("estop_window_s", low=0.0, high=1.0),
        default_video_bitrate=link.number("default_video_bitrate", low=0.0),
        camera_names=tuple(cameras),
        frame_types=frame_types,
    )

    si = root.sub("si", SI_KEYS)
    scales = {
        "linear": si.number("linear_axis_per_m_s", low=1e-9),
        "rotation": si.number("rotation_axis_per_rad_s", low=1e-9),
        "joint": si.number("joint_axis_per_rad_s", low=1e-9),
    }
    # Channels are named by the profile; what they do is their role.
    channels_reader = root.sub("channels", None)
    channels: dict[str, Channel] = {}
    for name in channels_reader.table:
        channels[name] = _parse_channel(name, channels_reader.sub(name, CHANNEL_KEYS), scales)
    if not channels:
        raise ProfileError("profile.channels: at least one channel is needed")
    axes = [c.axis for c in channels.values()]
    if len(set(axes)) != len(axes):
        raise ProfileError("profile.channels: two channels share one axis")
    for role in CHANNEL_ROLES:
        having = [c.name for c in channels.values() if c.role == role]
        if len(having) > 1:
            raise ProfileError(f"profile.channels: {having} all have role {role!r}; one may")
    roles = {c.role for c in channels.values() if c.role is not None}
    if roles and roles != set(CHANNEL_ROLES):
        raise ProfileError(
            f"profile.channels: the chassis needs both roles {list(CHANNEL_ROLES)}, "
            f"found only {sorted(roles)}"
        )

    # Motors are named by the profile: any name, each a table of known keys.
    motors_reader = root.sub("motors", None)
    motors: dict[str, Motor] = {}
    for name in motors_reader.table:
        motors[name] = _parse_motor(name, motors_reader.sub(name, MOTOR_KEYS), channels)
    ids = [m.device_id for m in motors.values()]
    if len(set(ids)) != len(ids):
        raise ProfileError("profile.motors: two motors share one device_id")
    if len(motors) > 10:
        raise ProfileError("profile.motors: the telemetry packet carries at most 10 motors")

    buttons = root.sub("buttons", BUTTON_KEYS)
    torch = buttons.integer("torch", low=0, high=BUTTON_COUNT - 1)
    camera = buttons.integer("camera_select", low=0, high=BUTTON_COUNT - 1)
    if torch == camera:
        raise ProfileError("profile.buttons: torch and camera_select must differ")

    assumptions = data.get("assumptions", [])
    if not isinstance(assumptions, list) or not all(isinstance(a, str) for a in assumptions):
        raise ProfileError("profile.assumptions: must be a list of key names")
    measured = _parse_measured(root, data, assumptions)
    return RobotProfile(
        name=root.string("name"),
        source=source,
        link=link_settings,
        channels=channels,
        motors=motors,
        torch_button=torch,
        camera_button=camera,
        track_width_m=root.sub("chassis", CHASSIS_KEYS).number("track_width_m", low=0.01),
        telemetry_speed_per_rad_s=si.number("telemetry_speed_per_rad_s", low=1e-9),
        telemetry_current_per_amp=si.number("telemetry_current_per_amp", low=1e-9),
        linear_axis_per_m_s=scales["linear"],
        rotation_axis_per_rad_s=scales["rotation"],
        assumptions=tuple(assumptions),
        extension=(
            _parse_extension(root.sub("extension", EXTENSION_KEYS), frame_types)
            if root.optional("extension")
            else None
        ),
        video=(
            _parse_video(root.sub("video", VIDEO_KEYS))
            if root.optional("video")
            else VideoSettings()
        ),
        cameras=_parse_cameras(root, tuple(cameras)),
        arm=_parse_arm(root.sub("arm", ARM_KEYS), motors) if root.optional("arm") else None,
        navigation=(
            _parse_navigation(root.sub("navigation", NAVIGATION_KEYS))
            if root.optional("navigation")
            else NavigationSettings()
        ),
        measured=measured,
    )


def _parse_measured(
    root: _Reader, data: dict[str, Any], assumptions: list[str]
) -> dict[str, Measurement]:
    """The `[measured."key"]` entries; each must name a key the profile holds."""
    if not root.optional("measured"):
        return {}
    table = root.sub("measured", None)
    measured: dict[str, Measurement] = {}
    for key, entry in table.table.items():
        where = f'profile.measured."{key}"'
        if not isinstance(entry, dict):
            raise ProfileError(f"{where}: must be a table (how, when, residual, ...)")
        reader = _Reader(entry, where, MEASUREMENT_KEYS)
        value: Any = data
        for part in key.split("."):
            if not isinstance(value, dict) or part not in value:
                raise ProfileError(f"{where}: names no key of this profile")
            value = value[part]
        if key in assumptions:
            raise ProfileError(f"{where}: also listed in assumptions; a key is one or the other")
        when = reader.table.get("when")
        if not isinstance(when, dt.datetime) or when.tzinfo is None:
            raise ProfileError(
                f"{where}.when: must be a date and time with its offset, e.g. 2025-06-01T12:00:00Z"
            )
        measured[key] = Measurement(
            key=key,
            how=reader.string("how"),
            when=when,
            residual=(reader.number("residual", low=0.0) if reader.optional("residual") else None),
            residual_unit=(
                reader.string("residual_unit") if reader.optional("residual_unit") else None
            ),
            samples=(
                reader.integer("samples", low=1, high=2**31 - 1)
                if reader.optional("samples")
                else None
            ),
        )
    return measured


# ---- writing -----------------------------------------------------------------------------


def _toml_key(key: str) -> str:
    return key if _BARE_KEY.match(key) else _toml_string(key)


def _toml_string(text: str) -> str:
    # A JSON string is a TOML basic string; TOML also wants DEL (U+007F) escaped.
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")


def _toml_value(value: Any, where: str) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ProfileError(f"{where}: cannot write {value!r}")
        return repr(value)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, dt.datetime):
        if value.tzinfo is None:
            raise ProfileError(f"{where}: a date and time needs its offset")
        return value.isoformat()
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v, where) for v in value) + "]"
    raise ProfileError(f"{where}: cannot write a {type(value).__name__}")


def _toml_table(lines: list[str], path: list[str], table: Mapping[str, Any]) -> None:
    values = {k: v for k, v in table.items() if not isinstance(v, dict)}
    tables = {k: v for k, v in table.items() if isinstance(v, dict)}
    if path and (values or not tables):
        lines.append("")
        lines.append("[" + ".".join(_toml_key(part) for part in path) + "]")
    for key, value in values.items():
        where = ".".join([*path, key])
        line = f"{_toml_key(key)} = {_toml_value(value, where)}"
        if isinstance(value, (list, tuple)) and len(line) > TOML_LINE_LENGTH:
            items = [f"    {_toml_value(item, where)}," for item in value]
            line = "\n".join([f"{_toml_key(key)} = [", *items, "]"])
        lines.append(line)
    for key, sub in tables.items():
        _toml_table(lines, [*path, key], sub)


def profile_to_toml(data: Mapping[str, Any], header: str = "") -> str:
    """A profile document as TOML text (comments: the header's lines), which tomllib reads
    back to the same document."""
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    _toml_table(lines, [], data)
    return "\n".join(lines).lstrip("\n") + "\n"


def write_profile_data(path: str | Path, data: Mapping[str, Any], header: str = "") -> None:
    """Validate a profile document and write it atomically (a temp file renamed over path).

    A profile that does not load is refused before anything is written; a writer killed
    half-way leaves the old file (or none), never half of the new one.
    """
    target = Path(path)
    text = profile_to_toml(data, header)
    parse_profile(tomllib.loads(text), source=str(target))
    write_text_atomically(target, text)
