"""`ocu probe`: what arrives, judged against the profile, in sentences; only zeros sent."""

from __future__ import annotations

import io
import socket
import struct
from collections.abc import Iterator
from contextlib import redirect_stdout

import pytest

from ocu.calibrate.cli import probe_main
from ocu.calibrate.observer import TelemetryLog
from ocu.calibrate.probe import MISMATCH, judge
from ocu.link.receiver import Receiver
from ocu.profile import RobotProfile, load_profile_data, parse_profile
from ocu.protocol import MotorRecord, TelemetryPacket, VideoFramePacket
from ocu.protocol.wire import make_codec
from ocu.sim.scramble import scramble_profile_data
from ocu.sim.simulator import RobotSimulator

JPEG = b"\xff\xd8\xff\xe0" + bytes(40) + b"\xff\xd9"


@pytest.fixture
def sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    simulator = RobotSimulator(profile, telemetry_hz=10.0, video_fps=5.0)
    simulator.start()
    yield simulator
    simulator.stop()


def probe(address: tuple[str, int], *extra: str) -> tuple[int, str]:
    out = io.StringIO()
    with redirect_stdout(out):
        code = probe_main(["--robot", f"{address[0]}:{address[1]}", "--seconds", "1.2", *extra])
    return code, out.getvalue()


def test_a_robot_that_matches_the_profile_passes_and_only_zeros_are_sent(
    sim: RobotSimulator,
) -> None:
    code, text = probe(sim.address)
    assert code == 0, text
    assert "Everything that arrived matches the profile." in text
    assert "telemetry packet(s): type 0x02, 275 bytes, parse" in text
    assert "video frame(s) of type 0x03" in text
    received = sim.received_commands()
    assert len(received) >= 5
    assert all(not any(r.packet.axes) for r in received)
    assert sim.state().foreign_count == 0  # no extension hellos either


def test_an_unknown_robot_fails_and_says_which_keys(profile: RobotProfile) -> None:
    truth = parse_profile(scramble_profile_data(load_profile_data(), 3))
    with RobotSimulator(truth, telemetry_hz=10.0, video_fps=0.0) as sim:
        code, text = probe(sim.address)
    assert code == 1
    assert "contradiction(s) with the profile" in text
    assert "motors.shoulder.zero_offset_ticks (2147483648)" in text
    assert "an assumption" in text
    assert "`ocu calibrate` measures both" in text


def test_silence_is_reported_with_what_to_check() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as quiet:
        quiet.bind(("127.0.0.1", 0))
        code, text = probe(quiet.getsockname())
    assert code == 1
    assert "Nothing arrived in 1.2 s" in text
    assert "link.port = 10000, an assumption" in text


def judged(
    profile: RobotProfile, datagrams: list[bytes], *, commanded_motion: bool = False
) -> list[str]:
    """The contradictions found in datagrams that went through the one receiver, 0.1 s
    apart."""
    log = TelemetryLog(profile.link.telemetry_tick_hz)
    receiver = Receiver(profile, log)
    for index, data in enumerate(datagrams):
        receiver.received(data, 100.0 + 0.1 * index, 0.0)
    findings = judge(profile, log, 2.0, foreign=0, commanded_motion=commanded_motion)
    return [f.text for f in findings if f.level == MISMATCH]


def telemetry(profile: RobotProfile, tick: int, **changes: int) -> bytes:
    records = [
        MotorRecord(device_id=m.device_id, position=m.zero_offset_ticks if m.has_position else 0)
        for m in profile.motors.values()
    ]
    if changes:
        records[4] = MotorRecord(**{"device_id": records[4].device_id, **changes})
    return make_codec(profile).encode(TelemetryPacket(tick=tick, motors=tuple(records)))


def test_contradictions_are_explained(profile: RobotProfile) -> None:
    good = [telemetry(profile, 100 * k) for k in range(1, 6)]
    assert judged(profile, good) == []

    # One byte too many: the layout, not the type, is wrong.
    long = [data + b"\x00" for data in good]
    texts = judged(profile, long)
    assert texts == [
        "Telemetry (type 0x02) arrives as 276 bytes, one more than the tables (275): check "
        "the pad layout of the motor record (docs/protocol.md, alignment layout, an "
        "assumption).",
        "No telemetry packet could be decoded.",
    ]

    # Another first byte at the telemetry's size: the frame type is the assumption to fix.
    retyped = [b"\x05" + data[1:] for data in good]
    texts = judged(profile, retyped)
    assert any("the telemetry frame type may be 0x05" in t for t in texts)

    # JPEGs behind another first byte.
    video = make_codec(profile).encode(VideoFramePacket(JPEG))
    texts = judged(profile, [*good, b"\x07" + video[1:]])
    assert any("the video frame type may be 0x07" in t for t in texts)

    # A tick written big-endian reads as an uptime of millennia.
    swapped = [data[:1] + struct.pack(">Q", 100 * k) + data[9:] for k, data in enumerate(good, 1)]
    assert any("byte order may be big-endian" in t for t in judged(profile, swapped))

    # A shoulder that moves while every axis is zero, and a device nobody knows.
    moving = [telemetry(profile, 100 * k, speed=300) for k in range(1, 6)]
    assert any("speed of 0.300" in t for t in judged(profile, moving))
    # ... unless the OCU commanded motion meanwhile (the console's Robot check).
    assert not [t for t in judged(profile, moving, commanded_motion=True) if "speed" in t]
    stranger = [telemetry(profile, 100 * k, device_id=42) for k in range(1, 6)]
    texts = judged(profile, stranger)
    assert any("Device 42 reports" in t for t in texts)
    assert any("never reports" in t for t in texts)
