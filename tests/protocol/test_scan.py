"""The extension's range scan and the status packet's version 2 (the IMU heading)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ocu.protocol import ProtocolError
from ocu.protocol.extended import (
    SCAN_INVALID,
    SCAN_NO_RETURN,
    ExtendedCodec,
    ScanPacket,
    StatusPacket,
)
from ocu.protocol.mapping import scan_frame
from ocu.records import StatusFrame

CODEC = ExtendedCodec(hello_type=0x10, fragment_type=0x11, status_type=0x12, scan_type=0x13)

SCAN = ScanPacket(
    sequence=5,
    capture_time_us=2_000_000,
    angle_min_urad=-3_141_593,
    angle_increment_urad=1_570_796,
    range_min_mm=50,
    range_max_mm=8000,
    ranges_mm=(1000, SCAN_NO_RETURN, SCAN_INVALID, 7999),
)
# type, magic, version, sequence, capture µs, angle min, increment, min mm, max mm, count,
# then four u16 ranges.
SCAN_BYTES = bytes.fromhex(
    "13 4f435558 01 05000000 80841e0000000000 2710d0ff ecf71700 3200 401f 0400e803 0000 ffff 3f1f"
)
STATUS_V2 = StatusPacket(sequence=7, voltage_mv=24100, camera_count=4, yaw_mrad=-1571)
STATUS_V2_BYTES = bytes.fromhex("12 4f435558 02 07000000 245e ffff ff 0080 0080 04 ddf9")


def test_scan_golden_bytes_both_ways() -> None:
    assert CODEC.encode(SCAN) == SCAN_BYTES
    assert CODEC.decode(SCAN_BYTES) == SCAN


def test_status_version_2_carries_the_heading_and_version_1_still_decodes() -> None:
    assert CODEC.encode(STATUS_V2) == STATUS_V2_BYTES
    assert CODEC.decode(STATUS_V2_BYTES) == STATUS_V2
    # Without a heading the robot sends version 1, as before.
    v1 = CODEC.encode(StatusPacket(sequence=7))
    assert len(v1) == 20
    assert v1[5] == 1
    decoded = CODEC.decode(v1)
    assert isinstance(decoded, StatusPacket)
    assert decoded.yaw_mrad is None
    frame = StatusFrame(STATUS_V2, 0.0, 0.0)
    assert frame.yaw_rad == pytest.approx(-1.571)


def test_a_scan_in_si_units() -> None:
    frame = scan_frame(SCAN, received_at=1.0, wall_time=2.0)
    assert frame.angle_min_rad == pytest.approx(-math.pi, abs=1e-6)
    assert frame.angle_increment_rad == pytest.approx(math.pi / 2, abs=1e-6)
    assert frame.ranges_m[0] == 1.0
    assert math.isinf(frame.ranges_m[1])
    assert math.isnan(frame.ranges_m[2])
    assert (frame.range_min_m, frame.range_max_m) == (0.05, 8.0)


@pytest.mark.parametrize(
    ("wire", "message"),
    [
        (SCAN_BYTES[:31], r"^scan packet needs 32 bytes, got 31$"),
        (SCAN_BYTES[:-1], r"^scan packet with 4 beams must be 40 bytes, got 39$"),
        (SCAN_BYTES[:5] + b"\x02" + SCAN_BYTES[6:], r"^scan version 2 not supported"),
        (SCAN_BYTES[:32] + b"\x28\x00" + SCAN_BYTES[34:], r"range #0=40 mm outside \[50, 8000\]"),
        (SCAN_BYTES[:22] + b"\x00\x00\x00\x00" + SCAN_BYTES[26:], r"angle_increment_urad is 0"),
        (SCAN_BYTES[:30] + b"\x00\x00", r"^scan packet: scan beam count 0 outside"),
        (STATUS_V2_BYTES[:-1], r"^status packet must be 22 bytes, got 21$"),
        (STATUS_V2_BYTES[:1] + b"ABCD" + STATUS_V2_BYTES[5:], r"^status magic b'ABCD'"),
    ],
)
def test_malformed_scans_and_statuses(wire: bytes, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        CODEC.decode(wire)


def test_a_codec_without_a_scan_type_knows_no_scan() -> None:
    older = ExtendedCodec(0x10, 0x11, 0x12, None)
    assert not older.handles(0x13)
    with pytest.raises(ProtocolError, match="not an extension packet"):
        older.decode(SCAN_BYTES)
    with pytest.raises(ProtocolError, match="no scan packet type"):
        older.encode(SCAN)


@settings(max_examples=200, deadline=None)
@given(ranges=st.lists(st.integers(0, 0xFFFF), min_size=1, max_size=400))
def test_any_scan_round_trips_or_is_refused(ranges: list[int]) -> None:
    packet = ScanPacket(1, 2, -3_141_593, 17_453, 0, 0xFFFE, tuple(ranges))
    try:
        wire = CODEC.encode(packet)
    except ProtocolError:
        return
    assert CODEC.decode(wire) == packet
