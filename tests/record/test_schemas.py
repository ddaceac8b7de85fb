"""Message definitions: every one encodes and decodes with mcap-ros2-support's public reader."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory

from ocu.record import schemas as s

REPO_ROOT = Path(__file__).resolve().parents[2]


def _round_trip(message_type: s.MessageType, message: dict[str, object]) -> object:
    data = s.make_encoder(message_type)(message)
    schema = Schema(
        id=1,
        name=message_type.name,
        encoding=s.SCHEMA_ENCODING,
        data=message_type.definition.encode(),
    )
    decoder = DecoderFactory().decoder_for(s.MESSAGE_ENCODING, schema)
    assert decoder is not None
    return decoder(data)


def test_twist_is_the_ros_layout() -> None:
    decoded = _round_trip(s.TWIST, {"linear": {"x": 0.3}, "angular": {"z": -0.5}})
    assert (decoded.linear.x, decoded.linear.y, decoded.angular.z) == (0.3, 0.0, -0.5)  # type: ignore[attr-defined]
    # 4-byte CDR header and six float64, as any ROS 2 node sends it.
    assert len(s.make_encoder(s.TWIST)({})) == 4 + 6 * 8


def test_raw_packet_keeps_bytes_and_both_stamps() -> None:
    data = bytes(range(256)) * 3
    decoded = _round_trip(
        s.RAW_PACKET,
        {
            "send_stamp": s.stamp(1_500_000_001),
            "receive_stamp": s.stamp(2_000_000_002),
            "source": s.SOURCE_ROBOT,
            "data": data,
        },
    )
    assert bytes(decoded.data) == data  # type: ignore[attr-defined]
    assert s.stamp_ns(decoded.send_stamp) == 1_500_000_001  # type: ignore[attr-defined]
    assert s.stamp_ns(decoded.receive_stamp) == 2_000_000_002  # type: ignore[attr-defined]
    assert decoded.source == "robot"  # type: ignore[attr-defined]


@pytest.mark.parametrize("message_type", s.MESSAGE_TYPES, ids=lambda t: t.name)
def test_every_type_round_trips_its_defaults(message_type: s.MessageType) -> None:
    assert _round_trip(message_type, {}) is not None


def test_unknown_values_are_nan() -> None:
    assert math.isnan(s.nan_if_none(None))
    assert s.none_if_nan(math.nan) is None
    assert s.none_if_nan(s.nan_if_none(0.25)) == 0.25
    assert s.stamp(-5) == {"sec": 0, "nanosec": 0}


_CHECK = """
import sys
import ocu.record, ocu.record.inspect, ocu.record.replay_link, ocu.record.reader
qt = sorted(n for n in sys.modules if n.split(".")[0] in ("PySide6", "shiboken6", "pyqtgraph"))
print(",".join(qt))
"""


def test_recording_core_imports_no_qt() -> None:
    result = subprocess.run(
        [sys.executable, "-c", _CHECK],
        capture_output=True,
        text=True,
        check=False,
        timeout=60,
        cwd=REPO_ROOT,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == ""
