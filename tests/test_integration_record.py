"""Recording in the console (`ocu --record`, the Record button), `ocu inspect`, and the console
replaying a recording (`ocu --replay`): real simulator, real files, mcap's own reader."""

from __future__ import annotations

import math
import threading
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from PySide6.QtCore import QSettings, Qt
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication
from pytestqt.qtbot import QtBot

from ocu.profile import RobotProfile
from ocu.protocol import RemoteControlPacket
from ocu.protocol.wire import make_codec
from ocu.record.recorder import Recorder
from ocu.record.replay_link import ReplayLink
from ocu.records import LinkState
from ocu.sim.simulator import RobotSimulator
from ocu.windows.main_window import MainWindow
from tests.windows.console_fixtures import (
    DEADLINE_MS,
    ConsoleFactory,
    make_console,
    qt_complaints,
    run_ocu,
    settings,
    sim,
)

__all__ = ["make_console", "settings", "sim"]  # fixtures used below

WAIST_RAD = 0.5  # where the recorded robot's waist stands: the replay must show it


@pytest.fixture(scope="module")
def recorded_session(tmp_path_factory: pytest.TempPathFactory, profile: RobotProfile) -> Path:
    """`ocu --record FILE --robot SIM --quit-after 2` against a simulator in this process."""
    work = tmp_path_factory.mktemp("record")
    path = work / "session.mcap"
    simulator = RobotSimulator(
        profile, telemetry_hz=10.0, video_fps=5.0, initial_joints={"waist": WAIST_RAD}
    )
    with simulator:
        host, port = simulator.address
        result = run_ocu(
            work, "--record", str(path), "--robot", f"{host}:{port}", "--quit-after", "2"
        )
    assert result.returncode == 0, result.stderr
    assert qt_complaints(result.stderr) == []
    return path


def read_messages(path: Path) -> list[tuple[str, Any]]:
    """Every message of a finished MCAP file as (topic, decoded ROS 2 message)."""
    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        return [
            (channel.topic, decoded)
            for _, channel, _, decoded in reader.iter_decoded_messages(log_time_order=True)
        ]


def test_ocu_record_writes_telemetry_and_commands(
    recorded_session: Path, profile: RobotProfile
) -> None:
    messages = read_messages(recorded_session)
    counts = Counter(topic for topic, _ in messages)
    assert counts["/raw/telemetry"] >= 10
    assert counts["/joint_states"] == counts["/raw/telemetry"]
    assert counts["/raw/rcp"] >= 10
    assert counts["/cmd_vel_sent"] == counts["/raw/rcp"]
    assert counts["/raw/hello"] > 0  # the console probes for the protocol extension
    assert counts["/camera/front/compressed"] > 0
    waist = [
        dict(zip(m.name, m.position, strict=True))["waist"]
        for topic, m in messages
        if topic == "/joint_states"
    ]
    assert all(math.isclose(angle, WAIST_RAD, abs_tol=1e-3) for angle in waist)
    # The link was stopped before the file was finished: its closing zeros are the last RCPs.
    codec = make_codec(profile)
    rcps = [codec.decode(bytes(m.data)) for topic, m in messages if topic == "/raw/rcp"]
    last = rcps[-profile.link.estop_repeats :]
    assert all(isinstance(p, RemoteControlPacket) and not any(p.axes) for p in last)


def test_ocu_inspect_prints_the_summary(recorded_session: Path, tmp_path: Path) -> None:
    result = run_ocu(tmp_path, "inspect", str(recorded_session))
    assert result.returncode == 0, result.stderr
    assert "/raw/telemetry" in result.stdout
    assert "RCPs sent" in result.stdout
    missing = tmp_path / "nothing.mcap"
    result = run_ocu(tmp_path, "inspect", str(missing))
    assert result.returncode == 1
    assert "nothing.mcap" in result.stderr
    assert "Traceback" not in result.stderr


def test_record_to_an_unwritable_path_stops_before_any_window(tmp_path: Path) -> None:
    target = tmp_path / "no" / "such" / "dir" / "x.mcap"
    result = run_ocu(tmp_path, "--record", str(target), "--quit-after", "5")
    assert result.returncode == 1
    assert "cannot record to" in result.stderr
    assert "Traceback" not in result.stderr
    assert "link started" not in result.stderr


def test_record_button_records_the_console_link(
    make_console: ConsoleFactory,
    sim: RobotSimulator,
    qtbot: QtBot,
    profile: RobotProfile,
    tmp_path: Path,
) -> None:
    recorder = Recorder(profile, flush_period_s=0.2)
    console = make_console(sim, recorder=recorder)
    button = console.record_button
    assert button is not None
    assert console.link_status.isAncestorOf(button)  # in the status bar
    button.directory = tmp_path / "recordings"
    with qtbot.waitSignal(button.recording_started, timeout=DEADLINE_MS) as started:
        QTest.mouseClick(button, Qt.MouseButton.LeftButton)
    assert button.isChecked()
    path = Path(started.args[0])
    assert path.parent == tmp_path / "recordings"
    console.model.set_velocity("waist", 0.2)
    qtbot.waitUntil(lambda: recorder.stats().messages_written >= 40, timeout=DEADLINE_MS)
    with qtbot.waitSignal(button.recording_stopped, timeout=DEADLINE_MS):
        QTest.mouseClick(button, Qt.MouseButton.LeftButton)
    assert not button.isChecked()
    assert not recorder.recording
    counts = Counter(topic for topic, _ in read_messages(path))
    assert counts["/raw/telemetry"] > 0
    assert counts["/raw/rcp"] > 0
    log = [console.event_log.item(k).text() for k in range(console.event_log.count())]
    assert any(f"recording to {path}" in line for line in log)
    assert any("recording finished" in line for line in log)


def test_console_replays_a_recording_with_commands_disabled(
    recorded_session: Path, qtbot: QtBot, profile: RobotProfile, settings: QSettings
) -> None:
    source = ReplayLink(recorded_session, profile)
    window = MainWindow(
        source.profile, None, f"replay {recorded_session.name}", settings, replay=source
    )
    qtbot.addWidget(window)
    try:
        window.show()
        window.activateWindow()
        qtbot.waitUntil(window.isActiveWindow, timeout=DEADLINE_MS)
        assert "REPLAY" in window.windowTitle()
        assert window.replay_banner.isVisible()
        assert window.replay_banner.text().startswith("REPLAY")
        assert window.replay_controls.isVisible()
        assert window.link is not None
        assert window.link.link is source
        assert window.video_panel.link is window.link
        for widget in (
            window.velocity_panel,
            window.max_panel,
            window.joint_panel.targets_panel,
            window.velocity_panel.connect_button,
            window.velocity_panel.stop_button,
        ):
            assert not widget.isEnabled()
        assert not window.video_panel.controls.bitrate_box.isEnabled()  # it would go to the robot
        assert window.link_status.estop_label.text().startswith("REPLAY")
        assert not window.ros.action.isEnabled()
        assert window.record_button is None
        assert window.key_filter is None

        # No link exists and a key drives nothing: the model stays still, nothing is sent.
        command_before = source.command
        QTest.keyPress(window, Qt.Key.Key_W)
        assert window.model.held_keys == frozenset()
        assert window.model.velocities() == {}
        QTest.keyRelease(window, Qt.Key.Key_W)
        assert source.command == command_before
        assert window.link.read_only
        assert not [t for t in threading.enumerate() if t.name == "ocu-link"]

        # Played, it shows what was recorded: the waist where the recorded robot stood.
        table = window.joint_panel.table

        def waist_shown() -> str | None:
            rows = (r for r in range(table.rowCount()) if table.cell_text(r, "joint") == "waist")
            return next((table.cell_text(r, "angle °") for r in rows), None)

        assert waist_shown() is None  # nothing before the replay plays
        source.play()
        expected = f"{math.degrees(WAIST_RAD):.2f}"
        qtbot.waitUntil(lambda: waist_shown() == expected, timeout=DEADLINE_MS)
        qtbot.waitUntil(
            lambda: window.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS
        )
    finally:
        window.shutdown()
        QApplication.processEvents()


def test_ocu_replay_runs_and_quits_by_itself(recorded_session: Path, tmp_path: Path) -> None:
    result = run_ocu(tmp_path, "--replay", str(recorded_session), "--quit-after", "1.5")
    assert result.returncode == 0, result.stderr
    assert "replay started" in result.stderr
    assert qt_complaints(result.stderr) == []
    missing = run_ocu(tmp_path, "--replay", str(tmp_path / "gone.mcap"), "--quit-after", "1")
    assert missing.returncode == 1
    assert "gone.mcap" in missing.stderr
    assert "Traceback" not in missing.stderr
    both = run_ocu(tmp_path, "--replay", str(recorded_session), "--robot", "127.0.0.1")
    assert both.returncode == 2
    assert "--replay" in both.stderr
