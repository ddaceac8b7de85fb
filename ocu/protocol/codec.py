"""Dispatch datagrams to the packet codecs by the frame type IDs of a robot profile."""

from __future__ import annotations

from dataclasses import dataclass

from ocu.protocol.errors import ProtocolError
from ocu.protocol.packets import (
    Packet,
    RemoteControlPacket,
    TelemetryPacket,
    VideoFramePacket,
)


@dataclass(frozen=True)
class Codec:
    """Encode and decode the vendor packets with a given set of frame type IDs."""

    rcp_type: int = 0x01
    telemetry_type: int = 0x02
    video_type: int = 0x03

    def encode(self, packet: Packet) -> bytes:
        """Bytes on the wire for any vendor packet."""
        if isinstance(packet, RemoteControlPacket):
            return packet.encode(self.rcp_type)
        if isinstance(packet, TelemetryPacket):
            return packet.encode(self.telemetry_type)
        return packet.encode(self.video_type)

    def decode(self, data: bytes) -> Packet:
        """Parse one datagram; ProtocolError for anything malformed or unknown."""
        if not data:
            raise ProtocolError("empty datagram")
        frame_type = data[0]
        if frame_type == self.rcp_type:
            return RemoteControlPacket.decode(data, frame_type)
        if frame_type == self.telemetry_type:
            return TelemetryPacket.decode(data, frame_type)
        if frame_type == self.video_type:
            return VideoFramePacket.decode(data, frame_type)
        raise ProtocolError(f"unknown frame type 0x{frame_type:02x}")
