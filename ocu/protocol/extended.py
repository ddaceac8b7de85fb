"""Codecs of ocu's open protocol extension (docs/protocol.md, "Extended protocol").

Three packet types beside the vendor's, each one UDP datagram, little-endian, no padding:

- hello (OCU -> robot): the extension probe, repeated alongside the RCPs, carrying the
  per-camera stream request (resolution, frame rate, JPEG quality) and the largest datagram
  the OCU wants to receive;
- video fragment (robot -> OCU): one piece of one camera's JPEG, tagged with camera id,
  sequence number, capture time, byte offset, fragment index and count;
- status (robot -> OCU): battery voltage and charge, headlight state, roll and pitch, each
  with a "not measured" value so the robot never has to invent one.

The vendor packets are unchanged. Pure code: no Qt, no sockets; ProtocolError for bad data.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from ocu.protocol.errors import ProtocolError
from ocu.protocol.packets import JPEG_EOI, JPEG_SOI, MAX_DATAGRAM

MAGIC = b"OCUX"
VERSION = 1

HELLO_HEADER_STRUCT = struct.Struct("<B4sBHB")
CAMERA_REQUEST_STRUCT = struct.Struct("<BHHBB")
FRAGMENT_HEADER_STRUCT = struct.Struct("<BBIQIIHH")
STATUS_STRUCT = struct.Struct("<B4sBIHHBhhB")

HELLO_HEADER_SIZE = HELLO_HEADER_STRUCT.size
CAMERA_REQUEST_SIZE = CAMERA_REQUEST_STRUCT.size
FRAGMENT_HEADER_SIZE = FRAGMENT_HEADER_STRUCT.size
STATUS_SIZE = STATUS_STRUCT.size

assert HELLO_HEADER_SIZE == 9
assert CAMERA_REQUEST_SIZE == 7
assert FRAGMENT_HEADER_SIZE == 26
assert STATUS_SIZE == 20

MAX_CAMERAS = 255
# Below this a datagram could not carry the fragment header plus a useful payload.
MIN_DATAGRAM = 64
MAX_FRAME_BYTES = 16 * 1024 * 1024
MAX_FRAGMENTS = 65535

# "Not measured" values of the status packet.
VOLTAGE_UNKNOWN = 0xFFFF
CHARGE_UNKNOWN = 0xFFFF
HEADLIGHT_UNKNOWN = 0xFF
ANGLE_UNKNOWN = -32768
CHARGE_FULL_PERMILLE = 1000

_U8 = (0, 255)
_U32 = (0, 2**32 - 1)
_U64 = (0, 2**64 - 1)
_I16 = (-32768, 32767)


def _check(name: str, value: int, bounds: tuple[int, int]) -> None:
    if not isinstance(value, int) or isinstance(value, bool):
        raise ProtocolError(f"{name}={value!r} is not an integer")
    if not bounds[0] <= value <= bounds[1]:
        raise ProtocolError(f"{name}={value} out of range [{bounds[0]}, {bounds[1]}]")


def _check_header(magic: bytes, version: int, what: str) -> None:
    if magic != MAGIC:
        raise ProtocolError(f"{what} magic {magic!r} is not {MAGIC!r}")
    if version != VERSION:
        raise ProtocolError(f"{what} version {version} not supported (expected {VERSION})")


@dataclass(frozen=True)
class CameraRequest:
    """What the OCU asks of one camera; fps 0 switches it off, quality 0 follows the RCP."""

    camera: int
    width_px: int
    height_px: int
    fps: int
    quality: int = 0

    def check(self) -> None:
        """ProtocolError unless every field fits its wire type and range."""
        _check("camera", self.camera, (0, MAX_CAMERAS - 1))
        _check("width_px", self.width_px, (1, 65535))
        _check("height_px", self.height_px, (1, 65535))
        _check("fps", self.fps, _U8)
        _check("quality", self.quality, (0, 100))


@dataclass(frozen=True)
class HelloPacket:
    """OCU -> robot: the extension probe and per-camera stream request."""

    cameras: tuple[CameraRequest, ...] = ()
    max_datagram_bytes: int = 1472

    def check(self) -> None:
        """ProtocolError unless the request fits the wire format."""
        _check("max_datagram_bytes", self.max_datagram_bytes, (MIN_DATAGRAM, MAX_DATAGRAM))
        if len(self.cameras) > MAX_CAMERAS:
            raise ProtocolError(f"camera count {len(self.cameras)} over {MAX_CAMERAS}")
        if len({c.camera for c in self.cameras}) != len(self.cameras):
            raise ProtocolError("a camera is requested twice")
        for request in self.cameras:
            request.check()

    def encode(self, frame_type: int) -> bytes:
        """9 + 7 x camera-count bytes."""
        self.check()
        parts = [
            HELLO_HEADER_STRUCT.pack(
                frame_type, MAGIC, VERSION, self.max_datagram_bytes, len(self.cameras)
            )
        ]
        for request in self.cameras:
            parts.append(
                CAMERA_REQUEST_STRUCT.pack(
                    request.camera,
                    request.width_px,
                    request.height_px,
                    request.fps,
                    request.quality,
                )
            )
        return b"".join(parts)

    @classmethod
    def decode(cls, data: bytes, frame_type: int) -> HelloPacket:
        """Parse a hello; the length must match its camera count."""
        if len(data) < HELLO_HEADER_SIZE:
            raise ProtocolError(f"hello packet needs {HELLO_HEADER_SIZE} bytes, got {len(data)}")
        kind, magic, version, max_datagram, count = HELLO_HEADER_STRUCT.unpack_from(data)
        _expect_type(kind, frame_type, "hello")
        _check_header(magic, version, "hello")
        expected = HELLO_HEADER_SIZE + count * CAMERA_REQUEST_SIZE
        if len(data) != expected:
            raise ProtocolError(
                f"hello packet with {count} cameras must be {expected} bytes, got {len(data)}"
            )
        offsets = range(HELLO_HEADER_SIZE, expected, CAMERA_REQUEST_SIZE)
        cameras = tuple(
            CameraRequest(*CAMERA_REQUEST_STRUCT.unpack_from(data, offset)) for offset in offsets
        )
        packet = cls(cameras=cameras, max_datagram_bytes=max_datagram)
        try:
            packet.check()
        except ProtocolError as err:
            raise ProtocolError(f"hello packet: {err}") from err
        return packet


@dataclass(frozen=True)
class VideoFragment:
    """Robot -> OCU: bytes [offset, offset + len(payload)) of one camera's JPEG frame."""

    camera: int
    sequence: int
    capture_time_us: int
    frame_bytes: int
    offset: int
    index: int
    count: int
    payload: bytes

    def check(self) -> None:
        """ProtocolError unless the header fields agree with each other and the payload."""
        _check("camera", self.camera, _U8)
        _check("sequence", self.sequence, _U32)
        _check("capture_time_us", self.capture_time_us, _U64)
        _check("frame_bytes", self.frame_bytes, (1, MAX_FRAME_BYTES))
        _check("count", self.count, (1, MAX_FRAGMENTS))
        _check("index", self.index, (0, self.count - 1))
        _check("offset", self.offset, (0, self.frame_bytes - 1))
        if not self.payload:
            raise ProtocolError("fragment payload is empty")
        if self.offset + len(self.payload) > self.frame_bytes:
            raise ProtocolError(
                f"fragment bytes {self.offset}..{self.offset + len(self.payload)} "
                f"run past the frame's {self.frame_bytes} bytes"
            )

    def encode(self, frame_type: int) -> bytes:
        """26-byte header plus the payload."""
        self.check()
        header = FRAGMENT_HEADER_STRUCT.pack(
            frame_type,
            self.camera,
            self.sequence,
            self.capture_time_us,
            self.frame_bytes,
            self.offset,
            self.index,
            self.count,
        )
        if len(header) + len(self.payload) > MAX_DATAGRAM:
            raise ProtocolError(f"fragment of {len(self.payload)} bytes does not fit a datagram")
        return header + self.payload

    @classmethod
    def decode(cls, data: bytes, frame_type: int) -> VideoFragment:
        """Parse a fragment datagram; header consistency is checked, the JPEG is not."""
        if len(data) <= FRAGMENT_HEADER_SIZE:
            raise ProtocolError(
                f"video fragment needs more than {FRAGMENT_HEADER_SIZE} bytes, got {len(data)}"
            )
        kind, camera, sequence, capture_us, frame_bytes, offset, index, count = (
            FRAGMENT_HEADER_STRUCT.unpack_from(data)
        )
        _expect_type(kind, frame_type, "video fragment")
        fragment = cls(
            camera=camera,
            sequence=sequence,
            capture_time_us=capture_us,
            frame_bytes=frame_bytes,
            offset=offset,
            index=index,
            count=count,
            payload=bytes(data[FRAGMENT_HEADER_SIZE:]),
        )
        fragment.check()
        return fragment


@dataclass(frozen=True)
class StatusPacket:
    """Robot -> OCU: what the vendor protocol cannot report; None = not measured."""

    sequence: int = 0
    voltage_mv: int | None = None
    charge_permille: int | None = None
    headlight_on: bool | None = None
    roll_mrad: int | None = None
    pitch_mrad: int | None = None
    camera_count: int = 0

    def encode(self, frame_type: int) -> bytes:
        """20 bytes; a None field goes on the wire as its "not measured" value."""
        _check("sequence", self.sequence, _U32)
        _check("camera_count", self.camera_count, _U8)
        voltage = VOLTAGE_UNKNOWN if self.voltage_mv is None else self.voltage_mv
        if self.voltage_mv is not None:
            _check("voltage_mv", voltage, (0, VOLTAGE_UNKNOWN - 1))
        charge = CHARGE_UNKNOWN if self.charge_permille is None else self.charge_permille
        if self.charge_permille is not None:
            _check("charge_permille", charge, (0, CHARGE_FULL_PERMILLE))
        headlight = HEADLIGHT_UNKNOWN if self.headlight_on is None else int(self.headlight_on)
        angles = []
        for name, value in (("roll_mrad", self.roll_mrad), ("pitch_mrad", self.pitch_mrad)):
            if value is None:
                angles.append(ANGLE_UNKNOWN)
            else:
                _check(name, value, (ANGLE_UNKNOWN + 1, _I16[1]))
                angles.append(value)
        return STATUS_STRUCT.pack(
            frame_type,
            MAGIC,
            VERSION,
            self.sequence,
            voltage,
            charge,
            headlight,
            angles[0],
            angles[1],
            self.camera_count,
        )

    @classmethod
    def decode(cls, data: bytes, frame_type: int) -> StatusPacket:
        """Parse a 20-byte status packet."""
        if len(data) != STATUS_SIZE:
            raise ProtocolError(f"status packet must be {STATUS_SIZE} bytes, got {len(data)}")
        kind, magic, version, sequence, voltage, charge, headlight, roll, pitch, cameras = (
            STATUS_STRUCT.unpack(data)
        )
        _expect_type(kind, frame_type, "status")
        _check_header(magic, version, "status")
        if charge != CHARGE_UNKNOWN and charge > CHARGE_FULL_PERMILLE:
            raise ProtocolError(f"status charge {charge} permille over {CHARGE_FULL_PERMILLE}")
        if headlight not in (0, 1, HEADLIGHT_UNKNOWN):
            raise ProtocolError(f"status headlight value {headlight} is not 0, 1 or 0xff")
        return cls(
            sequence=sequence,
            voltage_mv=None if voltage == VOLTAGE_UNKNOWN else voltage,
            charge_permille=None if charge == CHARGE_UNKNOWN else charge,
            headlight_on=None if headlight == HEADLIGHT_UNKNOWN else headlight == 1,
            roll_mrad=None if roll == ANGLE_UNKNOWN else roll,
            pitch_mrad=None if pitch == ANGLE_UNKNOWN else pitch,
            camera_count=cameras,
        )


ExtendedPacket = HelloPacket | VideoFragment | StatusPacket


@dataclass(frozen=True)
class ExtendedCodec:
    """Encode and decode the extension's packets with a given set of frame type IDs."""

    hello_type: int = 0x10
    fragment_type: int = 0x11
    status_type: int = 0x12

    def handles(self, frame_type: int) -> bool:
        """Whether a datagram's first byte names one of the extension's packets."""
        return frame_type in (self.hello_type, self.fragment_type, self.status_type)

    def encode(self, packet: ExtendedPacket) -> bytes:
        """Bytes on the wire for any extension packet."""
        if isinstance(packet, HelloPacket):
            return packet.encode(self.hello_type)
        if isinstance(packet, VideoFragment):
            return packet.encode(self.fragment_type)
        return packet.encode(self.status_type)

    def decode(self, data: bytes) -> ExtendedPacket:
        """Parse one datagram; ProtocolError for anything malformed or not an extension type."""
        if not data:
            raise ProtocolError("empty datagram")
        frame_type = data[0]
        if frame_type == self.fragment_type:
            return VideoFragment.decode(data, frame_type)
        if frame_type == self.status_type:
            return StatusPacket.decode(data, frame_type)
        if frame_type == self.hello_type:
            return HelloPacket.decode(data, frame_type)
        raise ProtocolError(f"frame type 0x{frame_type:02x} is not an extension packet")


def fragment_frame(
    camera: int,
    sequence: int,
    capture_time_us: int,
    jpeg: bytes,
    max_datagram_bytes: int,
) -> list[VideoFragment]:
    """Split one JPEG into fragments whose datagrams fit max_datagram_bytes."""
    if not (jpeg.startswith(JPEG_SOI) and jpeg.endswith(JPEG_EOI)):
        raise ProtocolError("frame is not a complete JPEG (SOI ... EOI)")
    _check("max_datagram_bytes", max_datagram_bytes, (MIN_DATAGRAM, MAX_DATAGRAM))
    chunk = max_datagram_bytes - FRAGMENT_HEADER_SIZE
    count = -(-len(jpeg) // chunk)
    if count > MAX_FRAGMENTS:
        raise ProtocolError(f"JPEG of {len(jpeg)} bytes needs {count} fragments")
    return [
        VideoFragment(
            camera=camera,
            sequence=sequence,
            capture_time_us=capture_time_us,
            frame_bytes=len(jpeg),
            offset=index * chunk,
            index=index,
            count=count,
            payload=jpeg[index * chunk : (index + 1) * chunk],
        )
        for index in range(count)
    ]


def _expect_type(kind: int, frame_type: int, what: str) -> None:
    if kind != frame_type:
        raise ProtocolError(f"frame type 0x{kind:02x} is not {what} (0x{frame_type:02x})")
