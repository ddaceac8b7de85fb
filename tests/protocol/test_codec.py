"""Codec: dispatch by frame type ID, golden datagrams, round trips and fuzzed input."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ocu.protocol
from ocu.protocol import (
    MOTOR_SLOTS,
    Codec,
    MotorRecord,
    Packet,
    ProtocolError,
    RemoteControlPacket,
    TelemetryPacket,
    VideoFramePacket,
    errors,
)

SOI = b"\xff\xd8\xff"
EOI = b"\xff\xd9"

CODEC = Codec()

RCP_GOLDEN = bytes.fromhex(
    "01"  # @0  frame type ID (RCP)
    "0000"  # @1  axis 0 = 0
    "e737"  # @3  axis 1 = 14311: 0.2 m/s forward at 71553.837 per m/s
    + "0000" * 14  # @5..32 axes 2-15 = 0
    + "01"  # @33 button 0 = 1
    + "00" * 15  # @34..48 buttons 1-15 = 0
    + "0000000000000000"  # @49..56 video bit rate = 0.0
)
RCP_PACKET = RemoteControlPacket(axes=(0, 14311) + (0,) * 14, buttons=(1,) + (0,) * 15)

MOTOR = MotorRecord(device_id=5, position=0x80000000, speed=-1000, current=250)
TELEMETRY_GOLDEN = (
    bytes.fromhex(
        "02"  # @0  frame type ID (telemetry)
        "e803000000000000"  # @1..8 tick = 1000
        "01"  # @9  number of motors = 1
        "05"  # @10 motor #0 device ID = 5
        "00"  # @11 device state
        "00"  # @12 operation mode
        "00"  # @13 pad
        "00000080"  # @14 position = 0x80000000
        "18fc"  # @18 speed = -1000
        "fa00"  # @20 current = 250
        "0000"  # @22 status bits
        "0000"  # @24 pad
        "00000000"  # @26 position command
        "0000"  # @30 speed command
        "0000"  # @32 current command
    )
    + bytes(24 * 9)  # @34..249 unused motor slots
    + bytes(25)  # @250..274 not used
)
TELEMETRY_PACKET = TelemetryPacket(tick=1000, motors=(MOTOR,))

VIDEO_JPEG = bytes.fromhex("ffd8ffdb0000ffd9")
VIDEO_GOLDEN = bytes.fromhex("03") + VIDEO_JPEG

i16 = st.integers(-32768, 32767)
u8 = st.integers(0, 255)
u32 = st.integers(0, 2**32 - 1)

packets: st.SearchStrategy[Packet] = st.one_of(
    st.builds(
        RemoteControlPacket,
        axes=st.lists(i16, min_size=16, max_size=16).map(tuple),
        buttons=st.lists(u8, min_size=16, max_size=16).map(tuple),
        video_bitrate=st.floats(allow_nan=False),
    ),
    st.builds(
        TelemetryPacket,
        tick=st.integers(0, 2**64 - 1),
        motors=st.lists(
            st.builds(
                MotorRecord,
                device_id=u8,
                state=u8,
                mode=u8,
                position=u32,
                speed=i16,
                current=i16,
                status=i16,
                position_command=u32,
                speed_command=i16,
                current_command=i16,
            ),
            max_size=MOTOR_SLOTS,
        ).map(tuple),
    ),
    st.builds(VideoFramePacket, jpeg=st.binary(max_size=512).map(lambda b: SOI + b + EOI)),
)


def test_one_exception_type() -> None:
    assert ocu.protocol.ProtocolError is errors.ProtocolError
    assert issubclass(ProtocolError, ValueError)


def test_default_frame_type_ids() -> None:
    assert (CODEC.rcp_type, CODEC.telemetry_type, CODEC.video_type) == (0x01, 0x02, 0x03)


@pytest.mark.parametrize(
    ("data", "packet"),
    [
        (RCP_GOLDEN, RCP_PACKET),
        (TELEMETRY_GOLDEN, TELEMETRY_PACKET),
        (VIDEO_GOLDEN, VideoFramePacket(jpeg=VIDEO_JPEG)),
    ],
    ids=["rcp", "telemetry", "video"],
)
def test_golden_datagrams(data: bytes, packet: Packet) -> None:
    assert CODEC.decode(data) == packet
    assert CODEC.encode(packet) == data


def test_frame_type_ids_come_from_the_codec() -> None:
    codec = Codec(rcp_type=0x10, telemetry_type=0x20, video_type=0x30)
    assert codec.encode(RCP_PACKET) == b"\x10" + RCP_GOLDEN[1:]
    assert codec.encode(TELEMETRY_PACKET) == b"\x20" + TELEMETRY_GOLDEN[1:]
    assert codec.encode(VideoFramePacket(jpeg=VIDEO_JPEG)) == b"\x30" + VIDEO_JPEG
    assert codec.decode(b"\x10" + RCP_GOLDEN[1:]) == RCP_PACKET
    assert codec.decode(b"\x20" + TELEMETRY_GOLDEN[1:]) == TELEMETRY_PACKET
    with pytest.raises(ProtocolError, match=r"^unknown frame type 0x01$"):
        codec.decode(RCP_GOLDEN)


@given(packets)
def test_round_trip(packet: Packet) -> None:
    assert CODEC.decode(CODEC.encode(packet)) == packet


# --- malformed datagrams ------------------------------------------------------------------


def test_empty_datagram() -> None:
    with pytest.raises(ProtocolError, match=r"^empty datagram$"):
        CODEC.decode(b"")


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (RCP_GOLDEN[:1], r"^RCP packet must be 57 bytes, got 1$"),
        (RCP_GOLDEN[:56], r"^RCP packet must be 57 bytes, got 56$"),
        (RCP_GOLDEN + b"\x00", r"^RCP packet must be 57 bytes, got 58$"),
        (TELEMETRY_GOLDEN[:1], r"^telemetry packet must be 275 bytes, got 1$"),
        (TELEMETRY_GOLDEN[:274], r"^telemetry packet must be 275 bytes, got 274$"),
        (TELEMETRY_GOLDEN + b"\x00", r"^telemetry packet must be 275 bytes, got 276$"),
        # An RCP-sized telemetry datagram and a telemetry-sized RCP.
        (b"\x02" + RCP_GOLDEN[1:], r"^telemetry packet must be 275 bytes, got 57$"),
        (b"\x01" + TELEMETRY_GOLDEN[1:], r"^RCP packet must be 57 bytes, got 275$"),
    ],
    ids=["rcp-1", "rcp-56", "rcp-58", "tm-1", "tm-274", "tm-276", "tm-57", "rcp-275"],
)
def test_wrong_length(data: bytes, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        CODEC.decode(data)


@pytest.mark.parametrize("frame_type", [0x00, 0x04, 0x7F, 0xFF])
def test_unknown_frame_type(frame_type: int) -> None:
    with pytest.raises(ProtocolError, match=rf"^unknown frame type 0x{frame_type:02x}$"):
        CODEC.decode(bytes((frame_type,)) + RCP_GOLDEN[1:])
    with pytest.raises(ProtocolError, match=rf"^unknown frame type 0x{frame_type:02x}$"):
        CODEC.decode(bytes((frame_type,)))


@pytest.mark.parametrize("count", [11, 255])
def test_motor_count_over_ten(count: int) -> None:
    data = TELEMETRY_GOLDEN[:9] + bytes((count,)) + TELEMETRY_GOLDEN[10:]
    with pytest.raises(ProtocolError, match=rf"^telemetry motor count {count} over 10$"):
        CODEC.decode(data)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"\x03", r"^video payload is not a JPEG \(no SOI marker\)$"),
        (b"\x03" + VIDEO_JPEG[2:], r"^video payload is not a JPEG \(no SOI marker\)$"),
        (VIDEO_GOLDEN[:-1], r"^video payload is a truncated JPEG \(no EOI marker\)$"),
        (VIDEO_GOLDEN[:-2], r"^video payload is a truncated JPEG \(no EOI marker\)$"),
    ],
    ids=["no-payload", "no-soi", "half-eoi", "no-eoi"],
)
def test_bad_video(data: bytes, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        CODEC.decode(data)


@pytest.mark.parametrize(
    ("packet", "message"),
    [
        (RemoteControlPacket(axes=(32768,) + (0,) * 15), r"^axis\[0\]=32768 out of range"),
        (RemoteControlPacket(buttons=(0, 256) + (0,) * 14), r"^button\[1\]=256 out of range"),
        (TelemetryPacket(tick=-1), r"^tick=-1 out of range"),
        (
            TelemetryPacket(motors=(MotorRecord(position=2**32),)),
            r"^motor\.position=4294967296 out of range",
        ),
        (TelemetryPacket(motors=(MOTOR,) * 11), r"^motor count 11 over 10$"),
        (VideoFramePacket(jpeg=b"not a jpeg"), r"no SOI marker"),
        (VideoFramePacket(jpeg=SOI), r"no EOI marker"),
        (
            VideoFramePacket(jpeg=SOI + bytes(70_000) + EOI),
            r"^JPEG of 70005 bytes does not fit one datagram$",
        ),
    ],
    ids=["axis", "button", "tick", "position", "motors", "no-soi", "no-eoi", "too-large"],
)
def test_encode_out_of_range(packet: Packet, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        CODEC.encode(packet)


# --- fuzzing ------------------------------------------------------------------------------


@st.composite
def datagrams(draw: st.DrawFn) -> bytes:
    """Random datagrams, many of them with a known frame type and a plausible length."""
    frame_type = draw(st.sampled_from([0x01, 0x02, 0x03]) | u8)
    size = draw(st.sampled_from([56, 57, 58, 274, 275, 276]) | st.integers(0, 400))
    body = bytearray(draw(st.binary(min_size=size, max_size=size)))
    if size >= 10 and draw(st.booleans()):
        body[8] = draw(st.integers(0, 12))  # telemetry motor count near the limit
    if draw(st.booleans()):
        body[: len(SOI)] = SOI
    return bytes((frame_type,)) + bytes(body)


@settings(max_examples=300)
@given(st.binary(max_size=400) | datagrams())
def test_decode_raises_only_protocol_error(data: bytes) -> None:
    try:
        packet = CODEC.decode(data)
    except ProtocolError:
        return
    assert isinstance(packet, (RemoteControlPacket, TelemetryPacket, VideoFramePacket))
