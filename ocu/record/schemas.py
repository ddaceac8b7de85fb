"""Topics and ROS 2 message definitions of an ocu recording, and their CDR encoders.

Every channel uses the ROS 2 encodings (message encoding "cdr", schema encoding "ros2msg"),
so Foxglove and the ROS 2 tools decode each one from the definition embedded in the file,
the custom `ocu_msgs` ones included. docs/recordings.md lists the topics.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final

from mcap_ros2._dynamic import serialize_dynamic

SCHEMA_ENCODING: Final = "ros2msg"
MESSAGE_ENCODING: Final = "cdr"
PROFILE: Final = "ros2"

# Raw datagrams, one channel per packet kind.
RAW_RCP: Final = "/raw/rcp"
RAW_HELLO: Final = "/raw/hello"
RAW_TELEMETRY: Final = "/raw/telemetry"
RAW_VIDEO: Final = "/raw/video"
RAW_VIDEO_FRAGMENT: Final = "/raw/video_fragment"
RAW_STATUS: Final = "/raw/status"
RAW_SCAN: Final = "/raw/scan"
RAW_OTHER: Final = "/raw/other"
RAW_TOPICS: Final = (
    RAW_RCP,
    RAW_HELLO,
    RAW_TELEMETRY,
    RAW_VIDEO,
    RAW_VIDEO_FRAGMENT,
    RAW_STATUS,
    RAW_SCAN,
    RAW_OTHER,
)
# A UR controller's: URScript lines sent, and each packet of its three TCP ports. Registered
# when first written (an Engineer's file has none of them).
RAW_UR_SCRIPT: Final = "/raw/ur/script"
RAW_UR_PRIMARY: Final = "/raw/ur/primary"
RAW_UR_SECONDARY: Final = "/raw/ur/secondary"
RAW_UR_REALTIME: Final = "/raw/ur/realtime"
RAW_UR_TOPICS: Final = (RAW_UR_SCRIPT, RAW_UR_PRIMARY, RAW_UR_SECONDARY, RAW_UR_REALTIME)
# An xArm board's serial frames, one message per frame: those the OCU wrote, and the whole
# frames it read (bytes its frame reader skipped go to /raw/other). Registered when used.
RAW_XARM_TO_BOARD: Final = "/raw/xarm/to_board"
RAW_XARM_FROM_BOARD: Final = "/raw/xarm/from_board"
RAW_XARM_TOPICS: Final = (RAW_XARM_TO_BOARD, RAW_XARM_FROM_BOARD)

# Decoded channels.
CMD_VEL: Final = "/cmd_vel_sent"
CMD_JOINTS: Final = "/cmd_joint_velocities_sent"
JOINT_STATES: Final = "/joint_states"
LINK_STATS: Final = "/ocu/link_stats"
EVENTS: Final = "/ocu/events"
ROBOT_STATUS: Final = "/ocu/robot_status"

SOURCE_OCU: Final = "ocu"
SOURCE_ROBOT: Final = "robot"

EVENT_SAFETY: Final = "safety"
EVENT_LINK_STATE: Final = "link_state"
EVENT_EXTENSION: Final = "extension"
EVENT_RECORDING: Final = "recording"
# The robot controller's own mode changed (a UR: robot mode, safety mode, stops).
EVENT_ROBOT_MODE: Final = "robot_mode"

METADATA_NAME: Final = "ocu.recording"
PROFILE_ATTACHMENT: Final = "profile.toml"
FORMAT_VERSION: Final = "1"


def camera_topic(name: str) -> str:
    """The CompressedImage topic of one camera."""
    return f"/camera/{name}/compressed"


_SEPARATOR = "=" * 80

_TIME = "int32 sec\nuint32 nanosec\n"
_HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
_VECTOR3 = "float64 x\nfloat64 y\nfloat64 z\n"


def concatenate(main: str, *dependencies: tuple[str, str]) -> str:
    """A message definition with its dependencies, as MCAP and Foxglove take it."""
    parts = [main]
    for name, text in dependencies:
        parts.append(f"{_SEPARATOR}\nMSG: {name}\n{text}")
    return "\n".join(parts)


@dataclass(frozen=True)
class MessageType:
    """A ROS 2 message type with its concatenated definition (what MCAP embeds)."""

    name: str
    definition: str


TWIST = MessageType(
    "geometry_msgs/msg/Twist",
    concatenate(
        "# This expresses velocity in free space broken into its linear and angular parts.\n"
        "Vector3 linear\nVector3 angular\n",
        ("geometry_msgs/Vector3", _VECTOR3),
    ),
)

JOINT_STATE = MessageType(
    "sensor_msgs/msg/JointState",
    concatenate(
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
        "float64[] effort\n",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
    ),
)

COMPRESSED_IMAGE = MessageType(
    "sensor_msgs/msg/CompressedImage",
    concatenate(
        "std_msgs/Header header\nstring format\nuint8[] data\n",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
    ),
)

RAW_PACKET = MessageType(
    "ocu_msgs/msg/RawPacket",
    concatenate(
        "# One UDP datagram exactly as it went on or came off the wire.\n"
        "# send_stamp: when it was sent; the OCU's wall clock for datagrams the OCU sent, the\n"
        "# robot's own clock (from the packet: telemetry tick, video capture time) for robot\n"
        "# datagrams that carry one, zero when unknown.\n"
        "# receive_stamp: the OCU's wall clock on arrival; zero for datagrams the OCU sent.\n"
        "builtin_interfaces/Time send_stamp\n"
        "builtin_interfaces/Time receive_stamp\n"
        "# 'ocu' or 'robot': who sent the datagram.\n"
        "string source\n"
        "uint8[] data\n",
        ("builtin_interfaces/Time", _TIME),
    ),
)

LINK_STATS_TYPE = MessageType(
    "ocu_msgs/msg/LinkStats",
    concatenate(
        "# The link's counters and rates (ocu.link.stats.LinkStats); NaN = not known yet.\n"
        "builtin_interfaces/Time stamp\n"
        "string link_state\n"
        "uint64 sent\nuint64 received\nuint64 telemetry\nuint64 video\nuint64 malformed\n"
        "uint64 foreign\nuint64 send_errors\n"
        "float64 rcp_rate_hz\nfloat64 telemetry_rate_hz\nfloat64 video_rate_hz\n"
        "float64 loss_estimate\n"
        "uint64 duplicates\nuint64 reordered\n"
        "float64 last_valid_age_s\nfloat64 send_rate_hz\n"
        "bool estop_latched\n"
        "bool extension_active\n"
        "# Messages the recorder itself dropped so far (its queue was full).\n"
        "uint64 recorder_dropped\n"
        "# Round trip measured from the robot's echoed speed commands (s); late or repeated\n"
        "# telemetry packets dropped.\n"
        "float64 delay_s\nuint64 stale_telemetry\n"
        "# The delay's jitter (standard deviation over 10 s of each telemetry packet's\n"
        "# arrival less its tick, s),\n"
        "# range scans per second, and per camera (profile order) the seconds since its\n"
        "# newest frame arrived (NaN before its first).\n"
        "float64 jitter_s\nfloat64 scan_rate_hz\nfloat64[] frame_age_s\n"
        "# Share of the commands sent over 30 s the robot did not apply (its echo of the\n"
        "# sequenced RCPs); NaN: the robot echoes none.\n"
        "float64 uplink_loss\n",
        ("builtin_interfaces/Time", _TIME),
    ),
)

EVENT = MessageType(
    "ocu_msgs/msg/Event",
    concatenate(
        "# kind: safety (e-stop, watchdogs), link_state, extension, recording or robot_mode.\n"
        "# state: the new link state, 'active'/'inactive' for the extension, the robot\n"
        "# controller's mode ('RUNNING · NORMAL', 'PROTECTIVE STOP'), else empty.\n"
        "builtin_interfaces/Time stamp\n"
        "string kind\nstring state\nstring message\n",
        ("builtin_interfaces/Time", _TIME),
    ),
)

ROBOT_STATUS_TYPE = MessageType(
    "ocu_msgs/msg/RobotStatus",
    concatenate(
        "# The protocol extension's status packet in SI units; NaN = not measured.\n"
        "std_msgs/Header header\n"
        "float64 voltage_v\nfloat64 charge_percent\n"
        "# 1 on, 0 off, -1 not measured.\n"
        "int8 headlight\n"
        "float64 roll_rad\nfloat64 pitch_rad\n",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
    ),
)

MESSAGE_TYPES: Final = (
    TWIST,
    JOINT_STATE,
    COMPRESSED_IMAGE,
    RAW_PACKET,
    LINK_STATS_TYPE,
    EVENT,
    ROBOT_STATUS_TYPE,
)

Encoder = Callable[[Any], bytes]


def make_encoder(message_type: MessageType) -> Encoder:
    """The CDR encoder of a message type, built by mcap-ros2-support from its definition.

    The public mcap_ros2 Writer does the same internally but cannot flush a chunk on demand,
    which a recorder that must survive kill -9 needs; so the mcap Writer writes and this
    encoder (the one the mcap_ros2 Writer uses) serialises.
    """
    encoders: dict[str, Encoder] = serialize_dynamic(message_type.name, message_type.definition)
    return encoders[message_type.name]


def stamp(ns: int) -> dict[str, int]:
    """A builtin_interfaces/Time from nanoseconds (zero or positive)."""
    sec, nanosec = divmod(max(ns, 0), 1_000_000_000)
    return {"sec": sec, "nanosec": nanosec}


def stamp_ns(value: Any) -> int:
    """Nanoseconds of a decoded builtin_interfaces/Time."""
    return int(value.sec) * 1_000_000_000 + int(value.nanosec)


def nan_if_none(value: float | None) -> float:
    """NaN for an unknown value (the messages' convention)."""
    return math.nan if value is None else float(value)


def none_if_nan(value: float) -> float | None:
    """None for NaN (the inverse of nan_if_none)."""
    return None if math.isnan(value) else float(value)
