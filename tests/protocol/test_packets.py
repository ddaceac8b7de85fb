"""Packet codecs against golden bytes written by hand from seed 000 tables 1-3 and seed 001
table IV, round trips, and every malformed input.

The golden byte strings are assembled field by field from the tables; struct is never used
here to produce expected bytes. Offsets in the comments are byte offsets in the packet.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ocu.protocol import (
    MOTOR_SLOTS,
    RCP_SIZE,
    TELEMETRY_SIZE,
    MotorRecord,
    ProtocolError,
    RemoteControlPacket,
    TelemetryPacket,
    VideoFramePacket,
)

RCP_TYPE = 0x01
TELEMETRY_TYPE = 0x02
VIDEO_TYPE = 0x03

# JPEG markers, as the codec checks them: SOI (FF D8) plus the first byte of the next marker.
SOI = b"\xff\xd8\xff"
EOI = b"\xff\xd9"

RCP_AXES = (
    -32768, 32767, 1, -1, 0x1234, -2, 256, 0,
    14311, -14311, 2, -256, 127, 128, -129, 0x0102,
)  # fmt: skip
RCP_BUTTONS = (1, 3, 0, 128, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 255)
RCP_BITRATE = 1_000_000.0

RCP_GOLDEN = bytes.fromhex(
    "01"  # @0  frame type ID, u8 (RCP)
    "0080"  # @1  axis 0, i16 = -32768
    "ff7f"  # @3  axis 1 = 32767
    "0100"  # @5  axis 2 = 1
    "ffff"  # @7  axis 3 = -1
    "3412"  # @9  axis 4 = 0x1234
    "feff"  # @11 axis 5 = -2
    "0001"  # @13 axis 6 = 256
    "0000"  # @15 axis 7 = 0
    "e737"  # @17 axis 8 = 14311 (0x37e7)
    "19c8"  # @19 axis 9 = -14311 (0xc819)
    "0200"  # @21 axis 10 = 2
    "00ff"  # @23 axis 11 = -256
    "7f00"  # @25 axis 12 = 127
    "8000"  # @27 axis 13 = 128
    "7fff"  # @29 axis 14 = -129
    "0201"  # @31 axis 15 = 0x0102
    "01"  # @33 button 0, u8 = 1
    "03"  # @34 button 1 = 3
    "00"  # @35 button 2 = 0
    "80"  # @36 button 3 = 128
    "0000000000000000000000"  # @37..47 buttons 4-14 = 0
    "ff"  # @48 button 15 = 255
    "0000000080842e41"  # @49..56 video bit rate, f64 = 1e6 (0x412e848000000000)
)

MOTOR_A = MotorRecord(
    device_id=3,
    state=1,
    mode=2,
    position=0x80001234,
    speed=-100,
    current=1500,
    status=0x0102,
    position_command=0x80000000,
    speed_command=-32768,
    current_command=32767,
)
MOTOR_A_GOLDEN = bytes.fromhex(
    "03"  # @0  device ID, u8 = 3
    "01"  # @1  device state, u8 = 1
    "02"  # @2  operation mode, u8 = 2
    "00"  # @3  pad: aligns the u32 position to offset 4
    "34120080"  # @4  position, u32 = 0x80001234
    "9cff"  # @8  speed, i16 = -100
    "dc05"  # @10 current, i16 = 1500
    "0201"  # @12 status bits, i16 = 0x0102
    "0000"  # @14 pad: aligns the u32 position command to offset 16
    "00000080"  # @16 position command, u32 = 0x80000000
    "0080"  # @20 speed command, i16 = -32768
    "ff7f"  # @22 current command, i16 = 32767
)

MOTOR_B = MotorRecord(
    device_id=4,
    state=0,
    mode=0,
    position=0xFFFFFFFF,
    speed=32767,
    current=-32768,
    status=-1,
    position_command=0,
    speed_command=1,
    current_command=-1,
)
MOTOR_B_GOLDEN = bytes.fromhex(
    "04"  # @0  device ID = 4
    "00"  # @1  device state = 0
    "00"  # @2  operation mode = 0
    "00"  # @3  pad
    "ffffffff"  # @4  position = 0xffffffff
    "ff7f"  # @8  speed = 32767
    "0080"  # @10 current = -32768
    "ffff"  # @12 status bits = -1
    "0000"  # @14 pad
    "00000000"  # @16 position command = 0
    "0100"  # @20 speed command = 1
    "ffff"  # @22 current command = -1
)

TELEMETRY_GOLDEN = (
    bytes.fromhex(
        "02"  # @0  frame type ID, u8 (telemetry)
        "0807060504030201"  # @1..8 tick number, u64 = 0x0102030405060708
        "02"  # @9  number of motors, u8 = 2
    )
    + MOTOR_A_GOLDEN  # @10..33  motor data #0
    + MOTOR_B_GOLDEN  # @34..57  motor data #1
    + bytes.fromhex("00" * 24 * 8)  # @58..249 motor data #2-#9, unused slots
    + bytes.fromhex("00" * 25)  # @250..274 not used
)

VIDEO_JPEG = bytes.fromhex(
    "ffd8"  # SOI
    "ffe000104a46494600010100000100010000"  # APP0 "JFIF"
    "ffd9"  # EOI
)
VIDEO_GOLDEN = bytes.fromhex("03") + VIDEO_JPEG  # @0 frame type ID (video), @1.. the JPEG

i16 = st.integers(-32768, 32767)
u8 = st.integers(0, 255)
u32 = st.integers(0, 2**32 - 1)
u64 = st.integers(0, 2**64 - 1)

rcps = st.builds(
    RemoteControlPacket,
    axes=st.lists(i16, min_size=16, max_size=16).map(tuple),
    buttons=st.lists(u8, min_size=16, max_size=16).map(tuple),
    video_bitrate=st.floats(allow_nan=False),
)
motor_records = st.builds(
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
)
telemetry_packets = st.builds(
    TelemetryPacket,
    tick=u64,
    motors=st.lists(motor_records, max_size=MOTOR_SLOTS).map(tuple),
)
video_packets = st.builds(
    VideoFramePacket, jpeg=st.binary(max_size=2048).map(lambda b: SOI + b + EOI)
)


# --- golden bytes -------------------------------------------------------------------------


def test_sizes_match_the_tables() -> None:
    assert len(RCP_GOLDEN) == RCP_SIZE == 57
    assert len(MOTOR_A_GOLDEN) == len(MOTOR_B_GOLDEN) == 24
    assert len(TELEMETRY_GOLDEN) == TELEMETRY_SIZE == 275


def test_rcp_golden_decode() -> None:
    packet = RemoteControlPacket.decode(RCP_GOLDEN, RCP_TYPE)
    assert packet.axes == RCP_AXES
    assert packet.buttons == RCP_BUTTONS
    assert packet.video_bitrate == RCP_BITRATE


def test_rcp_golden_encode() -> None:
    packet = RemoteControlPacket(axes=RCP_AXES, buttons=RCP_BUTTONS, video_bitrate=RCP_BITRATE)
    assert packet.encode(RCP_TYPE) == RCP_GOLDEN


def test_rcp_default_is_all_zero() -> None:
    assert RemoteControlPacket().encode(RCP_TYPE) == bytes.fromhex("01") + bytes(56)


def test_rcp_frame_type_byte_comes_from_the_caller() -> None:
    assert RemoteControlPacket().encode(0x7E)[0] == 0x7E


def test_motor_golden_decode() -> None:
    assert MotorRecord.decode(MOTOR_A_GOLDEN) == MOTOR_A
    assert MotorRecord.decode(MOTOR_B_GOLDEN) == MOTOR_B


def test_motor_golden_encode_writes_zero_pads() -> None:
    assert MOTOR_A.encode() == MOTOR_A_GOLDEN
    assert MOTOR_B.encode() == MOTOR_B_GOLDEN


def test_motor_decode_ignores_pad_bytes() -> None:
    dirty = bytearray(MOTOR_A_GOLDEN)
    dirty[3] = 0xAA
    dirty[14] = 0xBB
    dirty[15] = 0xCC
    assert MotorRecord.decode(bytes(dirty)) == MOTOR_A


def test_telemetry_golden_decode() -> None:
    packet = TelemetryPacket.decode(TELEMETRY_GOLDEN, TELEMETRY_TYPE)
    assert packet.tick == 0x0102030405060708
    assert packet.motors == (MOTOR_A, MOTOR_B)


def test_telemetry_golden_encode() -> None:
    data = TelemetryPacket(tick=0x0102030405060708, motors=(MOTOR_A, MOTOR_B)).encode(
        TELEMETRY_TYPE
    )
    assert data == TELEMETRY_GOLDEN
    assert len(data) == 275
    assert data[58:250] == bytes(24 * 8)  # unused motor slots
    assert data[250:] == bytes(25)  # trailing "not used" bytes


def test_telemetry_tick_is_unsigned() -> None:
    # Seed 000 table 2 says uint64, seed 001 table II says int64; we read uint64.
    data = bytearray(TELEMETRY_GOLDEN)
    data[1:9] = bytes.fromhex("ffffffffffffffff")
    assert TelemetryPacket.decode(bytes(data), TELEMETRY_TYPE).tick == 2**64 - 1
    data[1:9] = bytes.fromhex("0000000000000080")
    assert TelemetryPacket.decode(bytes(data), TELEMETRY_TYPE).tick == 2**63


def test_telemetry_decode_keeps_only_counted_records() -> None:
    data = bytearray(TELEMETRY_GOLDEN)
    data[9] = 1  # motor count 1: record #1 is still on the wire but not counted
    packet = TelemetryPacket.decode(bytes(data), TELEMETRY_TYPE)
    assert packet.motors == (MOTOR_A,)


def test_telemetry_decode_ignores_unused_bytes() -> None:
    data = bytearray(TELEMETRY_GOLDEN)
    data[58:] = b"\x5a" * (275 - 58)
    packet = TelemetryPacket.decode(bytes(data), TELEMETRY_TYPE)
    assert packet.motors == (MOTOR_A, MOTOR_B)


def test_telemetry_with_no_motors() -> None:
    expected = bytes.fromhex("02" + "2a00000000000000" + "00") + bytes(240 + 25)
    assert TelemetryPacket(tick=42).encode(TELEMETRY_TYPE) == expected
    assert TelemetryPacket.decode(expected, TELEMETRY_TYPE) == TelemetryPacket(tick=42)


def test_video_golden_decode() -> None:
    assert VideoFramePacket.decode(VIDEO_GOLDEN, VIDEO_TYPE) == VideoFramePacket(jpeg=VIDEO_JPEG)


def test_video_golden_encode() -> None:
    assert VideoFramePacket(jpeg=VIDEO_JPEG).encode(VIDEO_TYPE) == VIDEO_GOLDEN


def test_video_largest_jpeg_fits_one_datagram() -> None:
    # A UDP datagram carries at most 65507 bytes: one frame type byte plus 65506 of JPEG.
    jpeg = SOI + bytes(65506 - len(SOI) - len(EOI)) + EOI
    data = VideoFramePacket(jpeg=jpeg).encode(VIDEO_TYPE)
    assert len(data) == 65507
    assert VideoFramePacket.decode(data, VIDEO_TYPE).jpeg == jpeg


# --- round trips --------------------------------------------------------------------------


@given(rcps)
def test_rcp_round_trip(packet: RemoteControlPacket) -> None:
    data = packet.encode(RCP_TYPE)
    assert len(data) == 57
    assert RemoteControlPacket.decode(data, RCP_TYPE) == packet


@given(motor_records)
def test_motor_round_trip(record: MotorRecord) -> None:
    data = record.encode()
    assert len(data) == 24
    assert data[3] == 0
    assert data[14:16] == b"\x00\x00"
    assert MotorRecord.decode(data) == record


@given(telemetry_packets)
def test_telemetry_round_trip(packet: TelemetryPacket) -> None:
    data = packet.encode(TELEMETRY_TYPE)
    assert len(data) == 275
    assert data[9] == len(packet.motors)
    assert TelemetryPacket.decode(data, TELEMETRY_TYPE) == packet


@settings(max_examples=50)
@given(video_packets)
def test_video_round_trip(packet: VideoFramePacket) -> None:
    data = packet.encode(VIDEO_TYPE)
    assert data[0] == VIDEO_TYPE
    assert VideoFramePacket.decode(data, VIDEO_TYPE) == packet


@st.composite
def raw_telemetry(draw: st.DrawFn) -> bytes:
    """Any 275 bytes with the telemetry frame type and a motor count of at most ten."""
    tick = draw(st.binary(min_size=8, max_size=8))
    count = draw(st.integers(0, MOTOR_SLOTS))
    rest = draw(st.binary(min_size=265, max_size=265))
    return bytes((TELEMETRY_TYPE,)) + tick + bytes((count,)) + rest


def _wire_bytes_kept(data: bytes) -> bytes:
    """The datagram with the bytes a decoder must ignore set to zero."""
    count = data[9]
    kept = bytearray(data)
    for slot in range(count):
        base = 10 + 24 * slot
        kept[base + 3] = 0  # pad before position
        kept[base + 14 : base + 16] = b"\x00\x00"  # pad before position command
    kept[10 + 24 * count :] = bytes(275 - (10 + 24 * count))  # unused slots, not-used tail
    return bytes(kept)


@given(raw_telemetry())
def test_raw_telemetry_reencodes_every_meaningful_byte(data: bytes) -> None:
    packet = TelemetryPacket.decode(data, TELEMETRY_TYPE)
    assert len(packet.motors) == data[9]
    assert packet.encode(TELEMETRY_TYPE) == _wire_bytes_kept(data)


# --- malformed input ----------------------------------------------------------------------


def test_protocol_error_is_a_value_error() -> None:
    assert issubclass(ProtocolError, ValueError)


@pytest.mark.parametrize("size", [0, 1, 56, 58])
def test_rcp_wrong_length(size: int) -> None:
    data = (RCP_GOLDEN + b"\x00")[:size]
    with pytest.raises(ProtocolError, match=rf"^RCP packet must be 57 bytes, got {size}$"):
        RemoteControlPacket.decode(data, RCP_TYPE)


def test_rcp_wrong_frame_type() -> None:
    with pytest.raises(ProtocolError, match=r"^frame type 0x02 is not RCP \(0x01\)$"):
        RemoteControlPacket.decode(b"\x02" + RCP_GOLDEN[1:], RCP_TYPE)


@pytest.mark.parametrize("size", [0, 1, 274, 276])
def test_telemetry_wrong_length(size: int) -> None:
    data = (TELEMETRY_GOLDEN + b"\x00")[:size]
    with pytest.raises(ProtocolError, match=rf"^telemetry packet must be 275 bytes, got {size}$"):
        TelemetryPacket.decode(data, TELEMETRY_TYPE)


def test_telemetry_wrong_frame_type() -> None:
    with pytest.raises(ProtocolError, match=r"^frame type 0x01 is not telemetry \(0x02\)$"):
        TelemetryPacket.decode(b"\x01" + TELEMETRY_GOLDEN[1:], TELEMETRY_TYPE)


@pytest.mark.parametrize("count", [11, 255])
def test_telemetry_motor_count_over_ten(count: int) -> None:
    data = bytearray(TELEMETRY_GOLDEN)
    data[9] = count
    with pytest.raises(ProtocolError, match=rf"^telemetry motor count {count} over 10$"):
        TelemetryPacket.decode(bytes(data), TELEMETRY_TYPE)


@pytest.mark.parametrize("size", [0, 23, 25])
def test_motor_record_wrong_length(size: int) -> None:
    with pytest.raises(ProtocolError, match=rf"^motor record must be 24 bytes, got {size}$"):
        MotorRecord.decode((MOTOR_A_GOLDEN + b"\x00")[:size])


def test_video_empty_datagram() -> None:
    with pytest.raises(ProtocolError, match=r"^empty datagram$"):
        VideoFramePacket.decode(b"", VIDEO_TYPE)


def test_video_wrong_frame_type() -> None:
    with pytest.raises(ProtocolError, match=r"^frame type 0x02 is not video \(0x03\)$"):
        VideoFramePacket.decode(b"\x02" + VIDEO_JPEG, VIDEO_TYPE)


@pytest.mark.parametrize(
    "payload",
    [
        b"",
        b"\xff",
        b"\xff\xd8",  # SOI alone, no marker after it
        b"\x89PNG\r\n\x1a\n" + EOI,
        VIDEO_JPEG[1:],
    ],
    ids=["nothing", "one-byte", "bare-soi", "png", "soi-cut"],
)
def test_video_payload_not_jpeg(payload: bytes) -> None:
    with pytest.raises(ProtocolError, match=r"^video payload is not a JPEG \(no SOI marker\)$"):
        VideoFramePacket.decode(b"\x03" + payload, VIDEO_TYPE)
    with pytest.raises(ProtocolError, match=r"no SOI marker"):
        VideoFramePacket(jpeg=payload).encode(VIDEO_TYPE)


@pytest.mark.parametrize(
    "payload",
    [SOI, VIDEO_JPEG[:-1], VIDEO_JPEG[:-2], VIDEO_JPEG + b"\x00"],
    ids=["soi-only", "eoi-half", "eoi-missing", "trailing-byte"],
)
def test_video_truncated_jpeg(payload: bytes) -> None:
    with pytest.raises(
        ProtocolError, match=r"^video payload is a truncated JPEG \(no EOI marker\)$"
    ):
        VideoFramePacket.decode(b"\x03" + payload, VIDEO_TYPE)
    with pytest.raises(ProtocolError, match=r"no EOI marker"):
        VideoFramePacket(jpeg=payload).encode(VIDEO_TYPE)


def test_video_jpeg_too_large_for_one_datagram() -> None:
    jpeg = SOI + bytes(65507 - len(SOI) - len(EOI)) + EOI  # 65507 + frame type byte = 65508
    with pytest.raises(ProtocolError, match=r"^JPEG of 65507 bytes does not fit one datagram$"):
        VideoFramePacket(jpeg=jpeg).encode(VIDEO_TYPE)


def _rcp(axes: dict[int, int] | None = None, buttons: dict[int, int] | None = None) -> bytes:
    axis_values = [0] * 16
    button_values = [0] * 16
    for index, value in (axes or {}).items():
        axis_values[index] = value
    for index, value in (buttons or {}).items():
        button_values[index] = value
    return RemoteControlPacket(axes=tuple(axis_values), buttons=tuple(button_values)).encode(
        RCP_TYPE
    )


@pytest.mark.parametrize(
    ("axes", "buttons", "message"),
    [
        ({0: 32768}, None, r"^axis\[0\]=32768 out of range \[-32768, 32767\]$"),
        ({15: -32769}, None, r"^axis\[15\]=-32769 out of range \[-32768, 32767\]$"),
        (None, {3: 256}, r"^button\[3\]=256 out of range \[0, 255\]$"),
        (None, {0: -1}, r"^button\[0\]=-1 out of range \[0, 255\]$"),
    ],
)
def test_rcp_encode_out_of_range(
    axes: dict[int, int] | None, buttons: dict[int, int] | None, message: str
) -> None:
    with pytest.raises(ProtocolError, match=message):
        _rcp(axes, buttons)


@pytest.mark.parametrize(
    ("axes", "buttons"),
    [((0,) * 15, (0,) * 16), ((0,) * 17, (0,) * 16), ((0,) * 16, (0,) * 15), ((), ())],
)
def test_rcp_encode_wrong_counts(axes: tuple[int, ...], buttons: tuple[int, ...]) -> None:
    packet = RemoteControlPacket(axes=axes, buttons=buttons)
    with pytest.raises(
        ProtocolError,
        match=rf"^RCP needs 16 axes and 16 buttons, got {len(axes)} and {len(buttons)}$",
    ):
        packet.encode(RCP_TYPE)


@pytest.mark.parametrize(
    ("field", "value", "bounds"),
    [
        ("device_id", 256, r"\[0, 255\]"),
        ("state", -1, r"\[0, 255\]"),
        ("mode", 256, r"\[0, 255\]"),
        ("position", 2**32, r"\[0, 4294967295\]"),
        ("position", -1, r"\[0, 4294967295\]"),
        ("speed", 32768, r"\[-32768, 32767\]"),
        ("current", -32769, r"\[-32768, 32767\]"),
        ("status", 32768, r"\[-32768, 32767\]"),
        ("position_command", 2**32, r"\[0, 4294967295\]"),
        ("speed_command", -32769, r"\[-32768, 32767\]"),
        ("current_command", 32768, r"\[-32768, 32767\]"),
    ],
)
def test_motor_encode_out_of_range(field: str, value: int, bounds: str) -> None:
    record = MotorRecord(**{field: value})
    with pytest.raises(ProtocolError, match=rf"^motor\.{field}={value} out of range {bounds}$"):
        record.encode()
    with pytest.raises(ProtocolError, match=rf"^motor\.{field}="):
        TelemetryPacket(motors=(record,)).encode(TELEMETRY_TYPE)


@pytest.mark.parametrize("tick", [-1, 2**64])
def test_telemetry_encode_tick_out_of_range(tick: int) -> None:
    with pytest.raises(ProtocolError, match=rf"^tick={tick} out of range \[0, {2**64 - 1}\]$"):
        TelemetryPacket(tick=tick).encode(TELEMETRY_TYPE)


def test_telemetry_encode_eleven_motors() -> None:
    packet = TelemetryPacket(motors=(MOTOR_A,) * 11)
    with pytest.raises(ProtocolError, match=r"^motor count 11 over 10$"):
        packet.encode(TELEMETRY_TYPE)
