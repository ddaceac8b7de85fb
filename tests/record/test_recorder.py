"""The recorder against the real simulator and real files, read back with mcap's readers."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zstandard
from mcap.exceptions import EndOfFile
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk
from mcap_ros2.decoder import DecoderFactory

from ocu.link.live import UdpLink
from ocu.profile import RobotProfile
from ocu.protocol import TelemetryPacket
from ocu.protocol.mapping import read_telemetry
from ocu.protocol.wire import make_codec
from ocu.record import schemas as s
from ocu.record.errors import RecordingError
from ocu.record.inspect import main as inspect_main
from ocu.record.reader import Recording
from ocu.record.recorder import Recorder
from ocu.records import CameraRequest, Command, DatagramSent, LinkEvent, SafetyEvent, TelemetryFrame
from ocu.sim.simulator import RobotSimulator
from tests.record.helpers import Collector, assert_monotonic, poll_until, read_finished

REPO_ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def vendor_sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """The vendor-protocol simulator with light video."""
    sim = RobotSimulator(profile, telemetry_hz=20.0, video_fps=10.0, video_size=(160, 120))
    sim.start()
    yield sim
    sim.stop()


def test_session_is_in_the_file_raw_and_decoded(
    profile: RobotProfile, vendor_sim: RobotSimulator, tmp_path: Path
) -> None:
    collector = Collector()
    recorder = Recorder(profile)
    link = UdpLink(profile, vendor_sim.address, listener=collector, gui_alive_timeout_s=None)
    recorder.attach(link)
    path = tmp_path / "session.mcap"
    wall_before = time.time_ns()
    recorder.start(path)
    link.start()
    try:
        assert collector.wait(
            lambda: len(collector.telemetry) >= 5 and bool(collector.video and collector.stats)
        )
        link.set_command(
            Command(velocities={"drive_linear": 0.3, "drive_turn": -0.5, "waist": 0.2}, camera=1)
        )
        assert collector.wait(lambda: any(f.camera == 1 for f in collector.video))
        link.emergency_stop("test")
        assert collector.wait(lambda: len(collector.safety) > 0)
    finally:
        link.shutdown()
    stats = recorder.stop()
    wall_after = time.time_ns()
    assert stats.error is None
    assert stats.dropped == 0
    assert stats.messages_written > 0

    topics, summary = read_finished(path)
    assert summary is not None, "a stopped recording has its summary and footer"
    assert_monotonic(topics)
    for messages in topics.values():
        for message in messages:
            assert wall_before <= message.log_time <= wall_after

    # Every datagram, byte for byte, in order, on its raw channel, with its stamps.
    types = profile.link.frame_types
    rcps = topics[s.RAW_RCP]
    assert [bytes(m.decoded.data) for m in rcps] == collector.sent
    for message in rcps:
        assert message.decoded.source == s.SOURCE_OCU
        assert s.stamp_ns(message.decoded.send_stamp) == message.log_time
        assert s.stamp_ns(message.decoded.receive_stamp) == 0
    telemetry = topics[s.RAW_TELEMETRY]
    assert [bytes(m.decoded.data) for m in telemetry] == [
        d for d in collector.received if d[0] == types.telemetry
    ]
    tick_ns = 1e9 / profile.link.telemetry_tick_hz
    for message in telemetry:
        tick = TelemetryPacket.decode(bytes(message.decoded.data), types.telemetry).tick
        assert message.decoded.source == s.SOURCE_ROBOT
        assert s.stamp_ns(message.decoded.receive_stamp) == message.log_time
        assert s.stamp_ns(message.decoded.send_stamp) == round(tick * tick_ns)
        assert message.publish_time == round(tick * tick_ns)
    assert [bytes(m.decoded.data) for m in topics[s.RAW_VIDEO]] == [
        d for d in collector.received if d[0] == types.video
    ]

    # Decoded: joint states in radians as the link read them.
    joints = topics[s.JOINT_STATES]
    assert len(joints) == len(collector.telemetry)
    for message, frame in zip(joints, collector.telemetry, strict=True):
        positioned = {n: r for n, r in frame.readings.items() if r.angle_rad is not None}
        assert list(message.decoded.name) == list(positioned)
        assert list(message.decoded.position) == [r.angle_rad for r in positioned.values()]
        assert list(message.decoded.velocity) == [r.speed_rad_s for r in positioned.values()]
        assert list(message.decoded.effort) == [r.current_a for r in positioned.values()]
    # Commanded velocities as Twist: the SI values the RCP carried (axis rounding only).
    twists = [(m.decoded.linear.x, m.decoded.angular.z) for m in topics[s.CMD_VEL]]
    assert len(twists) == len(rcps)
    assert any(
        math.isclose(x, 0.3, abs_tol=1e-4) and math.isclose(z, -0.5, abs_tol=1e-4)
        for x, z in twists
    )
    assert twists[-1] == (0.0, 0.0)
    joint_commands = topics[s.CMD_JOINTS]
    assert any(
        math.isclose(
            dict(zip(m.decoded.name, m.decoded.velocity, strict=True))["waist"], 0.2, abs_tol=1e-4
        )
        for m in joint_commands
    )
    # Camera frames per camera: a vendor frame goes to the camera the OCU selected.
    names = profile.link.camera_names
    by_camera = {
        name: [bytes(m.decoded.data) for m in topics.get(s.camera_topic(name), [])]
        for name in names
    }
    assert sum(len(v) for v in by_camera.values()) == len(collector.video)
    assert by_camera[names[1]] == [f.jpeg for f in collector.video if f.camera == 1]
    for message in topics[s.camera_topic(names[1])]:
        assert message.decoded.format == "jpeg"
        assert message.decoded.header.frame_id == names[1]
    # Link statistics and events.
    assert topics[s.LINK_STATS], "stats are recorded every 0.5 s"
    assert topics[s.LINK_STATS][-1].decoded.link_state == "connected"
    events = [(m.decoded.kind, m.decoded.state, m.decoded.message) for m in topics[s.EVENTS]]
    assert events[0][:2] == (s.EVENT_RECORDING, "started")
    assert (s.EVENT_SAFETY, "", "EMERGENCY STOP (test)") in events
    assert (s.EVENT_LINK_STATE, "connected") in [e[:2] for e in events]
    assert events[-2][:2] == (s.EVENT_LINK_STATE, "closed")
    assert events[-1][:2] == (s.EVENT_RECORDING, "stopped")

    # The recording carries its profile and its clock anchor.
    with Recording(path) as recording:
        assert not recording.truncated
        assert recording.profile().link == profile.link
        assert int(recording.metadata["wall_anchor_ns"]) > 0


def test_extended_session_records_fragments_status_and_every_camera(
    profile: RobotProfile, tmp_path: Path
) -> None:
    sim = RobotSimulator(profile, telemetry_hz=10.0, video_fps=0.0, extended=True, status_hz=10.0)
    sim.start()
    collector = Collector()
    recorder = Recorder(profile)
    link = UdpLink(
        profile, sim.address, listener=collector, gui_alive_timeout_s=None, extension=True
    )
    recorder.attach(link)
    path = tmp_path / "extended.mcap"
    recorder.start(path)
    cameras = range(len(profile.link.camera_names))
    link.set_stream_request([CameraRequest(c, 160, 120, 10) for c in cameras])
    link.start()
    try:
        assert collector.wait(
            lambda: (
                {f.camera for f in collector.video} == set(cameras) and len(collector.status) >= 3
            )
        )
    finally:
        link.shutdown()
        sim.stop()
    recorder.stop()

    topics, _ = read_finished(path)
    assert_monotonic(topics)
    ext = profile.extension
    assert ext is not None
    fragments = [d for d in collector.received if d[0] == ext.frame_types.video_fragment]
    assert [bytes(m.decoded.data) for m in topics[s.RAW_VIDEO_FRAGMENT]] == fragments
    assert [bytes(m.decoded.data) for m in topics[s.RAW_HELLO]] == [
        d for d in collector.sent if d[0] == ext.frame_types.hello
    ]
    assert len(topics[s.RAW_STATUS]) == len(topics[s.ROBOT_STATUS]) == len(collector.status)
    first_status = topics[s.ROBOT_STATUS][0].decoded
    assert math.isclose(first_status.voltage_v, collector.status[0].voltage_v or math.nan)
    for camera in cameras:
        frames = [f for f in collector.video if f.camera == camera]
        images = topics[s.camera_topic(profile.link.camera_names[camera])]
        assert [bytes(m.decoded.data) for m in images] == [f.jpeg for f in frames]
        # publish_time is the robot's capture time (its own clock), as the packet says.
        assert [m.publish_time for m in images] == [(f.capture_time_us or 0) * 1000 for f in frames]
    events = [(m.decoded.kind, m.decoded.state) for m in topics[s.EVENTS]]
    assert (s.EVENT_EXTENSION, "active") in events


@pytest.mark.parametrize(
    ("target", "reason"),
    [
        ("missing/dir/x.mcap", "No such file or directory"),
        (".", "Is a directory"),
        ("/dev/full", "No space left on device"),
    ],
)
def test_unwritable_target_is_a_clear_error(
    profile: RobotProfile, tmp_path: Path, target: str, reason: str
) -> None:
    recorder = Recorder(profile)
    path = Path(target) if target.startswith("/") else tmp_path / target
    with pytest.raises(RecordingError, match=f"cannot record to .*{reason}"):
        recorder.start(path)
    assert not recorder.recording
    # The recorder stays usable.
    good = tmp_path / "good.mcap"
    recorder.start(good)
    recorder.stop()
    with Recording(good) as recording:
        assert not recording.truncated


def test_too_little_free_space_is_refused_before_writing(
    profile: RobotProfile, tmp_path: Path
) -> None:
    recorder = Recorder(profile, min_free_bytes=2**62)
    with pytest.raises(RecordingError, match=r"only [0-9.]+ MB free"):
        recorder.start(tmp_path / "x.mcap")
    assert not (tmp_path / "x.mcap").exists()


def test_full_queue_drops_and_counts_and_the_link_goes_on(
    profile: RobotProfile, vendor_sim: RobotSimulator, tmp_path: Path
) -> None:
    collector = Collector()
    recorder = Recorder(profile, max_queue_bytes=1)
    link = UdpLink(profile, vendor_sim.address, listener=collector, gui_alive_timeout_s=None)
    recorder.attach(link)
    recorder.start(tmp_path / "dropped.mcap")
    link.start()
    try:
        assert collector.wait(lambda: len(collector.telemetry) >= 5)
    finally:
        link.shutdown()
    stats = recorder.stop()
    assert stats.dropped >= len(collector.sent) + len(collector.received) + 5
    assert stats.messages_written == 0
    with Recording(tmp_path / "dropped.mcap") as recording:
        assert not recording.truncated
        assert list(recording.messages()) == []


def test_start_stop_are_safe_to_repeat(profile: RobotProfile, tmp_path: Path) -> None:
    recorder = Recorder(profile)
    recorder.start(tmp_path / "a.mcap")
    with pytest.raises(RecordingError, match="already recording"):
        recorder.start(tmp_path / "b.mcap")
    first = recorder.stop()
    assert recorder.stop() == first
    recorder.start(tmp_path / "b.mcap")
    recorder.stop()
    for name in ("a.mcap", "b.mcap"):
        with Recording(tmp_path / name) as recording:
            assert not recording.truncated
            events = [recording.decode(m).state for m in recording.messages([s.EVENTS])]
            assert events == ["started", "stopped"]


def test_a_failing_listener_spares_the_others(profile: RobotProfile) -> None:
    def failing(event: LinkEvent) -> None:
        raise RuntimeError("listener bug")

    collector = Collector()
    link = UdpLink(profile, ("127.0.0.1", 9), listener=failing)
    try:
        link.subscribe(collector)
        packet = TelemetryPacket(tick=1)
        frame = TelemetryFrame(packet, read_telemetry(profile, packet), 0.0, 0.0)
        link.emit(frame)
        link.emit(DatagramSent(b"\x01", 0.0))
        assert collector.telemetry == [frame]
        assert collector.sent == [b"\x01"]
    finally:
        link.shutdown()


def test_attach_subscribes_and_detach_leaves(profile: RobotProfile, tmp_path: Path) -> None:
    link = UdpLink(profile, ("127.0.0.1", 9))
    recorder = Recorder(profile)
    try:
        recorder.attach(link)
        recorder.start(tmp_path / "a.mcap")
        link.emit(SafetyEvent("recorded"))
        recorder.detach(link)
        link.emit(SafetyEvent("not recorded"))
        recorder.stop()
    finally:
        link.shutdown()
    with Recording(tmp_path / "a.mcap") as recording:
        messages = [recording.decode(m).message for m in recording.messages([s.EVENTS])]
    assert "recorded" in messages
    assert "not recorded" not in messages


def _run_session(path: Path, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "tests.record.record_session", str(path), *args],
        cwd=REPO_ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )


def test_file_of_a_killed_recorder_opens_up_to_its_last_complete_chunk(
    profile: RobotProfile, tmp_path: Path
) -> None:
    path = tmp_path / "killed.mcap"
    process = _run_session(path, "--until-killed")
    try:
        assert process.stdout is not None
        assert process.stdout.readline().strip() == "recording"
        assert poll_until(lambda: path.exists() and path.stat().st_size >= 256 * 1024)
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
        if process.stdout is not None:
            process.stdout.close()
    assert process.returncode == -signal.SIGKILL

    # mcap's non-seeking reader: every record up to where the writer was cut off.
    chunks = messages = 0
    channels: dict[int, Channel] = {}
    schemas: dict[int, Schema] = {}
    decoders = DecoderFactory()
    last_time: dict[str, int] = {}
    with path.open("rb") as f:
        records = StreamReader(f, emit_chunks=True, validate_crcs=True).records
        try:
            for record in records:
                if not isinstance(record, Chunk):
                    continue
                inner = breakup_chunk(record, validate_crc=True)
                chunks += 1
                for item in inner:
                    if isinstance(item, Schema):
                        schemas[item.id] = item
                    elif isinstance(item, Channel):
                        channels[item.id] = item
                    elif isinstance(item, Message):
                        channel = channels[item.channel_id]
                        decoder = decoders.decoder_for(
                            channel.message_encoding, schemas[channel.schema_id]
                        )
                        assert decoder is not None
                        decoder(item.data)
                        assert item.log_time >= last_time.get(channel.topic, 0)
                        last_time[channel.topic] = item.log_time
                        messages += 1
        except (EndOfFile, zstandard.ZstdError, CRCValidationError):
            pass  # the chunk being written when the process died
    assert chunks >= 3
    assert {s.RAW_RCP, s.RAW_TELEMETRY, s.JOINT_STATES, s.CMD_VEL} <= set(last_time)

    with Recording(path) as recording:
        assert recording.truncated
        assert len(recording.chunks) == chunks
        assert sum(1 for _ in recording.messages()) == messages
    assert inspect_main([str(path)]) == 0


def test_write_error_stops_the_recording_and_the_link_goes_on(tmp_path: Path) -> None:
    path = tmp_path / "limited.mcap"
    limit = 200 * 1024
    process = _run_session(path, "--file-size-limit", str(limit))
    try:
        out, _ = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 0, out
    report = json.loads(out.strip().splitlines()[-1])
    assert "File too large" in report["error"]
    assert "readable up to its last complete chunk" in report["error"]
    assert report["recording"] is False
    assert report["commands_flow_after_error"] is True
    assert report["stats_error"] == report["error"]
    assert os.path.getsize(path) <= limit
    with Recording(path) as recording:
        assert recording.truncated
        assert len(recording.chunks) >= 1
        assert any(True for _ in recording.messages([s.RAW_RCP]))


def test_telemetry_frames_decode_the_same_from_the_raw_channel(
    profile: RobotProfile, vendor_sim: RobotSimulator, tmp_path: Path
) -> None:
    # The raw bytes stored are enough to rebuild what the link decoded (replay relies on it).
    collector = Collector()
    recorder = Recorder(profile)
    link = UdpLink(profile, vendor_sim.address, listener=collector, gui_alive_timeout_s=None)
    recorder.attach(link)
    recorder.start(tmp_path / "t.mcap")
    link.start()
    try:
        assert collector.wait(lambda: len(collector.telemetry) >= 5)
    finally:
        link.shutdown()
    recorder.stop()
    codec = make_codec(profile)
    with Recording(tmp_path / "t.mcap") as recording:
        rebuilt = [
            codec.decode(bytes(recording.decode(m).data))
            for m in recording.messages([s.RAW_TELEMETRY])
        ]
    assert rebuilt == [f.packet for f in collector.telemetry]
