"""The Record button: model (Recorder) -> widget, clicks -> files."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import Qt
from PySide6.QtTest import QTest
from pytestqt.qtbot import QtBot

from ocu.profile import RobotProfile
from ocu.qt.record import RecordButton
from ocu.record.reader import Recording
from ocu.record.recorder import Recorder

DEADLINE_MS = 5000


def test_click_records_to_a_new_file_and_click_again_finishes_it(
    qtbot: QtBot, profile: RobotProfile, tmp_path: Path
) -> None:
    recorder = Recorder(profile)
    button = RecordButton(recorder, tmp_path / "recordings")
    qtbot.addWidget(button)
    assert button.text() == "\u25cf Record"
    with qtbot.waitSignal(button.recording_started, timeout=DEADLINE_MS) as started:
        QTest.mouseClick(button, Qt.MouseButton.LeftButton)
    path = Path(started.args[0])
    assert path.parent == tmp_path / "recordings"
    assert path.name.startswith("ocu-")
    assert path.suffix == ".mcap"
    assert button.isChecked()
    assert recorder.recording
    assert button.text().startswith("\u25a0 Stop  REC 00:00")
    with qtbot.waitSignal(button.recording_stopped, timeout=DEADLINE_MS) as stopped:
        QTest.mouseClick(button, Qt.MouseButton.LeftButton)
    assert str(path) in stopped.args[0]
    assert not button.isChecked()
    assert not recorder.recording
    with Recording(path) as recording:
        assert not recording.truncated


def test_unwritable_directory_unchecks_with_a_message(
    qtbot: QtBot, profile: RobotProfile, tmp_path: Path
) -> None:
    blocker = tmp_path / "not-a-directory"
    blocker.write_text("x")
    button = RecordButton(Recorder(profile), blocker)
    qtbot.addWidget(button)
    with qtbot.waitSignal(button.recording_failed, timeout=DEADLINE_MS) as failed:
        QTest.mouseClick(button, Qt.MouseButton.LeftButton)
    assert "cannot record to" in failed.args[0]
    assert not button.isChecked()
    assert button.toolTip() == failed.args[0]


def test_a_write_error_reported_by_the_recorder_unchecks_the_button(
    qtbot: QtBot, profile: RobotProfile, tmp_path: Path
) -> None:
    recorder = Recorder(profile)
    button = RecordButton(recorder, tmp_path)
    qtbot.addWidget(button)
    assert button.start_recording(tmp_path / "x.mcap")
    assert recorder.on_error is not None
    # What the writer thread does on ENOSPC (the error path itself is tested in
    # test_recorder with a real file size limit).
    with qtbot.waitSignal(button.recording_failed, timeout=DEADLINE_MS) as failed:
        recorder.on_error("recording to x.mcap stopped: No space left on device")
    assert "No space left" in failed.args[0]
    assert not button.isChecked()
    assert not recorder.recording
