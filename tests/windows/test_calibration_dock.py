"""The Calibration dock: `ocu calibrate` from the console, against scrambled simulators."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import pytest
from PySide6.QtCore import QEvent, QSettings, Qt
from PySide6.QtGui import QKeyEvent
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication
from pytestqt.qtbot import QtBot

from ocu.console.model import ConsoleModel
from ocu.link.base import Link
from ocu.link.live import UdpLink
from ocu.profile import RobotProfile, load_profile
from ocu.records import LinkState
from ocu.sim.simulator import RobotSimulator
from ocu.windows.calibration import FROM_ENTRY, CalibrationPanel, DeadmanKey, Question
from ocu.windows.main_window import MainWindow
from tests.calibrate.scrambled import scrambled_truth
from tests.windows.console_fixtures import DEADLINE_MS, is_zero

RUN_MS = 150_000


@pytest.fixture
def scrambled() -> Iterator[tuple[RobotProfile, RobotSimulator]]:
    """A scrambled robot at 20 Hz telemetry, no video."""
    truth = scrambled_truth(2)
    with RobotSimulator(truth, telemetry_hz=20.0, video_fps=0.0) as sim:
        yield truth, sim


def _console(
    qtbot: QtBot, profile: RobotProfile, settings: QSettings, sim: RobotSimulator
) -> MainWindow:
    def link() -> Link:
        return UdpLink(profile, sim.address)

    window = MainWindow(
        profile,
        link,
        "simulator",
        settings,
        calibration_link=lambda raw: UdpLink(raw, sim.address, extension=False),
    )
    qtbot.addWidget(window)
    window.show()
    window.activateWindow()
    qtbot.waitUntil(window.isActiveWindow, timeout=DEADLINE_MS)
    qtbot.waitUntil(lambda: window.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS)
    window.calibration_dock.show()
    window.calibration_dock.raise_()
    return window


def test_on_a_stand_the_dock_recovers_the_robot_and_writes_the_profile(
    qtbot: QtBot,
    profile: RobotProfile,
    settings: QSettings,
    tmp_path: Path,
    scrambled: tuple[RobotProfile, RobotSimulator],
) -> None:
    truth, sim = scrambled
    window = _console(qtbot, profile, settings, sim)
    panel = window.calibration_panel
    out = tmp_path / "calibrated.toml"
    panel.out_edit.setText(str(out))
    panel.on_stand.setChecked(True)
    try:
        with qtbot.waitSignal(panel.finished, timeout=RUN_MS):
            assert panel.start()
            assert window.link is None  # the console let go of the robot
            window.model.set_connected(True)  # Connect pressed meanwhile: not while it runs
            assert window.link is None
        assert panel.result is not None
        assert panel.result.aborted is None
        assert panel.written == out
        found = load_profile(out)
        for name, channel in truth.channels.items():
            assert found.channels[name].axis == channel.axis, name
            assert found.channels[name].axis_sign == channel.axis_sign, name
        for name, motor in truth.motors.items():
            if motor.channel is not None and motor.ticks_per_rad is not None:
                assert found.motors[name].ticks_per_rad == pytest.approx(
                    motor.ticks_per_rad, rel=0.02
                ), name
        steps = [panel.steps.item(i).text() for i in range(panel.steps.count())]
        assert any(s.startswith("Axis map") for s in steps), steps
        assert f"Wrote {out}" in panel.status.text()
        # The console connects again when the calibration ends.
        qtbot.waitUntil(
            lambda: window.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS
        )
    finally:
        window.shutdown()
        QApplication.processEvents()


def _wait_question(qtbot: QtBot, panel: CalibrationPanel) -> Question:
    qtbot.waitUntil(lambda: panel._question is not None, timeout=DEADLINE_MS * 3)
    assert panel._question is not None
    return panel._question


def test_guided_the_robot_moves_only_with_the_deadman_and_space_stops_it(
    qtbot: QtBot,
    profile: RobotProfile,
    settings: QSettings,
    tmp_path: Path,
    scrambled: tuple[RobotProfile, RobotSimulator],
) -> None:
    _truth, sim = scrambled
    window = _console(qtbot, profile, settings, sim)
    panel = window.calibration_panel
    out = tmp_path / "calibrated.toml"
    panel.out_edit.setText(str(out))
    try:
        assert panel.start()
        # Each step is shown and confirmed: the zero pose, then the axis map.
        question = _wait_question(qtbot, panel)
        assert question.text.startswith("Zero offsets")
        assert panel.answer(True)
        question = _wait_question(qtbot, panel)
        assert question.text.startswith("Axis map")
        before = len(sim.received_commands())
        assert panel.answer(True)
        # Nothing moves while the deadman is not held.
        qtbot.waitUntil(
            lambda: any("deadman released" in panel.steps.item(i).text()
                        for i in range(panel.steps.count())),
            timeout=DEADLINE_MS,
        )  # fmt: skip
        assert all(is_zero(rcp) for rcp in sim.received_commands()[before:])
        # Held with the mouse, the scan pulses the axes.
        QTest.mousePress(panel.deadman_button, Qt.MouseButton.LeftButton)
        qtbot.waitUntil(
            lambda: any(not is_zero(r) for r in sim.received_commands()[before:]),
            timeout=DEADLINE_MS,
        )
        # Which joint a device is: the 3D model's ghost turns the joint the profile says.
        qtbot.waitUntil(
            lambda: panel._question is not None and "Which joint" in panel._question.text,
            timeout=RUN_MS // 4,
        )
        asked = panel._question
        assert asked is not None
        assert asked.joint is not None
        assert window.model_view.ghost_targets == {asked.joint: pytest.approx(math.radians(30))}
        assert panel.answer(FROM_ENTRY)  # the profile's joint, as the list proposes
        assert window.model_view.ghost_targets == {}
        moving_from = len(sim.received_commands())
        qtbot.waitUntil(
            lambda: any(not is_zero(r) for r in sim.received_commands()[moving_from:]),
            timeout=DEADLINE_MS,
        )
        with qtbot.waitSignal(panel.finished, timeout=DEADLINE_MS):
            QTest.keyClick(window.velocity_panel, Qt.Key.Key_Space)
        QTest.mouseRelease(panel.deadman_button, Qt.MouseButton.LeftButton)
        assert panel.result is not None
        assert panel.result.aborted == "Space"
        assert not out.exists()
        assert "STOPPED: Space" in panel.status.text()
        # Zeros are the last thing the robot got, and it stands still.
        received = sim.received_commands()
        assert is_zero(received[-1])
        qtbot.waitUntil(lambda: sim.state().all_stopped, timeout=DEADLINE_MS)
    finally:
        window.shutdown()
        QApplication.processEvents()


def test_answers_are_checked_and_ctrl_holds_the_deadman_until_the_keyboard_goes(
    qtbot: QtBot, profile: RobotProfile
) -> None:
    model = ConsoleModel(profile)
    shown: list[str | None] = []
    panel = CalibrationPanel(model, None, Path("unused.toml"), show_joint=shown.append)
    qtbot.addWidget(panel)
    assert not panel.start_button.isEnabled()  # no robot to calibrate (a replay)
    # A typed number must be a positive number; the calibrator gets it as one.
    question = Question("How many degrees?", [("Use my angle", FROM_ENTRY)], entry="number")
    panel._on_asked(question)
    panel.entry.setText("eight")
    assert not panel.answer(FROM_ENTRY)
    assert "Not a positive number: 'eight'" in panel.question_label.text()
    assert question.answer.empty()
    panel.entry.setText("8.1")
    assert panel.answer(FROM_ENTRY)
    assert question.answer.get_nowait() == pytest.approx(8.1)
    # The joint asked about is shown, then the one picked, then nothing.
    question = Question(
        "Which joint moved?",
        [("That one", FROM_ENTRY)],
        entry="choice",
        choices=["shoulder", "elbow"],
        default="shoulder",
        joint="shoulder",
    )
    panel._on_asked(question)
    panel.choice.setCurrentText("elbow")
    assert panel.answer(FROM_ENTRY)
    assert question.answer.get_nowait() == "elbow"
    assert shown == ["shoulder", "elbow", None]
    # Ctrl held anywhere holds the deadman; its release, or the keyboard going, lets go.
    key = DeadmanKey(panel.deadman)
    press = QKeyEvent(QEvent.Type.KeyPress, Qt.Key.Key_Control, Qt.KeyboardModifier.NoModifier)
    release = QKeyEvent(QEvent.Type.KeyRelease, Qt.Key.Key_Control, Qt.KeyboardModifier.NoModifier)
    assert not key.eventFilter(panel, press)  # never consumed
    assert panel.deadman.held()
    key.eventFilter(panel, release)
    assert not panel.deadman.held()
    key.eventFilter(panel, press)
    key.eventFilter(panel, QEvent(QEvent.Type.ApplicationDeactivate))
    assert not panel.deadman.held()
