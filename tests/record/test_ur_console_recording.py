"""A UR arm's session recorded by the console (`ocu --profile ur5e --record`, the Record
button), replayed by the console (`ocu --replay`), and a recording console killed mid-write.

Real processes, the real UR simulator (in the console's process for `ocu --profile ur5e`, in
this process for the window tests), real files read back with mcap's own readers.
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
from pathlib import Path

import pytest
import zstandard
from mcap.exceptions import EndOfFile
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk
from mcap_ros2.decoder import DecoderFactory
from PySide6.QtCore import QSettings, Qt
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication, QDockWidget
from pytestqt.qtbot import QtBot

from ocu.core.hardware import HardwareComponent
from ocu.hardware.replay import replay_hardware
from ocu.hardware.ur import UR_CAPABILITIES, ur_component
from ocu.hotkeys import load_key_map
from ocu.link.base import Link
from ocu.link.ur import UrLink
from ocu.profile.ur import load_ur_profile
from ocu.profile.ur_robot import ur_robot_profile
from ocu.record import schemas as s
from ocu.record.inspect import main as inspect_main
from ocu.record.reader import Recording
from ocu.record.recorder import Recorder
from ocu.record.ur_replay import UrReplayLink, open_replay
from ocu.records import LinkState
from ocu.sim.ur import UrSimulator
from ocu.windows.main_window import MainWindow
from tests.record.helpers import Collector, poll_until
from tests.test_integration_record import read_messages
from tests.windows.console_fixtures import DEADLINE_MS, qt_complaints, run_ocu, settings

__all__ = ["settings"]  # a fixture used below

REPO_ROOT = Path(__file__).resolve().parents[2]
JOINTS = load_ur_profile("ur5e").joint_names


def realtime_q(data: bytes) -> tuple[float, ...]:
    """q_actual of a realtime packet (offset 252, six big-endian doubles: docs/ur.md)."""
    return struct.unpack_from(">6d", data, 252)


@pytest.fixture(scope="module")
def ur_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """`ocu --profile ur5e --record FILE --quit-after 2` (the simulator in its process)."""
    work = tmp_path_factory.mktemp("urrec")
    path = work / "ur.mcap"
    result = run_ocu(work, "--profile", "ur5e", "--record", str(path), "--quit-after", "2")
    assert result.returncode == 0, result.stderr
    assert qt_complaints(result.stderr) == []
    return path


def test_ocu_profile_ur5e_record_writes_the_urs_channels(ur_recording: Path) -> None:
    counts = Counter(topic for topic, _ in read_messages(ur_recording))
    # How many of each depends on how soon a loaded machine connects within the 2 s.
    assert counts[s.RAW_UR_REALTIME] > 0
    assert counts[s.RAW_UR_PRIMARY] == 1  # the version message
    assert counts[s.RAW_UR_SECONDARY] > 0
    assert counts[s.RAW_UR_SCRIPT] > 0  # speedj streamed at 125 Hz, stopj last
    assert counts[s.JOINT_STATES] > 0
    assert counts[s.RAW_RCP] == counts[s.RAW_TELEMETRY] == 0  # nothing of the Engineer's
    messages = read_messages(ur_recording)
    scripts = [bytes(m.data) for topic, m in messages if topic == s.RAW_UR_SCRIPT]
    assert scripts[-1].startswith(b"stopj(")  # the console's shutdown is in the file


def test_ocu_inspect_and_ocu_replay_of_the_urs_file(ur_recording: Path, tmp_path: Path) -> None:
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen"}
    inspect = subprocess.run(
        [sys.executable, "-m", "ocu", "inspect", str(ur_recording)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        env=env,
        cwd=REPO_ROOT,
    )
    assert inspect.returncode == 0, inspect.stderr
    assert "profile ur5e" in inspect.stdout
    assert "URScript lines sent" in inspect.stdout
    assert ", 0 lost: drop 0.00 %" in inspect.stdout
    # The file says which robot it is: with or without a --profile naming it.
    for profile in ((), ("--profile", "ur5e")):
        replay = run_ocu(tmp_path, *profile, "--replay", str(ur_recording), "--quit-after", "1.5")
        assert replay.returncode == 0, replay.stderr
        assert "replay started" in replay.stderr
        assert "UR link" not in replay.stderr  # no live link, no simulator
        assert qt_complaints(replay.stderr) == []


def test_the_console_replays_a_ur_recording_as_a_ur(
    ur_recording: Path, qtbot: QtBot, settings: QSettings
) -> None:
    source = open_replay(ur_recording)
    assert isinstance(source, UrReplayLink)
    hardware_for, capabilities = replay_hardware(source)
    assert capabilities == UR_CAPABILITIES
    window = MainWindow(
        source.profile,
        None,
        f"replay {ur_recording.name}",
        settings,
        load_key_map(source.profile),
        replay=source,
        hardware_for=hardware_for,
        capabilities=capabilities,
    )
    qtbot.addWidget(window)
    try:
        window.show()
        names = {dock.objectName() for dock in window.findChildren(QDockWidget)}
        assert "joint_position_dock" in names
        assert not names & {"video_dock", "map_dock", "calibration_dock"}
        assert not window.velocity_panel.isEnabled()
        assert window.link is not None
        assert window.link.read_only
        table = window.joint_panel.table

        def shown() -> list[str | None]:
            return [table.cell_text(r, "angle °") for r in range(len(JOINTS))]

        # The console's joints follow the file: where the last realtime packet has them.
        last = next(
            bytes(m.data)
            for topic, m in reversed(read_messages(ur_recording))
            if topic == s.RAW_UR_REALTIME
        )
        expected = [f"{math.degrees(q):.2f}" for q in realtime_q(last)]
        source.set_speed(4.0)
        source.play()
        qtbot.waitUntil(lambda: source.finished, timeout=DEADLINE_MS)
        # The recording ends with the console's own shutdown of its link.
        qtbot.waitUntil(lambda: window.link_status.state == LinkState.CLOSED, timeout=DEADLINE_MS)
        qtbot.waitUntil(lambda: shown() == expected, timeout=DEADLINE_MS)
        joints = [table.cell_text(r, "joint") for r in range(table.rowCount())]
        assert joints == list(JOINTS)
    finally:
        window.shutdown()
        QApplication.processEvents()


@pytest.fixture
def ur_sim() -> Iterator[UrSimulator]:
    simulator = UrSimulator(load_ur_profile("ur5e"), host="127.0.0.1", ports=(0, 0, 0))
    simulator.start()
    yield simulator
    simulator.stop()


def test_the_record_button_records_a_ur_console(
    ur_sim: UrSimulator, qtbot: QtBot, settings: QSettings, tmp_path: Path
) -> None:
    arm = load_ur_profile("ur5e")
    profile = ur_robot_profile(arm)
    ports = (ur_sim.ports["primary"], ur_sim.ports["secondary"], ur_sim.ports["realtime"])

    def make_link() -> Link:
        return UrLink(arm, "127.0.0.1", profile=profile, ports=ports)

    def hardware_for(link: Link) -> HardwareComponent:
        assert isinstance(link, UrLink)
        return ur_component(link)

    recorder = Recorder(profile, flush_period_s=0.2)
    window = MainWindow(
        profile,
        make_link,
        "UR simulator",
        settings,
        load_key_map(profile),
        recorder=recorder,
        hardware_for=hardware_for,
        capabilities=UR_CAPABILITIES,
    )
    qtbot.addWidget(window)
    try:
        window.show()
        qtbot.waitUntil(
            lambda: window.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS
        )
        button = window.record_button
        assert button is not None
        button.directory = tmp_path / "recordings"
        with qtbot.waitSignal(button.recording_started, timeout=DEADLINE_MS) as started:
            QTest.mouseClick(button, Qt.MouseButton.LeftButton)
        path = Path(started.args[0])
        window.activateWindow()
        window.velocity_panel.setFocus()
        QTest.keyPress(window, Qt.Key.Key_Y)  # shoulder_lift_joint + (the UR's key map)
        qtbot.waitUntil(lambda: ur_sim.snapshot().qd[1] > 0.0, timeout=DEADLINE_MS)
        QTest.keyRelease(window, Qt.Key.Key_Y)
        qtbot.waitUntil(lambda: ur_sim.snapshot().qd[1] == 0.0, timeout=DEADLINE_MS)
        with qtbot.waitSignal(button.recording_stopped, timeout=DEADLINE_MS):
            QTest.mouseClick(button, Qt.MouseButton.LeftButton)
    finally:
        window.shutdown()
        QApplication.processEvents()
    messages = read_messages(path)
    counts = Counter(topic for topic, _ in messages)
    assert counts[s.RAW_UR_REALTIME] > 0
    # The shoulder's lift went out as speedj and was recorded as the command it carried.
    lifts = [
        m.velocity[1] for topic, m in messages if topic == s.CMD_JOINTS and m.velocity[1] > 0.0
    ]
    assert lifts
    lifted = [realtime_q(bytes(m.data))[1] for t, m in messages if t == s.RAW_UR_REALTIME]
    assert lifted[-1] > lifted[0]
    # Started after the link connected: no version message in the file. The replay takes
    # any known realtime layout then, and shows the lift.
    assert counts[s.RAW_UR_PRIMARY] == 0
    collector = Collector()
    source = open_replay(path, on_finished=collector.mark_finished)
    source.subscribe(collector)
    source.start()
    try:
        source.set_speed(4.0)
        source.play()
        assert collector.wait(lambda: collector.finished)
    finally:
        source.shutdown()
    replayed = [f.readings["shoulder_lift_joint"].angle_rad for f in collector.telemetry]
    assert replayed
    assert replayed[-1] == lifted[-1]


def test_a_ur_console_refuses_an_unwritable_recording_before_any_window(tmp_path: Path) -> None:
    target = tmp_path / "no" / "such" / "x.mcap"
    result = run_ocu(tmp_path, "--profile", "ur5e", "--record", str(target), "--quit-after", "5")
    assert result.returncode == 1
    assert f"cannot record to {target}" in result.stderr
    assert "Traceback" not in result.stderr
    assert "link started" not in result.stderr


def test_a_killed_ur_recording_stays_readable(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    env = {
        **os.environ,
        "QT_QPA_PLATFORM": "offscreen",
        "OCU_CONFIG_DIR": str(tmp_path / "cfg"),
    }
    process = subprocess.Popen(
        [sys.executable, "-m", "ocu", "--profile", "ur5e", "--record", str(path)],
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
        # The recorder closes a chunk at least every second.
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
                        topics[channel.topic] += 1
                        messages += 1
        except (EndOfFile, zstandard.ZstdError, CRCValidationError):
            pass  # the chunk being written when the process died
    assert chunks >= 3
    assert topics[s.RAW_UR_REALTIME] > 0
    assert topics[s.RAW_UR_SCRIPT] > 0
    assert topics[s.JOINT_STATES] > 0

    with Recording(path) as recording:
        assert recording.truncated
        assert len(recording.chunks) == chunks
        assert sum(1 for _ in recording.messages()) == messages
    assert inspect_main([str(path)]) == 0
    source = open_replay(path)
    try:
        assert isinstance(source, UrReplayLink)
        assert source.duration_s > 0.5
    finally:
        source.shutdown()
