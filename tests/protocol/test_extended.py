"""The protocol extension's codecs: golden bytes, round trips, every malformed input."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ocu.protocol import ProtocolError
from ocu.protocol.extended import (
    FRAGMENT_HEADER_SIZE,
    ExtendedCodec,
    HelloPacket,
    StatusPacket,
    VideoFragment,
    fragment_frame,
)
from ocu.records import CameraRequest

CODEC = ExtendedCodec(hello_type=0x10, fragment_type=0x11, status_type=0x12)
JPEG = b"\xff\xd8\xff\xe0" + bytes(range(256)) * 20 + b"\xff\xd9"

HELLO = HelloPacket(
    cameras=(CameraRequest(camera=2, width_px=640, height_px=480, fps=30),),
    max_datagram_bytes=1472,
)
HELLO_BYTES = bytes.fromhex("10 4f435558 01 c005 01" + "02 8002 e001 1e 00")

FRAGMENT = VideoFragment(
    camera=3,
    sequence=0x01020304,
    capture_time_us=1_000_000,
    frame_bytes=10,
    offset=4,
    index=1,
    count=3,
    payload=b"abcd",
)
FRAGMENT_BYTES = bytes.fromhex(
    "11 03 04030201 40420f0000000000 0a000000 04000000 0100 0300" + "61626364"
)

STATUS = StatusPacket(
    sequence=7,
    voltage_mv=24100,
    charge_permille=635,
    headlight_on=True,
    roll_mrad=-52,
    pitch_mrad=105,
    camera_count=4,
)
STATUS_BYTES = bytes.fromhex("12 4f435558 01 07000000 245e 7b02 01 ccff 6900 04")
UNKNOWN_STATUS_BYTES = bytes.fromhex("12 4f435558 01 00000000 ffff ffff ff 0080 0080 00")


@pytest.mark.parametrize(
    ("packet", "wire"),
    [(HELLO, HELLO_BYTES), (FRAGMENT, FRAGMENT_BYTES), (STATUS, STATUS_BYTES)],
    ids=["hello", "fragment", "status"],
)
def test_golden_bytes_both_ways(packet: object, wire: bytes) -> None:
    assert CODEC.encode(packet) == wire  # type: ignore[arg-type]
    assert CODEC.decode(wire) == packet


def test_status_not_measured_is_none_never_a_value() -> None:
    assert CODEC.encode(StatusPacket()) == UNKNOWN_STATUS_BYTES
    decoded = CODEC.decode(UNKNOWN_STATUS_BYTES)
    assert isinstance(decoded, StatusPacket)
    assert decoded.voltage_mv is None
    assert decoded.charge_permille is None
    assert decoded.headlight_on is None
    assert decoded.roll_mrad is None
    assert decoded.pitch_mrad is None


def test_hello_with_four_cameras_round_trips() -> None:
    hello = HelloPacket(
        cameras=tuple(CameraRequest(k, 320 * (k + 1), 240, 15 + k, k * 10) for k in range(4)),
        max_datagram_bytes=65507,
    )
    wire = CODEC.encode(hello)
    assert len(wire) == 9 + 4 * 7
    assert CODEC.decode(wire) == hello


def test_codec_knows_only_its_types() -> None:
    assert CODEC.handles(0x10)
    assert CODEC.handles(0x12)
    assert not CODEC.handles(0x01)
    with pytest.raises(ProtocolError, match=r"^frame type 0x03 is not an extension packet$"):
        CODEC.decode(b"\x03\xff\xd8\xff\xd9")
    with pytest.raises(ProtocolError, match=r"^empty datagram$"):
        CODEC.decode(b"")


@pytest.mark.parametrize(
    ("wire", "message"),
    [
        (HELLO_BYTES[:8], r"^hello packet needs 9 bytes, got 8$"),
        (HELLO_BYTES[:-1], r"^hello packet with 1 cameras must be 16 bytes, got 15$"),
        (HELLO_BYTES[:1] + b"OCUY" + HELLO_BYTES[5:], r"^hello magic b'OCUY' is not b'OCUX'$"),
        (HELLO_BYTES[:5] + b"\x02" + HELLO_BYTES[6:], r"^hello version 2 not supported"),
        (HELLO_BYTES[:6] + b"\x10\x00" + HELLO_BYTES[8:], r"max_datagram_bytes=16 out of range"),
        (HELLO_BYTES[:-1] + b"\x65", r"^hello packet: quality=101 out of range \[0, 100\]$"),
        (HELLO_BYTES[:9] + b"\x02\x00\x00" + HELLO_BYTES[12:], r"width_px=0 out of range"),
        (FRAGMENT_BYTES[:FRAGMENT_HEADER_SIZE], r"^video fragment needs more than 26 bytes"),
        (FRAGMENT_BYTES[:22] + b"\x03\x00" + FRAGMENT_BYTES[24:], r"^index=3 out of range"),
        (FRAGMENT_BYTES[:24] + b"\x00\x00" + FRAGMENT_BYTES[26:], r"^count=0 out of range"),
        (FRAGMENT_BYTES + b"xyz", r"^fragment bytes 4\.\.11 run past the frame's 10 bytes$"),
        (FRAGMENT_BYTES[:14] + bytes(4) + FRAGMENT_BYTES[18:], r"^frame_bytes=0 out of range"),
        (STATUS_BYTES[:-1], r"^status packet must be 20 bytes, got 19$"),
        (STATUS_BYTES[:12] + b"\xe9\x03" + STATUS_BYTES[14:], r"charge 1001 permille over 1000"),
        (STATUS_BYTES[:14] + b"\x02" + STATUS_BYTES[15:], r"headlight value 2 is not 0, 1"),
        (STATUS_BYTES[:1] + b"ABCD" + STATUS_BYTES[5:], r"^status magic b'ABCD' is not"),
    ],
)
def test_malformed_datagrams(wire: bytes, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        CODEC.decode(wire)


@pytest.mark.parametrize(
    ("packet", "message"),
    [
        (HelloPacket(cameras=(CameraRequest(0, 640, 480, 256),)), r"^fps=256 out of range"),
        (HelloPacket(cameras=(CameraRequest(0, 1, 1, 1),) * 2), r"^a camera is requested twice$"),
        (HelloPacket(max_datagram_bytes=70000), r"^max_datagram_bytes=70000 out of range"),
        (StatusPacket(charge_permille=1001), r"^charge_permille=1001 out of range"),
        (StatusPacket(voltage_mv=65535), r"^voltage_mv=65535 out of range"),
        (StatusPacket(roll_mrad=-32768), r"^roll_mrad=-32768 out of range"),
        (StatusPacket(sequence=-1), r"^sequence=-1 out of range"),
        (
            VideoFragment(0, 0, 0, 4, 0, 0, 1, b""),
            r"^fragment payload is empty$",
        ),
        (
            VideoFragment(0, 2**32, 0, 4, 0, 0, 1, b"abcd"),
            r"^sequence=4294967296 out of range",
        ),
    ],
)
def test_values_that_cannot_be_encoded(packet: object, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        CODEC.encode(packet)  # type: ignore[arg-type]


@pytest.mark.parametrize("max_datagram", [64, 1472, 9000, 65507])
def test_fragment_frame_covers_the_jpeg_within_the_datagram_size(max_datagram: int) -> None:
    fragments = fragment_frame(1, 42, 123, JPEG, max_datagram)
    assert b"".join(f.payload for f in fragments) == JPEG
    for index, fragment in enumerate(fragments):
        wire = CODEC.encode(fragment)
        assert len(wire) <= max_datagram
        assert (fragment.index, fragment.count) == (index, len(fragments))
        assert fragment.frame_bytes == len(JPEG)
        assert CODEC.decode(wire) == fragment


def test_fragment_frame_refuses_what_is_not_a_jpeg() -> None:
    with pytest.raises(ProtocolError, match=r"^frame is not a complete JPEG"):
        fragment_frame(0, 0, 0, JPEG[:-1], 1472)
    with pytest.raises(ProtocolError, match=r"^max_datagram_bytes=10 out of range"):
        fragment_frame(0, 0, 0, JPEG, 10)


@settings(max_examples=300, deadline=None)
@given(
    kind=st.sampled_from([0x10, 0x11, 0x12]),
    body=st.binary(max_size=64),
)
def test_random_datagrams_raise_only_protocol_errors(kind: int, body: bytes) -> None:
    try:
        packet = CODEC.decode(bytes([kind]) + body)
    except ProtocolError:
        return
    assert CODEC.decode(CODEC.encode(packet)) == packet
