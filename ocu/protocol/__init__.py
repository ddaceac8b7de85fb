"""Vendor wire format: pure codecs, no Qt and no sockets."""

from ocu.protocol.codec import Codec
from ocu.protocol.errors import ProtocolError
from ocu.protocol.packets import (
    AXIS_COUNT,
    BUTTON_COUNT,
    MOTOR_SLOTS,
    RCP_SIZE,
    TELEMETRY_SIZE,
    MotorRecord,
    Packet,
    RemoteControlPacket,
    TelemetryPacket,
    VideoFramePacket,
)

__all__ = [
    "AXIS_COUNT",
    "BUTTON_COUNT",
    "MOTOR_SLOTS",
    "RCP_SIZE",
    "TELEMETRY_SIZE",
    "Codec",
    "MotorRecord",
    "Packet",
    "ProtocolError",
    "RemoteControlPacket",
    "TelemetryPacket",
    "VideoFramePacket",
]
