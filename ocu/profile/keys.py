"""The profile's vocabulary: the keys each table may hold, wire constants, and its error."""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable

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
    "urdf",
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
    "tool_axis",
)
# The tool frame's axes an arm may point along (ArmSettings.tool_axis).
TOOL_AXES = ("x", "z")
# What a `[measured."some.key"]` entry may say about how that key was measured on a robot.
MEASUREMENT_KEYS = ("how", "when", "residual", "residual_unit", "samples")
# Table names are TOML bare keys; the dotted names in `measured` and `assumptions` join them.
BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")
# Arrays longer than this are written one item per line.
TOML_LINE_LENGTH = 96

CAMERA_MODELS = ("fisheye", "standard")
COLOUR_MODES = ("off", "gray_world", "fixed")
# Distortion coefficients per model: cv2.fisheye takes k1..k4; the standard (Brown-Conrady)
# model k1, k2, p1, p2 and optionally k3.
DISTORTION_LENGTHS = {"fisheye": (4,), "standard": (4, 5)}


# The longest LINK LOST delay a profile may set: a robot unheard for longer must be said.
LINK_LOST_MAX_S = 30.0


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
