"""Recording an xArm 1S session, reading it back, replaying it, inspecting it.

The session is real: the xArm simulator (ocu.sim.xarm) on a pseudo-terminal with garbage
before a fifth of its replies, driven through the real XarmLink (pyserial), recorded by the
real Recorder. The file is read back with mcap's own reader and mcap_ros2's decoder, and the
board's frames in it are parsed here with `struct` from the layout in docs/xarm.md, not with
ocu's codec; they are checked against what the simulator ran (its count of moves, its last
move) and what the link reported live. `ocu --profile xarm1s --record` is run as a process,
replayed by `ocu --replay`, inspected, and killed with SIGKILL mid-write.
"""

from __future__ import annotations

import math
import os
import signal
import struct
import subprocess
import sys
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import zstandard
from mcap.exceptions import EndOfFile
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk
from mcap_ros2.decoder import DecoderFactory

from ocu.link.xarm import XarmLink
from ocu.profile.xarm import XarmProfile, load_xarm_profile
from ocu.profile.xarm_robot import xarm_robot_profile
from ocu.record import schemas as s
from ocu.record.inspect import main as inspect_main
from ocu.record.inspect import summarize
from ocu.record.reader import Recording
from ocu.record.recorder import Recorder
from ocu.record.ur_replay import open_replay
from ocu.record.xarm_replay import XarmReplayLink
from ocu.records import Command, LinkState, TelemetryFrame
from ocu.sim.xarm import XarmSimulator
from tests.record.helpers import Collector, assert_monotonic, poll_until, read_finished
from tests.record.helpers import Message as Read
from tests.windows.console_fixtures import qt_complaints, run_ocu

REPO_ROOT = Path(__file__).resolve().parents[2]
BASE, SHOULDER, ELBOW = 6, 5, 4
BATTERY_MV = 7400
GOAL_S = 0.6


def frame_fields(data: bytes) -> tuple[int, bytes]:
    """A board frame's command and parameters, by docs/xarm.md: 55 55 LEN CMD PRM...,
    LEN = parameters + 2."""
    assert data[:2] == b"\x55\x55", data.hex()
    assert data[2] == len(data) - 2, data.hex()
    return data[3], data[4:]


def move_fields(parameters: bytes) -> tuple[int, dict[int, int]]:
    """CMD_SERVO_MOVE: count, duration (u16 LE), count x {id, position u16 LE}."""
    count, duration = parameters[0], struct.unpack_from("<H", parameters, 1)[0]
    assert len(parameters) == 3 + 3 * count
    targets = {
        parameters[3 + 3 * k]: struct.unpack_from("<H", parameters, 4 + 3 * k)[0]
        for k in range(count)
    }
    return duration, targets


def position_fields(parameters: bytes) -> dict[int, int]:
    """A position reply: count, count x {id, position i16 LE}."""
    count = parameters[0]
    assert len(parameters) == 1 + 3 * count
    return {
        parameters[1 + 3 * k]: struct.unpack_from("<h", parameters, 2 + 3 * k)[0]
        for k in range(count)
    }


@dataclass
class Session:
    path: Path
    arm: XarmProfile
    topics: dict[str, list[Read]]
    live: Collector
    moves_run: int
    bad_frames: int
    goal: dict[int, int]


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Session]:
    """Connect, jog the base, one timed goal of three joints, the e-stop, shut down."""
    arm = load_xarm_profile("xarm1s")
    profile = xarm_robot_profile(arm)
    path = tmp_path_factory.mktemp("xarm") / "xarm.mcap"
    sim = XarmSimulator(arm, garbage_rate=0.2, seed=11, battery_mv=BATTERY_MV)
    sim.start()
    try:
        link = XarmLink(arm, sim.path, profile=profile, gui_alive_timeout_s=None)
        recorder = Recorder(profile, flush_period_s=0.2)
        live = Collector()
        link.subscribe(live)
        recorder.attach(link)
        recorder.start(path)
        link.start()
        try:
            assert live.wait(lambda: LinkState.CONNECTED in live.states)
            assert live.wait(lambda: bool(live.status))
            link.set_command(Command(velocities={"base": 0.5}))
            assert poll_until(lambda: sim.snapshot().setpoints[BASE] >= 540.0)
            link.set_command(Command())
            now = link.clock()
            until = now + GOAL_S
            goals = {"base": 0.0, "shoulder": 0.2, "elbow": -0.3}
            link.set_command(
                Command(
                    velocities=dict.fromkeys(goals, 0.1),
                    until=dict.fromkeys(goals, until),
                    goals=goals,
                )
            )
            assert poll_until(lambda: sim.snapshot().setpoints[ELBOW] < 440.0)
            assert poll_until(lambda: link.clock() > until)
            link.set_command(Command())
            # Heard where the goal left the servos' setpoints before the e-stop.
            assert live.wait(
                lambda: (
                    live.telemetry[-1].received_at > until + 0.3
                    and live.telemetry[-1].readings["elbow"].target_angle_rad is not None
                )
            )
            link.emergency_stop()
        finally:
            link.shutdown()
            recorder.stop()
        # The simulator reads the pseudo-terminal on its own thread: the last frames written
        # (the shutdown's stop move) may still be on their way when the link has shut down
        # (a hog run counted 10 moves run of 14 written). Wait for every move in the file.
        topics, _ = read_finished(path)
        written = sum(
            1
            for message in topics[s.RAW_XARM_TO_BOARD]
            if frame_fields(bytes(message.decoded.data))[0] == 0x03
        )
        poll_until(lambda: sim.snapshot().moves >= written)
        snapshot = sim.snapshot()
        goal = {
            arm.joint(name).servo: round(arm.raw_units(arm.joint(name), angle))
            for name, angle in goals.items()
        }
        yield Session(path, arm, topics, live, snapshot.moves, link.bad_frames, goal)
    finally:
        sim.stop()


def test_the_file_says_it_is_an_xarm_and_holds_its_profile(session: Session) -> None:
    with session.path.open("rb") as f:
        reader = make_reader(f)
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        attachments = {a.name: a.data for a in reader.iter_attachments()}
    assert metadata["ocu.recording"]["profile_name"] == "xarm1s"
    assert attachments["profile.toml"] == Path(session.arm.source).read_bytes()
    with Recording(session.path) as recording:
        assert recording.xarm() is not None
        assert recording.ur_arm() is None
        assert recording.profile().name == "xarm1s"


def test_every_frame_written_is_in_the_file_as_the_board_ran_it(session: Session) -> None:
    topics = session.topics
    assert_monotonic(topics)
    written = topics[s.RAW_XARM_TO_BOARD]
    moves: list[tuple[int, dict[int, int]]] = []
    reads = 0
    for message in written:
        raw = message.decoded
        assert raw.source == "ocu"
        # The OCU's send time is the log time; nothing was received.
        assert s.stamp_ns(raw.send_stamp) == message.log_time
        assert s.stamp_ns(raw.receive_stamp) == 0
        command, parameters = frame_fields(bytes(raw.data))
        if command == 0x03:
            moves.append(move_fields(parameters))
        elif command == 0x15:
            reads += 1
    # Every move the simulator ran is in the file, and no other.
    assert len(moves) == session.moves_run
    assert reads > 0
    # The goal went as ONE move of three servos with one duration.
    timed = [(d, t) for d, t in moves if len(t) == 3]
    assert len(timed) == 1
    duration, targets = timed[0]
    assert targets == session.goal
    assert abs(duration - GOAL_S * 1000) <= 60
    # The shutdown's stop moves are last: every servo held, within 0 ms.
    last_duration, last_targets = moves[-1]
    assert last_duration == 0
    assert len(last_targets) == 6


def test_the_boards_frames_and_the_garbage_are_in_the_file(session: Session) -> None:
    topics = session.topics
    frames = topics[s.RAW_XARM_FROM_BOARD]
    garbage = [m for m in topics[s.RAW_OTHER] if m.decoded.source == "robot"]
    assert frames
    assert garbage
    replies: Counter[int] = Counter()
    for message in frames:
        raw = message.decoded
        assert s.stamp_ns(raw.receive_stamp) == message.log_time
        assert s.stamp_ns(raw.send_stamp) == 0  # the board stamps nothing
        command, parameters = frame_fields(bytes(raw.data))
        replies[command] += 1
        if command == 0x0F:
            assert struct.unpack("<H", parameters)[0] == BATTERY_MV
    assert replies[0x15] == len(session.live.telemetry)
    assert replies[0x0F] == len(session.live.status)
    assert replies.keys() <= {0x15, 0x0F}


def test_joint_states_and_the_battery_are_the_replies_decoded(session: Session) -> None:
    topics = session.topics
    arm = session.arm
    replies = [
        position_fields(frame_fields(bytes(m.decoded.data))[1])
        for m in topics[s.RAW_XARM_FROM_BOARD]
        if bytes(m.decoded.data)[3] == 0x15
    ]
    states = topics[s.JOINT_STATES]
    assert len(states) == len(replies)
    for message, positions in zip(states, replies, strict=True):
        state = message.decoded
        assert list(state.name) == list(arm.joint_names)
        for name, angle in zip(state.name, state.position, strict=True):
            joint = arm.joint(name)
            expected = joint.sign * (positions[joint.servo] - 500 - joint.offset_units)
            assert angle == pytest.approx(expected * math.radians(arm.range_deg) / 1000)
    battery = topics[s.ROBOT_STATUS]
    assert battery
    assert all(m.decoded.voltage_v == BATTERY_MV / 1000 for m in battery)


def test_ocu_inspect_counts_frames_bad_frames_and_moves(
    session: Session, capsys: pytest.CaptureFixture[str]
) -> None:
    with Recording(session.path) as recording:
        summary = summarize(recording, recording.profile())
    assert summary.xarm
    assert summary.xarm_moves == session.moves_run
    assert summary.xarm_stop_moves >= 4  # the release, after the goal, the e-stop, shutdown
    assert summary.xarm_frames_received == len(session.topics[s.RAW_XARM_FROM_BOARD])
    # The live reader's count of bad frames, from the file alone.
    assert summary.xarm_bad_frames == session.bad_frames > 0
    assert inspect_main([str(session.path)]) == 0
    out = capsys.readouterr().out
    assert "profile xarm1s" in out
    assert f"{session.moves_run} moves sent" in out
    assert f"{session.bad_frames} bad frame(s)" in out


def test_the_replay_decodes_the_frames_as_the_live_link_did(session: Session) -> None:
    source = open_replay(session.path)
    assert isinstance(source, XarmReplayLink)
    replayed = Collector()
    source.subscribe(replayed)
    source.on_finished = replayed.mark_finished
    source.start()
    try:
        source.set_speed(4.0)
        source.play()
        assert replayed.wait(lambda: replayed.finished, timeout_s=30.0)
    finally:
        source.shutdown()
    live, again = session.live.telemetry, replayed.telemetry
    assert len(again) == len(live)
    for before, after in zip(live, again, strict=True):
        assert isinstance(after, TelemetryFrame)
        assert after.packet == before.packet
        for name, reading in before.readings.items():
            other = after.readings[name]
            assert other.angle_rad == reading.angle_rad
            assert other.fault == reading.fault
            assert other.speed_rad_s == pytest.approx(reading.speed_rad_s, rel=0.05, abs=0.01)
        # The setpoints the recorded moves gave are those the link kept.
        target = before.readings["elbow"].target_angle_rad
        assert target is not None
        assert after.readings["elbow"].target_angle_rad == pytest.approx(target, abs=1e-3)
    assert [f.voltage_v for f in replayed.status] == [f.voltage_v for f in session.live.status]
    assert source.recording.xarm() is not None


def test_ocu_profile_xarm1s_record_then_replay_and_inspect(tmp_path: Path) -> None:
    path = tmp_path / "console.mcap"
    result = run_ocu(tmp_path, "--profile", "xarm1s", "--record", str(path), "--quit-after", "2")
    assert result.returncode == 0, result.stderr
    assert qt_complaints(result.stderr) == []
    with Recording(path) as recording:
        topics = Counter(m.topic for m in recording.messages())
    assert topics[s.RAW_XARM_TO_BOARD] > 0
    assert topics[s.RAW_XARM_FROM_BOARD] > 0
    assert topics[s.JOINT_STATES] > 0
    assert topics[s.RAW_RCP] == 0
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen"}
    inspect = subprocess.run(
        [sys.executable, "-m", "ocu", "inspect", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        env=env,
        cwd=REPO_ROOT,
    )
    assert inspect.returncode == 0, inspect.stderr
    assert "xArm board" in inspect.stdout
    assert "profile xarm1s" in inspect.stdout
    replay = run_ocu(tmp_path, "--replay", str(path), "--quit-after", "1.5")
    assert replay.returncode == 0, replay.stderr
    assert "replay started" in replay.stderr
    assert "xArm simulator" not in replay.stderr  # no live link, no simulator
    assert qt_complaints(replay.stderr) == []


def test_a_killed_xarm_recording_stays_readable(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "OCU_CONFIG_DIR": str(tmp_path / "c")}
    process = subprocess.Popen(
        [sys.executable, "-m", "ocu", "--profile", "xarm1s", "--record", str(path)],
        env=env,
        cwd=REPO_ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )

    def chunks_written() -> int:
        if not path.exists() or path.stat().st_size == 0:
            return 0
        with Recording(path) as recording:
            return len(recording.chunks)

    try:
        assert poll_until(lambda: chunks_written() >= 3, timeout_s=60.0)
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    assert process.returncode == -signal.SIGKILL
    # mcap's non-seeking reader: every record up to where the writer was cut off.
    chunks = messages = 0
    channels: dict[int, Channel] = {}
    schemas: dict[int, Schema] = {}
    decoders = DecoderFactory()
    topics: Counter[str] = Counter()
    with path.open("rb") as f:
        try:
            for record in StreamReader(f, emit_chunks=True, validate_crcs=True).records:
                if not isinstance(record, Chunk):
                    continue
                chunks += 1
                for item in breakup_chunk(record, validate_crc=True):
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
                        topics[channel.topic] += 1
                        messages += 1
        except (EndOfFile, zstandard.ZstdError, CRCValidationError):
            pass  # the chunk being written when the process died
    assert chunks >= 3
    assert topics[s.RAW_XARM_TO_BOARD] > 0
    assert topics[s.RAW_XARM_FROM_BOARD] > 0
    assert topics[s.JOINT_STATES] > 0
    with Recording(path) as recording:
        assert recording.truncated
        assert sum(1 for _ in recording.messages()) == messages
    assert inspect_main([str(path)]) == 0
    source = open_replay(path)
    try:
        assert isinstance(source, XarmReplayLink)
        assert source.duration_s > 0.5
    finally:
        source.shutdown()
