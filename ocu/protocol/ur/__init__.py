"""Universal Robots controller codecs: the realtime (30003) and primary/secondary (30001/30002)
packets, URScript motion commands, and a TCP stream splitter. Pure: no sockets, no threads.

Every layout and its source is in docs/ur.md. Numbers are big-endian (network order) on every
UR port. All three ports carry framed packets whose first four bytes are the packet's length,
header included; the primary/secondary packets then have a one-byte type.
"""

from ocu.protocol.ur.common import JOINTS, RobotMode, SafetyMode, UrProtocolError, Vector3, Vector6
from ocu.protocol.ur.primary import (
    MAX_PRIMARY_SIZE,
    MESSAGE_SOURCE_CONTROLLER,
    ROBOT_MESSAGE_VERSION,
    JointData,
    JointState,
    MasterboardData,
    PackageType,
    PrimaryPackage,
    RobotModeData,
    RobotState,
    RobotStateType,
    StreamSplitter,
    SubPackage,
    UnknownPackage,
    UnknownSubPackage,
    VersionMessage,
    decode_primary,
)
from ocu.protocol.ur.realtime import (
    KNOWN_REALTIME_SIZES,
    REALTIME_FIELDS,
    REALTIME_SIZES,
    RealtimeState,
    realtime_size,
    realtime_state,
)
from ocu.protocol.ur.script import ScriptCommand, movej, parse_script_line, servoj, speedj, stopj

__all__ = [
    "JOINTS",
    "KNOWN_REALTIME_SIZES",
    "MAX_PRIMARY_SIZE",
    "MESSAGE_SOURCE_CONTROLLER",
    "REALTIME_FIELDS",
    "REALTIME_SIZES",
    "ROBOT_MESSAGE_VERSION",
    "JointData",
    "JointState",
    "MasterboardData",
    "PackageType",
    "PrimaryPackage",
    "RealtimeState",
    "RobotMode",
    "RobotModeData",
    "RobotState",
    "RobotStateType",
    "SafetyMode",
    "ScriptCommand",
    "StreamSplitter",
    "SubPackage",
    "UnknownPackage",
    "UnknownSubPackage",
    "UrProtocolError",
    "Vector3",
    "Vector6",
    "VersionMessage",
    "decode_primary",
    "movej",
    "parse_script_line",
    "realtime_size",
    "realtime_state",
    "servoj",
    "speedj",
    "stopj",
]
