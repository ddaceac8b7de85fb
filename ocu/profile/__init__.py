"""Robot profile: load and validate the TOML file that holds every robot fact.

A package of six modules, read in this order:
  keys.py         the vocabulary (the keys each table may hold), wire constants, ProfileError
  hardware.py     what the wire needs (packet IDs, link timing, the extension, video transport,
                  the RCP's velocity channels): the hardware's settings
  description.py  what the robot is (motors, limits, cameras, chassis, navigation, arm) and
                  the whole RobotProfile: the robot's description
  reader.py       one TOML table read key by key, every error naming the file and the key
  parse.py        TOML document -> RobotProfile, section by section
  writer.py       RobotProfile's document -> TOML, atomically (ocu calibrate, ocu-sim --scramble)
Everything public is imported from here (`from ocu.profile import RobotProfile, load_profile`).
"""

from __future__ import annotations

from pathlib import Path

from ocu.profile.description import (
    ArmSettings,
    AssistSettings,
    CameraCalibration,
    CameraMount,
    CameraSettings,
    Footprint,
    Measurement,
    Motor,
    NavigationSettings,
    OdometrySettings,
    RobotProfile,
    ZoneSettings,
    assumption_covers,
)
from ocu.profile.hardware import (
    Channel,
    ExtensionFrameTypes,
    ExtensionSettings,
    FrameTypes,
    LinkSettings,
    VideoSettings,
)
from ocu.profile.keys import (
    ARM_KEYS,
    ASSIST_KEYS,
    AXIS_COUNT,
    AXIS_MAX,
    BUTTON_COUNT,
    BUTTON_KEYS,
    CAMERA_KEYS,
    CAMERA_MODELS,
    CHANNEL_KEYS,
    CHANNEL_ROLES,
    CHASSIS_KEYS,
    COLOUR_MODES,
    DISTORTION_LENGTHS,
    DRIVE_LINEAR_ROLE,
    DRIVE_TURN_ROLE,
    EXTENSION_FRAME_TYPE_KEYS,
    EXTENSION_KEYS,
    FRAME_TYPE_KEYS,
    LINK_KEYS,
    LINK_LOST_MAX_S,
    MEASUREMENT_KEYS,
    MOTOR_KEYS,
    MOTOR_POSITION_KEYS,
    NAVIGATION_KEYS,
    ODOMETRY_KEYS,
    OPTIONAL_EXTENSION_FRAME_TYPE_KEYS,
    SCALE_NAMES,
    SI_KEYS,
    TOML_LINE_LENGTH,
    TOOL_AXES,
    TOP_KEYS,
    VIDEO_KEYS,
    ZONE_KEYS,
    ProfileError,
    did_you_mean,
)
from ocu.profile.parse import (
    default_profile_path,
    load_profile,
    load_profile_data,
    parse_profile,
)
from ocu.profile.writer import (
    profile_to_toml,
    write_profile_data,
)


def companion_file(profile: RobotProfile, name: str) -> Path | None:
    """A file shipped beside the profile's own (`hotkeys.toml`, `gamepad.toml`): a robot's
    key map and pad mapping sit with its profile. None when there is none."""
    if not profile.source:
        return None
    candidate = Path(profile.source).parent / name
    return candidate if candidate.is_file() else None


__all__ = [
    "ARM_KEYS",
    "ASSIST_KEYS",
    "AXIS_COUNT",
    "AXIS_MAX",
    "BUTTON_COUNT",
    "BUTTON_KEYS",
    "CAMERA_KEYS",
    "CAMERA_MODELS",
    "CHANNEL_KEYS",
    "CHANNEL_ROLES",
    "CHASSIS_KEYS",
    "COLOUR_MODES",
    "DISTORTION_LENGTHS",
    "DRIVE_LINEAR_ROLE",
    "DRIVE_TURN_ROLE",
    "EXTENSION_FRAME_TYPE_KEYS",
    "EXTENSION_KEYS",
    "FRAME_TYPE_KEYS",
    "LINK_KEYS",
    "LINK_LOST_MAX_S",
    "MEASUREMENT_KEYS",
    "MOTOR_KEYS",
    "MOTOR_POSITION_KEYS",
    "NAVIGATION_KEYS",
    "ODOMETRY_KEYS",
    "OPTIONAL_EXTENSION_FRAME_TYPE_KEYS",
    "SCALE_NAMES",
    "SI_KEYS",
    "TOML_LINE_LENGTH",
    "TOOL_AXES",
    "TOP_KEYS",
    "VIDEO_KEYS",
    "ZONE_KEYS",
    "ArmSettings",
    "AssistSettings",
    "CameraCalibration",
    "CameraMount",
    "CameraSettings",
    "Channel",
    "ExtensionFrameTypes",
    "ExtensionSettings",
    "Footprint",
    "FrameTypes",
    "LinkSettings",
    "Measurement",
    "Motor",
    "NavigationSettings",
    "OdometrySettings",
    "ProfileError",
    "RobotProfile",
    "VideoSettings",
    "ZoneSettings",
    "assumption_covers",
    "companion_file",
    "default_profile_path",
    "did_you_mean",
    "load_profile",
    "load_profile_data",
    "parse_profile",
    "profile_to_toml",
    "write_profile_data",
]
