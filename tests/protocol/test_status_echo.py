"""Status version 3: the robot's echo of the sequenced RCPs it applied (golden bytes)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from ocu.protocol import ProtocolError
from ocu.protocol.extended import ExtendedCodec, StatusPacket

CODEC = ExtendedCodec(hello_type=0x10, fragment_type=0x11, status_type=0x12)
STATUS = StatusPacket(
    sequence=7,
    voltage_mv=24100,
    charge_permille=635,
    headlight_on=True,
    roll_mrad=-52,
    pitch_mrad=105,
    camera_count=4,
    yaw_mrad=-1571,
    rcp_sequence=0xFFFFFFFE,
    rcp_received=0x01020304,
)
V1_FIELDS = "4f435558 03 07000000 245e 7b02 01 ccff 6900 04"
STATUS_BYTES = bytes.fromhex("12" + V1_FIELDS + "ddf9" + "feffffff" + "04030201")


def test_golden_bytes_both_ways() -> None:
    assert len(STATUS_BYTES) == 30
    assert CODEC.encode(STATUS) == STATUS_BYTES
    assert CODEC.decode(STATUS_BYTES) == STATUS


def test_an_echo_without_a_heading_says_the_heading_is_unknown() -> None:
    packet = replace(STATUS, yaw_mrad=None)
    wire = CODEC.encode(packet)
    assert wire[20:22] == bytes.fromhex("0080")
    assert CODEC.decode(wire) == packet


def test_no_echo_keeps_the_older_versions() -> None:
    assert len(CODEC.encode(replace(STATUS, rcp_sequence=None, rcp_received=None))) == 22
    plain = replace(STATUS, yaw_mrad=None, rcp_sequence=None, rcp_received=None)
    assert len(CODEC.encode(plain)) == 20


def test_half_an_echo_is_refused() -> None:
    with pytest.raises(ProtocolError, match=r"^the RCP echo needs both"):
        CODEC.encode(replace(STATUS, rcp_received=None))
    with pytest.raises(ProtocolError, match=r"^rcp_received=4294967296 out of range"):
        CODEC.encode(replace(STATUS, rcp_received=2**32))


@pytest.mark.parametrize(
    ("wire", "message"),
    [
        (STATUS_BYTES[:-1], r"^status packet must be 30 bytes, got 29$"),
        (STATUS_BYTES[:22], r"^status packet must be 30 bytes, got 22$"),
        (STATUS_BYTES[:1] + b"OCUY" + STATUS_BYTES[5:], r"^status magic b'OCUY' is not"),
    ],
)
def test_malformed_version_3(wire: bytes, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        CODEC.decode(wire)
