"""Recording a Universal Robots arm's session, reading it back, replaying it, inspecting it.

The session is real: the UR simulator (ocu.sim.ur, TCP on 127.0.0.1, a UR5e at 5.10: 1220-byte
realtime packets at 500 Hz) driven through the real UrLink, recorded by the real Recorder.
The file is read back with mcap's own reader and mcap_ros2's decoder, and the UR packets in
it are parsed here with `struct` from the byte layout in docs/ur.md, not with ocu's codecs;
the values are checked against what the simulator did (its snapshot, its count of accepted
URScript commands, its controller clock).
"""

from __future__ import annotations

import itertools
import json
import struct
import tomllib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from ocu.link.ur import UrLink
from ocu.profile.ur import UrArmProfile, load_ur_profile
from ocu.profile.ur_robot import ur_robot_profile
from ocu.record import schemas as s
from ocu.record.errors import RecordingError
from ocu.record.inspect import main as inspect_main
from ocu.record.recorder import Recorder
from ocu.record.replay_link import ReplayLink
from ocu.record.ur_replay import UrReplayLink, open_replay
from ocu.records import Command, CommandSent, LinkEvent, LinkState, RobotModeReport
from ocu.sim.ur import UrSimSnapshot, UrSimulator
from tests.link.test_ur_link import GarbageProxy
from tests.record.helpers import Collector, Message, assert_monotonic, poll_until, read_finished

JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
PAN_RAD_S = 0.3
MUTE_S = 0.2
MOVE_S = 0.4  # heard moving after the mute, by the controller's clock
REALTIME_BYTES = 1220  # 5.10
REALTIME_HZ = 500.0


def realtime_fields(data: bytes) -> tuple[int, float, tuple[float, ...], tuple[float, ...]]:
    """Length, controller time, q_actual and qd_actual of a realtime packet (docs/ur.md)."""
    (length,) = struct.unpack_from(">i", data, 0)
    (time_s,) = struct.unpack_from(">d", data, 4)
    return (
        length,
        time_s,
        struct.unpack_from(">6d", data, 252),
        struct.unpack_from(">6d", data, 300),
    )


@dataclass
class Session:
    path: Path
    arm: UrArmProfile
    topics: dict[str, list[Message]]
    summary: object
    at_rest: UrSimSnapshot
    accepted_after: UrSimSnapshot


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Session]:
    """Connect, turn the base, mute the controller for MUTE_S, stop, e-stop, shut down."""
    arm = load_ur_profile("ur5e")
    profile = ur_robot_profile(arm)
    path = tmp_path_factory.mktemp("ur") / "ur.mcap"
    sim = UrSimulator(arm, host="127.0.0.1", ports=(0, 0, 0))
    sim.start()
    try:
        ports = [sim.ports[k] for k in ("primary", "secondary", "realtime")]
        link = UrLink(arm, "127.0.0.1", profile=profile, ports=ports, gui_alive_timeout_s=None)
        recorder = Recorder(profile, flush_period_s=0.2)
        collector = Collector()
        link.subscribe(collector)
        recorder.attach(link)
        recorder.start(path)
        link.start()
        try:
            assert collector.wait(lambda: LinkState.CONNECTED in collector.states)
            link.set_velocities(shoulder_pan_joint=PAN_RAD_S)
            assert poll_until(lambda: sim.snapshot().qd[0] >= PAN_RAD_S - 1e-9)
            sim.set_mute(True)
            muted_at = sim.snapshot().time_s
            assert poll_until(lambda: sim.snapshot().time_s >= muted_at + MUTE_S)
            sim.set_mute(False)
            moving_at = sim.snapshot().time_s
            assert poll_until(lambda: sim.snapshot().time_s >= moving_at + MOVE_S)
            link.set_velocities(shoulder_pan_joint=0.0)
            assert poll_until(lambda: all(v == 0.0 for v in sim.snapshot().qd))
            at_rest = sim.snapshot()
            # Heard at rest (the actual angle lags the target by a period) before the e-stop.
            assert collector.wait(
                lambda: (
                    collector.telemetry[-1].readings["shoulder_pan_joint"].angle_rad == at_rest.q[0]
                )
            )
            link.emergency_stop()
            assert poll_until(lambda: sim.snapshot().program == "stopj")
        finally:
            link.shutdown()
            recorder.stop()
        topics, summary = read_finished(path)
        lines = len(topics[s.RAW_UR_SCRIPT])
        # What the controller ran: every line the file says went out, and no other.
        assert poll_until(lambda: sim.snapshot().accepted + sim.snapshot().refused >= lines)
        yield Session(path, arm, topics, summary, at_rest, sim.snapshot())
    finally:
        sim.stop()


def test_the_file_says_it_is_a_ur5e_and_holds_its_profile(session: Session) -> None:
    with session.path.open("rb") as f:
        reader = make_reader(f)
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        attachments = {a.name: a.data for a in reader.iter_attachments()}
    assert metadata["ocu.recording"]["profile_name"] == "ur5e"
    shipped = Path(session.arm.source).read_bytes()
    assert attachments["profile.toml"] == shipped
    assert tomllib.loads(shipped.decode())["series"] == "e-series"


def test_every_realtime_packet_is_in_the_file_as_the_controller_sent_it(session: Session) -> None:
    topics = session.topics
    assert_monotonic(topics)
    realtime = topics[s.RAW_UR_REALTIME]
    assert len(realtime) >= MOVE_S * REALTIME_HZ
    times: list[float] = []
    for message in realtime:
        raw = message.decoded
        data = bytes(raw.data)
        length, time_s, _, _ = realtime_fields(data)
        assert len(data) == length == REALTIME_BYTES
        assert raw.source == "robot"
        # send_stamp and publish time: the controller's own clock; receive_stamp: ours.
        assert s.stamp_ns(raw.send_stamp) == message.publish_time == round(time_s * 1e9)
        assert s.stamp_ns(raw.receive_stamp) == message.log_time
        times.append(time_s)
    steps = [round((b - a) * REALTIME_HZ) for a, b in itertools.pairwise(times)]
    # One controller period apart, except across the mute: the periods it sent nothing.
    gaps = [step for step in steps if step != 1]
    assert len(gaps) == 1, gaps
    assert gaps[0] >= MUTE_S * REALTIME_HZ
    # The arm at rest in the last packets is where the simulator holds it.
    _, _, q_last, qd_last = realtime_fields(bytes(realtime[-1].decoded.data))
    assert q_last == pytest.approx(session.at_rest.q, abs=1e-12)
    assert qd_last == (0.0,) * 6
    assert q_last[0] > 0.05  # the base turned


def test_the_primary_version_message_and_secondary_state_are_in_the_file(
    session: Session,
) -> None:
    (version,) = session.topics[s.RAW_UR_PRIMARY]
    data = bytes(version.decoded.data)
    length, kind = struct.unpack_from(">iB", data, 0)
    assert (length, kind) == (len(data), 20)  # a robot message
    assert data[14] == 3  # the version message
    name_length = data[15]
    assert data[16 : 16 + name_length] == b"URControl"
    assert tuple(data[16 + name_length : 18 + name_length]) == (5, 10)
    secondary = session.topics[s.RAW_UR_SECONDARY]
    assert len(secondary) >= 5
    kinds = []
    for message in secondary:
        data = bytes(message.decoded.data)
        length, kind = struct.unpack_from(">iB", data, 0)
        assert length == len(data)
        kinds.append(kind)
    # From 3.1 the secondary port too starts with the version message, then robot state.
    assert kinds[0] == 20
    assert set(kinds[1:]) == {16}


def test_every_urscript_line_sent_is_in_the_file_and_reached_the_controller(
    session: Session,
) -> None:
    lines = [bytes(m.decoded.data).decode("ascii") for m in session.topics[s.RAW_UR_SCRIPT]]
    assert all(m.decoded.source == "ocu" for m in session.topics[s.RAW_UR_SCRIPT])
    assert all(line.endswith("\n") for line in lines)
    assert any(line.startswith(f"speedj([{PAN_RAD_S:.6f},") for line in lines), lines[:3]
    assert lines[-1].startswith("stopj(")  # the link's last words at shutdown
    # The simulator ran exactly as many commands as the file says were sent.
    after = session.accepted_after
    assert after.accepted + after.refused == len(lines)
    commands = session.topics[s.CMD_JOINTS]
    assert any(
        dict(zip(m.decoded.name, m.decoded.velocity, strict=True))["shoulder_pan_joint"]
        == PAN_RAD_S
        for m in commands
    )
    assert all(list(m.decoded.name) == list(JOINTS) for m in commands)


def test_joint_states_events_and_link_statistics(session: Session) -> None:
    states = session.topics[s.JOINT_STATES]
    assert len(states) >= 3  # at most 50 Hz: how many depends on the machine's load
    assert all(list(m.decoded.name) == list(JOINTS) for m in states)
    assert list(states[-1].decoded.position) == pytest.approx(session.at_rest.q, abs=1e-12)
    pans = [m.decoded.position[0] for m in states]
    assert pans == sorted(pans)  # the base only ever turned one way
    events = [
        (m.decoded.kind, m.decoded.state, m.decoded.message) for m in session.topics[s.EVENTS]
    ]
    kinds = [kind for kind, _, _ in events]
    assert ("robot_mode", "RUNNING · NORMAL", "robot RUNNING, safety NORMAL") in events
    assert ("safety", "", "EMERGENCY STOP (operator)") in events
    assert ("link_state", "connected") in [(k, st) for k, st, _ in events]
    assert kinds[0] == "recording"
    assert session.topics[s.LINK_STATS]
    assert max(m.decoded.telemetry for m in session.topics[s.LINK_STATS]) > 0


def test_inspect_counts_lines_packets_the_gap_and_the_stops(
    session: Session, capsys: pytest.CaptureFixture[str]
) -> None:
    assert inspect_main([str(session.path), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    topics = session.topics
    lines = [bytes(m.decoded.data) for m in topics[s.RAW_UR_SCRIPT]]
    times = [realtime_fields(bytes(m.decoded.data))[1] for m in topics[s.RAW_UR_REALTIME]]
    expected = round((times[-1] - times[0]) * REALTIME_HZ) + 1
    assert summary["ur"] is True
    assert summary["profile_name"] == "ur5e"
    assert summary["rcp_sent"] == len(lines)
    assert summary["stopj_sent"] == sum(line.startswith(b"stopj(") for line in lines) > 0
    assert summary["telemetry_received"] == len(times)
    assert summary["telemetry_lost"] == expected - len(times) >= MUTE_S * REALTIME_HZ - 1
    assert summary["telemetry_longest_gap_s"] >= MUTE_S
    assert summary["telemetry_rate_hz"] == pytest.approx(
        (len(times) - 1)
        / ((topics[s.RAW_UR_REALTIME][-1].log_time - topics[s.RAW_UR_REALTIME][0].log_time) / 1e9)
    )
    assert summary["estops"] == 1
    assert summary["robot_watchdog_s"] == pytest.approx(0.06)
    assert inspect_main([str(session.path)]) == 0
    text = capsys.readouterr().out
    assert f"{len(lines)} URScript lines sent" in text
    assert f"realtime packets {len(times)} received" in text


def test_the_replay_plays_the_recorded_states_through_the_links_decoder(
    session: Session,
) -> None:
    collector = Collector()
    events: list[LinkEvent] = []
    source = open_replay(session.path, on_finished=collector.mark_finished)
    assert isinstance(source, UrReplayLink)
    assert source.profile.name == "ur5e"
    assert source.profile.channels.keys() == set(JOINTS)
    source.subscribe(collector)
    source.subscribe(events.append)
    recorded = {
        realtime_fields(bytes(m.decoded.data))[2] for m in session.topics[s.RAW_UR_REALTIME]
    }
    source.start()
    try:
        source.play()
        assert collector.wait(lambda: collector.finished)
    finally:
        source.shutdown()
    frames = collector.telemetry
    assert len(frames) >= 3  # at most 50 Hz, as the live link handed them on
    for frame in frames:
        q = tuple(frame.readings[name].angle_rad for name in JOINTS)
        assert q in recorded  # each one a state the controller sent, decoded as live
    last = frames[-1]
    assert [last.readings[n].angle_rad for n in JOINTS] == pytest.approx(session.at_rest.q)
    reports = [e for e in events if isinstance(e, RobotModeReport)]
    assert reports
    assert reports[0].mode == "RUNNING"
    assert reports[0].may_move
    sent = [e.command for e in events if isinstance(e, CommandSent)]
    assert any(c.velocity("shoulder_pan_joint") == PAN_RAD_S for c in sent)
    assert "EMERGENCY STOP (operator)" in collector.safety
    assert collector.states[0] is LinkState.CONNECTED
    # Read-only: commands go nowhere.
    source.set_command(Command(velocities={"shoulder_pan_joint": 1.0}))
    source.emergency_stop()
    assert source.read_only


def test_an_engineer_recording_still_opens_as_the_engineers(tmp_path: Path) -> None:
    from ocu.profile import load_profile

    profile = load_profile()
    recorder = Recorder(profile)
    recorder.start(tmp_path / "e.mcap")
    recorder.stop()
    source = open_replay(tmp_path / "e.mcap")
    try:
        assert type(source) is ReplayLink
        assert source.profile.name == profile.name
    finally:
        source.shutdown()


def _write_ur_file(path: Path, profile_toml: bytes, realtime: list[bytes]) -> None:
    """A file as ocu writes one, with a given profile and raw realtime packets."""
    with path.open("wb") as f:
        writer = Writer(f)
        writer.start(profile=s.PROFILE, library="test")
        writer.add_metadata(s.METADATA_NAME, {"format_version": "1", "profile_name": "ur5e"})
        writer.add_attachment(
            create_time=0, log_time=0, name=s.PROFILE_ATTACHMENT, media_type="", data=profile_toml
        )
        schema = writer.register_schema(
            s.RAW_PACKET.name, s.SCHEMA_ENCODING, s.RAW_PACKET.definition.encode()
        )
        channel = writer.register_channel(s.RAW_UR_REALTIME, s.MESSAGE_ENCODING, schema)
        encode = s.make_encoder(s.RAW_PACKET)
        for index, data in enumerate(realtime):
            message = {
                "send_stamp": s.stamp(0),
                "receive_stamp": s.stamp(index),
                "source": "robot",
                "data": data,
            }
            writer.add_message(
                channel, log_time=1_000_000 * (index + 1), data=encode(message), publish_time=0
            )
        writer.finish()  # type: ignore[no-untyped-call]


def test_a_broken_ur_profile_in_the_file_is_refused_with_the_reason(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    arm = load_ur_profile("ur5e")
    text = Path(arm.source).read_text()
    broken = text.replace('name = "ur5e"', 'name = ""').encode()
    assert broken != text.encode()
    path = tmp_path / "broken.mcap"
    _write_ur_file(path, broken, [])
    with pytest.raises(RecordingError, match=r"recorded UR profile unusable: .*name"):
        open_replay(path)
    assert inspect_main([str(path)]) == 1
    assert "recorded UR profile unusable" in capsys.readouterr().err


def test_packets_that_do_not_decode_are_counted_and_the_replay_goes_on(tmp_path: Path) -> None:
    arm = load_ur_profile("ur5e")
    good = _realtime_packet(0.5)
    garbage = b"\x00\x00\x04\xc4" + b"\xff" * 1216  # a 1220-byte frame with NaN modes
    path = tmp_path / "bad.mcap"
    _write_ur_file(path, Path(arm.source).read_bytes(), [garbage, good])
    collector = Collector()
    source = open_replay(path, on_finished=collector.mark_finished)
    assert isinstance(source, UrReplayLink)
    source.subscribe(collector)
    source.start()
    try:
        source.play()
        assert collector.wait(lambda: collector.finished)
    finally:
        source.shutdown()
    assert [f.readings["elbow_joint"].angle_rad for f in collector.telemetry] == [0.5]
    assert source.decoder.malformed == 1


def _realtime_packet(elbow_rad: float) -> bytes:
    """A 5.10 realtime packet built from the layout in docs/ur.md: running, normal."""
    values = [0.0] * 152
    values[0] = 1.0  # controller time
    values[31:37] = [0.0, -1.57, elbow_rad, 0.0, 0.0, 0.0]  # q_actual (offset 252)
    values[94] = 7.0  # robot mode RUNNING (offset 756)
    values[95:101] = [253.0] * 6  # joint modes
    values[101] = 1.0  # safety mode NORMAL (offset 812)
    return struct.pack(">i152d", REALTIME_BYTES, *values)


def _record(
    path: Path, sim: UrSimulator, ports: tuple[int, int, int], act: Callable[[Collector], None]
) -> None:
    """Record a UrLink to `sim` (at `ports`) while `act` runs."""
    arm = sim.profile
    profile = ur_robot_profile(arm)
    link = UrLink(arm, "127.0.0.1", profile=profile, ports=ports, gui_alive_timeout_s=None)
    recorder = Recorder(profile, flush_period_s=0.2)
    collector = Collector()
    link.subscribe(collector)
    recorder.attach(link)
    recorder.start(path)
    link.start()
    try:
        assert collector.wait(lambda: LinkState.CONNECTED in collector.states)
        assert poll_until(lambda: link.robot_status is not None)  # the secondary port heard
        act(collector)
    finally:
        link.shutdown()
        recorder.stop()


def test_bytes_that_are_no_packet_are_kept_on_raw_other(tmp_path: Path) -> None:
    sim = UrSimulator(load_ur_profile("ur5e"), host="127.0.0.1", ports=(0, 0, 0))
    sim.start()
    proxy = GarbageProxy(sim.host, sim.ports["realtime"])
    size = sim.realtime_size

    def inject(collector: Collector) -> None:
        proxy.inject(b"\xff" * 300)
        proxy.inject(size.to_bytes(4, "big") + b"\x7f" * (size - 4))
        assert collector.wait(lambda: bool(collector.stats) and collector.stats[-1].malformed >= 2)
        # Closed before the link: a proxy left forwarding would write to a closed socket.
        proxy.close()

    try:
        ports = (sim.ports["primary"], sim.ports["secondary"], proxy.port)
        _record(tmp_path / "garbage.mcap", sim, ports, inject)
    finally:
        proxy.close()
        sim.stop()
    topics, _ = read_finished(tmp_path / "garbage.mcap")
    other = b"".join(bytes(m.decoded.data) for m in topics[s.RAW_OTHER])
    assert other.count(b"\xff") >= 300
    assert other.count(b"\x7f") >= size - 4
    assert all(m.decoded.source == "robot" for m in topics[s.RAW_OTHER])
    assert all(len(bytes(m.decoded.data)) == size for m in topics[s.RAW_UR_REALTIME])


def test_the_controllers_own_stop_is_recorded_and_counted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = UrSimulator(load_ur_profile("ur5e"), host="127.0.0.1", ports=(0, 0, 0))
    sim.start()

    def press_the_red_button(collector: Collector) -> None:
        sim.emergency_stop(True)
        assert collector.wait(lambda: any("EMERGENCY_STOP" in m for m in collector.safety))
        sim.emergency_stop(False)
        assert collector.wait(lambda: any("ready" in m for m in collector.safety))

    try:
        ports = (sim.ports["primary"], sim.ports["secondary"], sim.ports["realtime"])
        _record(tmp_path / "stop.mcap", sim, ports, press_the_red_button)
    finally:
        sim.stop()
    topics, _ = read_finished(tmp_path / "stop.mcap")
    modes = [m.decoded.state for m in topics[s.EVENTS] if m.decoded.kind == "robot_mode"]
    assert modes == ["RUNNING · NORMAL", "EMERGENCY STOP", "RUNNING · NORMAL"]
    assert inspect_main([str(tmp_path / "stop.mcap"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["controller_stops"] == 1
    assert summary["estops"] == 0  # the operator pressed nothing


def test_a_seek_plays_on_from_the_moment_sought(session: Session) -> None:
    realtime = session.topics[s.RAW_UR_REALTIME]
    start_ns = min(m.log_time for topic in session.topics.values() for m in topic)
    middle = realtime[len(realtime) // 2]
    target_s = (middle.log_time - start_ns) / 1e9
    # The controller times of the packets recorded from the target on.
    later = {
        realtime_fields(bytes(m.decoded.data))[1] for m in realtime if m.log_time >= middle.log_time
    }
    collector = Collector()
    source = open_replay(session.path, on_finished=collector.mark_finished)
    source.subscribe(collector)
    source.start()
    try:
        source.seek(target_s)
        source.play()
        assert collector.wait(lambda: collector.finished)
    finally:
        source.shutdown()
    assert collector.telemetry
    times = [frame.packet.state.time_s for frame in collector.telemetry]  # type: ignore[attr-defined]
    assert set(times) <= later
    # The command in force at the target came back from the last speedj before it.
    assert source.command.velocity("shoulder_pan_joint") in (0.0, PAN_RAD_S)
