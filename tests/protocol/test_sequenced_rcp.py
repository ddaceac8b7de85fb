"""The extension's sequenced RCP: golden bytes, round trip, malformed input, wrapping order."""

from __future__ import annotations

import struct

import pytest

from ocu.protocol import ProtocolError, RemoteControlPacket
from ocu.protocol.extended import SEQUENCED_RCP_SIZE, ExtendedCodec, SequencedRcp, sequence_newer

RCP_TYPE = 0x14
AXES = (1000, -2000) + (0,) * 14
BUTTONS = (1,) + (0,) * 15
PACKET = SequencedRcp(0x01020304, RemoteControlPacket(AXES, BUTTONS, 500000.0))


def golden() -> bytes:
    return (
        bytes((RCP_TYPE,))
        + b"OCUX"
        + bytes((1,))
        + bytes((0x04, 0x03, 0x02, 0x01))
        + struct.pack("<16h", *AXES)
        + bytes(BUTTONS)
        + struct.pack("<d", 500000.0)
    )


def test_golden_bytes_and_round_trip() -> None:
    data = PACKET.encode(RCP_TYPE)
    assert data == golden()
    assert len(data) == SEQUENCED_RCP_SIZE == 66
    assert SequencedRcp.decode(data, RCP_TYPE) == PACKET
    codec = ExtendedCodec()
    assert codec.handles(RCP_TYPE)
    assert codec.encode(PACKET) == data
    assert codec.decode(data) == PACKET


def test_the_body_is_the_vendor_rcp_after_its_frame_type() -> None:
    vendor = PACKET.rcp.encode(0x01)
    assert PACKET.encode(RCP_TYPE)[10:] == vendor[1:]


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (golden()[:-1], r"^sequenced RCP must be 66 bytes, got 65$"),
        (golden() + b"\0", r"^sequenced RCP must be 66 bytes, got 67$"),
        (b"\x15" + golden()[1:], r"^frame type 0x15 is not a sequenced RCP \(0x14\)$"),
        (golden()[:1] + b"OCUY" + golden()[5:], r"^sequenced RCP magic b'OCUY' is not b'OCUX'$"),
        (golden()[:5] + b"\x02" + golden()[6:], r"^sequenced RCP version 2 not supported"),
    ],
    ids=["short", "long", "type", "magic", "version"],
)
def test_malformed_sequenced_rcps_are_refused(data: bytes, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        SequencedRcp.decode(data, RCP_TYPE)


def test_a_sequence_out_of_range_is_refused() -> None:
    with pytest.raises(ProtocolError, match=r"^sequence=4294967296 out of range"):
        SequencedRcp(2**32, RemoteControlPacket()).encode(RCP_TYPE)


def test_an_extension_without_the_type_sends_no_sequenced_rcp() -> None:
    codec = ExtendedCodec(rcp_type=None)
    assert not codec.handles(RCP_TYPE)
    with pytest.raises(ProtocolError, match="no sequenced RCP type"):
        codec.encode(PACKET)


@pytest.mark.parametrize(
    ("sequence", "than", "newer"),
    [
        (1, 0, True),
        (0, 1, False),
        (5, 5, False),
        (0, 2**32 - 1, True),  # wrapped
        (2**32 - 1, 0, False),
        (2**31 - 1, 0, True),
        (2**31, 0, False),  # half the circle away: not newer
    ],
)
def test_sequence_order_wraps(sequence: int, than: int, newer: bool) -> None:
    assert sequence_newer(sequence, than) is newer
