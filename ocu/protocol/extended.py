"""Codecs of ocu's open protocol extension (docs/protocol.md, "Extended protocol").

Five packet types beside the vendor's, each one UDP datagram, little-endian, no padding:

- hello (OCU -> robot): the extension probe, repeated alongside the RCPs, carrying the
  per-camera stream request (resolution, frame rate, JPEG quality) and the largest datagram
  the OCU wants to receive;
- video fragment (robot -> OCU): one piece of one camera's JPEG, tagged with camera id,
  sequence number, capture time, byte offset, fragment index and count;
- status (robot -> OCU): battery voltage and charge, headlight state, roll and pitch, each
  with a "not measured" value so the robot never has to invent one; version 2 adds the
  heading (yaw) of the robot's IMU;
- scan (robot -> OCU): one sweep of a planar range sensor, ranges in millimetres;
- sequenced RCP (OCU -> robot): the vendor RCP's fields behind a sequence number, sent instead
  of the vendor RCP to a robot that speaks the extension, so that it can drop an RCP older
  than the newest it applied (one that jitter or a duplicate delivered late).

The vendor packets are unchanged. Pure code: no Qt, no sockets; ProtocolError for bad data.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from ocu.protocol.errors import ProtocolError
from ocu.protocol.packets import JPEG_EOI, JPEG_SOI, MAX_DATAGRAM, RCP_SIZE, RemoteControlPacket
from ocu.records import CameraRequest, StreamRequestError

MAGIC = b"OCUX"
VERSION = 1

HELLO_HEADER_STRUCT = struct.Struct("<B4sBHB")
CAMERA_REQUEST_STRUCT = struct.Struct("<BHHBB")
FRAGMENT_HEADER_STRUCT = struct.Struct("<BBIQIIHH")
STATUS_STRUCT = struct.Struct("<B4sBIHHBhhB")
# Version 2 of the status packet appends the IMU heading (i16 mrad) to version 1's fields.
STATUS_YAW_STRUCT = struct.Struct("<h")
# Version 3 appends the echo of the sequenced RCPs to version 2's fields: the newest one the
# robot applied and how many it applied (u32 each, wrapping).
STATUS_RCP_STRUCT = struct.Struct("<II")
SCAN_HEADER_STRUCT = struct.Struct("<B4sBIQiiHHH")
# Frame type, magic, version, sequence; then the vendor RCP without its frame type byte.
SEQUENCED_RCP_HEADER_STRUCT = struct.Struct("<B4sBI")

HELLO_HEADER_SIZE = HELLO_HEADER_STRUCT.size
CAMERA_REQUEST_SIZE = CAMERA_REQUEST_STRUCT.size
FRAGMENT_HEADER_SIZE = FRAGMENT_HEADER_STRUCT.size
STATUS_SIZE = STATUS_STRUCT.size
STATUS_V2_SIZE = STATUS_SIZE + STATUS_YAW_STRUCT.size
STATUS_V3_SIZE = STATUS_V2_SIZE + STATUS_RCP_STRUCT.size
SCAN_HEADER_SIZE = SCAN_HEADER_STRUCT.size
SEQUENCED_RCP_SIZE = SEQUENCED_RCP_HEADER_STRUCT.size + RCP_SIZE - 1

assert HELLO_HEADER_SIZE == 9
assert CAMERA_REQUEST_SIZE == 7
assert FRAGMENT_HEADER_SIZE == 26
assert STATUS_SIZE == 20
assert STATUS_V2_SIZE == 22
assert STATUS_V3_SIZE == 30
assert SCAN_HEADER_SIZE == 32
assert SEQUENCED_RCP_SIZE == 66

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
STATUS_VERSION_YAW = 2
STATUS_VERSION_RCP = 3
# Scan ranges: 0 means no return within range_max, 0xFFFF no measurement at all.
SCAN_NO_RETURN = 0
SCAN_INVALID = 0xFFFF
MAX_SCAN_BEAMS = 8192
SEQUENCE_MODULUS = 2**32

_U8 = (0, 255)
_U32 = (0, 2**32 - 1)
_U64 = (0, 2**64 - 1)
_I16 = (-32768, 32767)
_I32 = (-(2**31), 2**31 - 1)
TWO_PI_URAD = 6_283_186


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
            try:
                request.check()
            except StreamRequestError as err:
                raise ProtocolError(str(err)) from err

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
    # Heading of the robot's IMU, mrad, counter-clockwise seen from above (REP 103), in
    # [-pi, pi]; its zero is wherever the IMU started. Sent from version 2 on.
    yaw_mrad: int | None = None
    # The sequenced RCPs' echo (version 3): the number of the newest one the robot applied
    # and how many distinct ones it has received, applied or dropped as late (both u32,
    # wrapping); None: no sequenced RCP applied yet,
    # or a robot that does not echo them.
    rcp_sequence: int | None = None
    rcp_received: int | None = None

    def encode(self, frame_type: int) -> bytes:
        """20 bytes (version 1), 22 with the heading (version 2), 30 with the sequenced RCPs'
        echo (version 3); a None field goes on the wire as its "not measured" value."""
        _check("sequence", self.sequence, _U32)
        echo = self.rcp_sequence is not None or self.rcp_received is not None
        if echo:
            if self.rcp_sequence is None or self.rcp_received is None:
                raise ProtocolError("the RCP echo needs both rcp_sequence and rcp_received")
            _check("rcp_sequence", self.rcp_sequence, _U32)
            _check("rcp_received", self.rcp_received, _U32)
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
        if self.yaw_mrad is not None:
            _check("yaw_mrad", self.yaw_mrad, (ANGLE_UNKNOWN + 1, _I16[1]))
        if echo:
            version = STATUS_VERSION_RCP
        else:
            version = VERSION if self.yaw_mrad is None else STATUS_VERSION_YAW
        packed = STATUS_STRUCT.pack(
            frame_type,
            MAGIC,
            version,
            self.sequence,
            voltage,
            charge,
            headlight,
            angles[0],
            angles[1],
            self.camera_count,
        )
        if version == VERSION:
            return packed
        yaw = ANGLE_UNKNOWN if self.yaw_mrad is None else self.yaw_mrad
        packed += STATUS_YAW_STRUCT.pack(yaw)
        if version == STATUS_VERSION_YAW:
            return packed
        assert self.rcp_sequence is not None
        assert self.rcp_received is not None
        return packed + STATUS_RCP_STRUCT.pack(self.rcp_sequence, self.rcp_received)

    @classmethod
    def decode(cls, data: bytes, frame_type: int) -> StatusPacket:
        """Parse a status packet: 20 bytes (version 1), 22 (version 2, with the heading) or 30
        (version 3, with the sequenced RCPs' echo)."""
        # The version byte says how long the packet must be (each version adds fields).
        sizes = {STATUS_VERSION_YAW: STATUS_V2_SIZE, STATUS_VERSION_RCP: STATUS_V3_SIZE}
        later = data[5] if len(data) > 5 and data[5] in sizes else None
        expected = STATUS_SIZE if later is None else sizes[later]
        if len(data) != expected:
            raise ProtocolError(f"status packet must be {expected} bytes, got {len(data)}")
        kind, magic, version, sequence, voltage, charge, headlight, roll, pitch, cameras = (
            STATUS_STRUCT.unpack_from(data)
        )
        _expect_type(kind, frame_type, "status")
        if later is None:
            _check_header(magic, version, "status")
        elif magic != MAGIC:
            raise ProtocolError(f"status magic {magic!r} is not {MAGIC!r}")
        yaw: int | None = None
        rcp_sequence: int | None = None
        rcp_received: int | None = None
        if later is not None:
            (raw_yaw,) = STATUS_YAW_STRUCT.unpack_from(data, STATUS_SIZE)
            yaw = None if raw_yaw == ANGLE_UNKNOWN else raw_yaw
        if later == STATUS_VERSION_RCP:
            rcp_sequence, rcp_received = STATUS_RCP_STRUCT.unpack_from(data, STATUS_V2_SIZE)
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
            yaw_mrad=yaw,
            rcp_sequence=rcp_sequence,
            rcp_received=rcp_received,
        )


@dataclass(frozen=True)
class ScanPacket:
    """Robot -> OCU: one sweep of a planar range sensor in the sensor's frame.

    Beam k points at angle_min + k * angle_increment (µrad, counter-clockwise from the
    sensor's x axis, REP 103); its range is in mm, `SCAN_NO_RETURN` when nothing was within
    range_max, `SCAN_INVALID` when the beam measured nothing.
    """

    sequence: int
    capture_time_us: int
    angle_min_urad: int
    angle_increment_urad: int
    range_min_mm: int
    range_max_mm: int
    ranges_mm: tuple[int, ...]

    def check(self) -> None:
        """ProtocolError unless every field fits the wire format and the ranges make sense."""
        _check("sequence", self.sequence, _U32)
        _check("capture_time_us", self.capture_time_us, _U64)
        _check("angle_min_urad", self.angle_min_urad, _I32)
        _check("angle_increment_urad", self.angle_increment_urad, _I32)
        if self.angle_increment_urad == 0:
            raise ProtocolError("scan angle_increment_urad is 0")
        _check("range_max_mm", self.range_max_mm, (1, SCAN_INVALID - 1))
        _check("range_min_mm", self.range_min_mm, (0, self.range_max_mm))
        count = len(self.ranges_mm)
        if not 1 <= count <= MAX_SCAN_BEAMS:
            raise ProtocolError(f"scan beam count {count} outside 1-{MAX_SCAN_BEAMS}")
        if abs(self.angle_increment_urad) * (count - 1) > 2 * TWO_PI_URAD:
            raise ProtocolError("scan beams span more than two turns")
        for index, value in enumerate(self.ranges_mm):
            if not isinstance(value, int) or isinstance(value, bool):
                raise ProtocolError(f"scan range #{index}={value!r} is not an integer")
            if value in (SCAN_NO_RETURN, SCAN_INVALID):
                continue
            if not self.range_min_mm <= value <= self.range_max_mm:
                raise ProtocolError(
                    f"scan range #{index}={value} mm outside "
                    f"[{self.range_min_mm}, {self.range_max_mm}] mm"
                )

    def encode(self, frame_type: int) -> bytes:
        """32-byte header plus 2 bytes per beam."""
        self.check()
        header = SCAN_HEADER_STRUCT.pack(
            frame_type,
            MAGIC,
            VERSION,
            self.sequence,
            self.capture_time_us,
            self.angle_min_urad,
            self.angle_increment_urad,
            self.range_min_mm,
            self.range_max_mm,
            len(self.ranges_mm),
        )
        data = header + struct.pack(f"<{len(self.ranges_mm)}H", *self.ranges_mm)
        if len(data) > MAX_DATAGRAM:
            raise ProtocolError(f"scan of {len(self.ranges_mm)} beams does not fit a datagram")
        return data

    @classmethod
    def decode(cls, data: bytes, frame_type: int) -> ScanPacket:
        """Parse a scan datagram; its length must match its beam count."""
        if len(data) < SCAN_HEADER_SIZE:
            raise ProtocolError(f"scan packet needs {SCAN_HEADER_SIZE} bytes, got {len(data)}")
        kind, magic, version, sequence, capture_us, angle_min, increment, low, high, count = (
            SCAN_HEADER_STRUCT.unpack_from(data)
        )
        _expect_type(kind, frame_type, "scan")
        _check_header(magic, version, "scan")
        expected = SCAN_HEADER_SIZE + 2 * count
        if len(data) != expected:
            raise ProtocolError(
                f"scan packet with {count} beams must be {expected} bytes, got {len(data)}"
            )
        ranges = struct.unpack_from(f"<{count}H", data, SCAN_HEADER_SIZE)
        packet = cls(
            sequence=sequence,
            capture_time_us=capture_us,
            angle_min_urad=angle_min,
            angle_increment_urad=increment,
            range_min_mm=low,
            range_max_mm=high,
            ranges_mm=tuple(ranges),
        )
        try:
            packet.check()
        except ProtocolError as err:
            raise ProtocolError(f"scan packet: {err}") from err
        return packet


@dataclass(frozen=True)
class SequencedRcp:
    """OCU -> robot: a vendor RCP behind a sequence number (u32, +1 per RCP, wrapping)."""

    sequence: int
    rcp: RemoteControlPacket

    def encode(self, frame_type: int) -> bytes:
        """66 bytes: the extension header, the sequence, the RCP's 56 bytes after its type."""
        _check("sequence", self.sequence, _U32)
        body = self.rcp.encode(0)[1:]
        return SEQUENCED_RCP_HEADER_STRUCT.pack(frame_type, MAGIC, VERSION, self.sequence) + body

    @classmethod
    def decode(cls, data: bytes, frame_type: int) -> SequencedRcp:
        """Parse a 66-byte sequenced RCP; ProtocolError on a wrong length, type or header."""
        if len(data) != SEQUENCED_RCP_SIZE:
            raise ProtocolError(
                f"sequenced RCP must be {SEQUENCED_RCP_SIZE} bytes, got {len(data)}"
            )
        kind, magic, version, sequence = SEQUENCED_RCP_HEADER_STRUCT.unpack_from(data)
        _expect_type(kind, frame_type, "a sequenced RCP")
        _check_header(magic, version, "sequenced RCP")
        body = bytes(data[SEQUENCED_RCP_HEADER_STRUCT.size :])
        return cls(sequence, RemoteControlPacket.decode(b"\0" + body, 0))


def sequence_newer(sequence: int, than: int) -> bool:
    """Whether `sequence` comes after `than` (serial number arithmetic: it wraps at 2**32)."""
    return 0 < (sequence - than) % SEQUENCE_MODULUS < SEQUENCE_MODULUS // 2


ExtendedPacket = HelloPacket | VideoFragment | StatusPacket | ScanPacket | SequencedRcp


@dataclass(frozen=True)
class ExtendedCodec:
    """Encode and decode the extension's packets with a given set of frame type IDs."""

    hello_type: int = 0x10
    fragment_type: int = 0x11
    status_type: int = 0x12
    # None: no range scans in this extension (an older profile).
    scan_type: int | None = 0x13
    # None: no sequenced RCPs (an older profile): the OCU sends vendor RCPs only.
    rcp_type: int | None = 0x14

    def handles(self, frame_type: int) -> bool:
        """Whether a datagram's first byte names one of the extension's packets."""
        return frame_type in (
            self.hello_type,
            self.fragment_type,
            self.status_type,
            self.scan_type,
            self.rcp_type,
        )

    def encode(self, packet: ExtendedPacket) -> bytes:
        """Bytes on the wire for any extension packet."""
        if isinstance(packet, HelloPacket):
            return packet.encode(self.hello_type)
        if isinstance(packet, VideoFragment):
            return packet.encode(self.fragment_type)
        if isinstance(packet, ScanPacket):
            if self.scan_type is None:
                raise ProtocolError("this extension has no scan packet type")
            return packet.encode(self.scan_type)
        if isinstance(packet, SequencedRcp):
            if self.rcp_type is None:
                raise ProtocolError("this extension has no sequenced RCP type")
            return packet.encode(self.rcp_type)
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
        if frame_type == self.scan_type:
            return ScanPacket.decode(data, frame_type)
        if frame_type == self.rcp_type:
            return SequencedRcp.decode(data, frame_type)
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
