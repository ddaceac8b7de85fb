"""Byte-exact codecs for the vendor's packets (seed 000 tables 1-3, seed 001 table IV).

All multi-byte fields are little-endian. The motor record uses natural C alignment: one pad
byte before the u32 position and two before the u32 position command (docs/protocol.md).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

from ocu.protocol.errors import ProtocolError

AXIS_COUNT = 16
BUTTON_COUNT = 16
MOTOR_SLOTS = 10

RCP_STRUCT = struct.Struct("<B16h16Bd")
MOTOR_STRUCT = struct.Struct("<BBBxIhhh2xIhh")
TELEMETRY_HEADER_STRUCT = struct.Struct("<BQB")
TELEMETRY_UNUSED_BYTES = 25

RCP_SIZE = RCP_STRUCT.size
MOTOR_SIZE = MOTOR_STRUCT.size
TELEMETRY_SIZE = TELEMETRY_HEADER_STRUCT.size + MOTOR_SLOTS * MOTOR_SIZE + TELEMETRY_UNUSED_BYTES
MAX_DATAGRAM = 65507
JPEG_SOI = b"\xff\xd8\xff"
JPEG_EOI = b"\xff\xd9"

assert RCP_SIZE == 57
assert MOTOR_SIZE == 24
assert TELEMETRY_SIZE == 275

_I16 = (-32768, 32767)
_U8 = (0, 255)
_U32 = (0, 2**32 - 1)
_U64 = (0, 2**64 - 1)


def _pack(layout: struct.Struct, *values: object) -> bytes:
    try:
        return layout.pack(*values)
    except struct.error as err:
        raise ProtocolError(f"cannot encode: {err}") from err


def _check_range(name: str, value: int, bounds: tuple[int, int]) -> None:
    if not isinstance(value, int) or isinstance(value, bool):
        raise ProtocolError(f"{name}={value!r} is not an integer")
    if not bounds[0] <= value <= bounds[1]:
        raise ProtocolError(f"{name}={value} out of range [{bounds[0]}, {bounds[1]}]")


@dataclass(frozen=True)
class RemoteControlPacket:
    """Table 1: the state of the vendor's gamepad, sent by the OCU."""

    axes: tuple[int, ...] = (0,) * AXIS_COUNT
    buttons: tuple[int, ...] = (0,) * BUTTON_COUNT
    video_bitrate: float = 0.0

    def encode(self, frame_type: int) -> bytes:
        """57 bytes: frame type u8, 16 axes i16, 16 buttons u8, bit-rate f64."""
        if len(self.axes) != AXIS_COUNT or len(self.buttons) != BUTTON_COUNT:
            raise ProtocolError(
                f"RCP needs {AXIS_COUNT} axes and {BUTTON_COUNT} buttons, "
                f"got {len(self.axes)} and {len(self.buttons)}"
            )
        for index, axis in enumerate(self.axes):
            _check_range(f"axis[{index}]", axis, _I16)
        for index, button in enumerate(self.buttons):
            _check_range(f"button[{index}]", button, _U8)
        return _pack(RCP_STRUCT, frame_type, *self.axes, *self.buttons, self.video_bitrate)

    @classmethod
    def decode(cls, data: bytes, frame_type: int) -> RemoteControlPacket:
        """Parse a 57-byte RCP; ProtocolError on a wrong length or frame type."""
        _expect(data, RCP_SIZE, frame_type, "RCP")
        values = RCP_STRUCT.unpack(data)
        return cls(
            axes=tuple(values[1 : 1 + AXIS_COUNT]),
            buttons=tuple(values[1 + AXIS_COUNT : 1 + AXIS_COUNT + BUTTON_COUNT]),
            video_bitrate=values[-1],
        )


@dataclass(frozen=True)
class MotorRecord:
    """Table 3: one servo's telemetry, raw wire units."""

    device_id: int = 0
    state: int = 0
    mode: int = 0
    position: int = 0
    speed: int = 0
    current: int = 0
    status: int = 0
    position_command: int = 0
    speed_command: int = 0
    current_command: int = 0

    def encode(self) -> bytes:
        """24 bytes with natural C alignment padding."""
        for name, bounds in (
            ("device_id", _U8),
            ("state", _U8),
            ("mode", _U8),
            ("position", _U32),
            ("speed", _I16),
            ("current", _I16),
            ("status", _I16),
            ("position_command", _U32),
            ("speed_command", _I16),
            ("current_command", _I16),
        ):
            _check_range(f"motor.{name}", getattr(self, name), bounds)
        return _pack(
            MOTOR_STRUCT,
            self.device_id,
            self.state,
            self.mode,
            self.position,
            self.speed,
            self.current,
            self.status,
            self.position_command,
            self.speed_command,
            self.current_command,
        )

    @classmethod
    def decode(cls, data: bytes) -> MotorRecord:
        """Parse one 24-byte record; pad bytes are ignored."""
        if len(data) != MOTOR_SIZE:
            raise ProtocolError(f"motor record must be {MOTOR_SIZE} bytes, got {len(data)}")
        return cls(*MOTOR_STRUCT.unpack(data))


@dataclass(frozen=True)
class TelemetryPacket:
    """Table 2: tick counter and up to ten motor records."""

    tick: int = 0
    motors: tuple[MotorRecord, ...] = field(default_factory=tuple)

    def encode(self, frame_type: int) -> bytes:
        """275 bytes; unused motor slots and the trailing 25 bytes are zero."""
        if len(self.motors) > MOTOR_SLOTS:
            raise ProtocolError(f"motor count {len(self.motors)} over {MOTOR_SLOTS}")
        _check_range("tick", self.tick, _U64)
        parts = [_pack(TELEMETRY_HEADER_STRUCT, frame_type, self.tick, len(self.motors))]
        parts.extend(motor.encode() for motor in self.motors)
        parts.append(bytes(MOTOR_SIZE * (MOTOR_SLOTS - len(self.motors)) + TELEMETRY_UNUSED_BYTES))
        return b"".join(parts)

    @classmethod
    def decode(cls, data: bytes, frame_type: int) -> TelemetryPacket:
        """Parse a 275-byte telemetry packet; only the first `motor count` records are kept."""
        _expect(data, TELEMETRY_SIZE, frame_type, "telemetry")
        _, tick, count = TELEMETRY_HEADER_STRUCT.unpack_from(data)
        if count > MOTOR_SLOTS:
            raise ProtocolError(f"telemetry motor count {count} over {MOTOR_SLOTS}")
        base = TELEMETRY_HEADER_STRUCT.size
        motors = tuple(
            MotorRecord(*MOTOR_STRUCT.unpack_from(data, base + i * MOTOR_SIZE))
            for i in range(count)
        )
        return cls(tick=tick, motors=motors)


@dataclass(frozen=True)
class VideoFramePacket:
    """Table IV: frame type followed by one JPEG image."""

    jpeg: bytes

    def encode(self, frame_type: int) -> bytes:
        """Frame type byte plus the JPEG; the JPEG must be valid and fit one datagram."""
        _check_jpeg(self.jpeg)
        if len(self.jpeg) + 1 > MAX_DATAGRAM:
            raise ProtocolError(f"JPEG of {len(self.jpeg)} bytes does not fit one datagram")
        return bytes((frame_type,)) + self.jpeg

    @classmethod
    def decode(cls, data: bytes, frame_type: int) -> VideoFramePacket:
        """Parse a video datagram; the payload must start with SOI and end with EOI."""
        if not data:
            raise ProtocolError("empty datagram")
        if data[0] != frame_type:
            raise ProtocolError(f"frame type 0x{data[0]:02x} is not video (0x{frame_type:02x})")
        jpeg = bytes(data[1:])
        _check_jpeg(jpeg)
        return cls(jpeg=jpeg)


def _check_jpeg(jpeg: bytes) -> None:
    if not jpeg.startswith(JPEG_SOI):
        raise ProtocolError("video payload is not a JPEG (no SOI marker)")
    if not jpeg.endswith(JPEG_EOI):
        raise ProtocolError("video payload is a truncated JPEG (no EOI marker)")


def _expect(data: bytes, size: int, frame_type: int, what: str) -> None:
    if len(data) != size:
        raise ProtocolError(f"{what} packet must be {size} bytes, got {len(data)}")
    if data[0] != frame_type:
        raise ProtocolError(f"frame type 0x{data[0]:02x} is not {what} (0x{frame_type:02x})")


Packet = RemoteControlPacket | TelemetryPacket | VideoFramePacket
