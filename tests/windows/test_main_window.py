"""The console window: docks in one window, the layout remembered, the status bar."""

from __future__ import annotations

import re

from PySide6.QtCore import QSettings, Qt
from PySide6.QtWidgets import QLabel, QWidget
from pytestqt.qtbot import QtBot

from ocu.profile import RobotProfile
from ocu.records import LinkState
from ocu.sim.simulator import RobotSimulator
from ocu.windows.main_window import MainWindow
from tests.windows.console_fixtures import DEADLINE_MS, ConsoleFactory

DOCKS = {
    "velocity_dock",
    "max_velocity_dock",
    "joint_position_dock",
    "event_log_dock",
    "model3d_dock",
    "video_dock",
    "arm_dock",
    "gamepad_dock",
    "robot_check_dock",
    "calibration_dock",
    "map_dock",
    "link_dock",
}


def test_console_is_one_window_of_docks(console: MainWindow) -> None:
    assert {dock.objectName() for dock in console.docks()} == DOCKS
    assert all(not dock.isFloating() for dock in console.docks())
    assert console.statusBar().isVisible()
    assert console.link_status.isVisible()
    assert console.link_status.state_label.text() == "CONNECTED"
    assert console.link_status.address_label.text() == "simulator"


def test_layout_is_remembered_between_runs(
    make_console: ConsoleFactory, sim: RobotSimulator, settings: QSettings, qtbot: QtBot
) -> None:
    first = make_console(sim, connected=False)
    first.log_dock.hide()
    first.removeDockWidget(first.max_dock)
    first.addDockWidget(Qt.DockWidgetArea.BottomDockWidgetArea, first.max_dock)
    first.max_dock.show()
    first.close()
    assert settings.value("main_window/state") is not None
    second = make_console(sim, connected=False)
    assert not second.log_dock.isVisible()
    assert second.dockWidgetArea(second.max_dock) == Qt.DockWidgetArea.BottomDockWidgetArea
    # The geometry is saved too (offscreen Qt clips restored sizes to its small screen).
    assert settings.value("main_window/geometry") is not None
    second.reset_layout()
    assert second.log_dock.toggleViewAction().isChecked()
    assert second.dockWidgetArea(second.max_dock) == Qt.DockWidgetArea.LeftDockWidgetArea


def test_status_bar_shows_link_lost_with_the_telemetry_age(
    make_console: ConsoleFactory, sim: RobotSimulator, qtbot: QtBot
) -> None:
    console = make_console(sim, link_lost_after_s=0.5)
    status = console.link_status
    qtbot.waitUntil(lambda: "telemetry 0." in status.age_label.text(), timeout=DEADLINE_MS)
    qtbot.waitUntil(lambda: "—" not in status.rates_label.text(), timeout=DEADLINE_MS)
    assert re.match(r"RCP \d+\.\d Hz · telemetry \d+\.\d Hz", status.rates_label.text())
    assert re.match(r"loss \d+ %", status.loss_label.text())
    sim.cut_link()
    qtbot.waitUntil(lambda: status.state == LinkState.LOST, timeout=DEADLINE_MS)
    assert status.state_label.text() == "LINK LOST"
    assert "#c62828" in status.state_label.styleSheet()
    qtbot.waitUntil(lambda: "telemetry 1." in status.age_label.text(), timeout=DEADLINE_MS)
    sim.restore_link()
    qtbot.waitUntil(lambda: status.state == LinkState.CONNECTED, timeout=DEADLINE_MS)


def test_estop_indicator_follows_the_model(console: MainWindow) -> None:
    label = console.link_status.estop_label
    assert label.text().startswith("STOPPED")
    console.model.set_velocity("waist", 0.1)
    assert label.text().startswith("MOVING")
    console.model.emergency_stop("test")
    assert label.text() == "E-STOP"
    console.model.set_velocity("waist", 0.0)
    assert label.text().startswith("STOPPED")


def test_a_new_console_starts_disconnected_when_asked(
    make_console: ConsoleFactory, sim: RobotSimulator, profile: RobotProfile
) -> None:
    console = make_console(sim, connected=False)
    assert console.link is None
    assert console.velocity_panel.connect_button.text() == "Connect"
    assert sim.state().rcp_count == 0


def fully_shown(label: QLabel, bar: QWidget) -> bool:
    """Whether a label has the width its text needs and lies inside the bar."""
    right = label.mapTo(bar, label.rect().topRight()).x()
    return label.width() >= label.sizeHint().width() and right < bar.width()


def test_the_motion_indicator_is_never_cut_at_1600_px(
    make_console: ConsoleFactory, sim: RobotSimulator, qtbot: QtBot
) -> None:
    console = make_console(sim)  # its Record button shows
    console.resize(1600, 1000)
    qtbot.waitUntil(lambda: console.width() == 1600, timeout=DEADLINE_MS)
    assert console.model.arm is not None
    console.model.arm.toggle_cartesian()
    console.velocity_panel.sliders["neck"].setValue(300)
    status, bar = console.link_status, console.statusBar()
    qtbot.waitUntil(
        lambda: status.estop_label.text() == "MOVING · Space = stop", timeout=DEADLINE_MS
    )
    # Where room is short the address gives way first; the indicators keep their texts.
    labels = (status.estop_label, console.arm_indicator, console.nav_status, console.pad_indicator)
    qtbot.waitUntil(lambda: all(fully_shown(x, bar) for x in labels), timeout=DEADLINE_MS)
    # More to say than there is room for: ROS commanding, an assisted mode stopped.
    console.ros.label.setText("ROS is commanding the robot")
    console.ros.label.show()
    console.nav_status.setText("PATH MODE · stopped: obstacle 0.35 m ahead")
    qtbot.waitUntil(lambda: not fully_shown(console.ros.label, bar), timeout=DEADLINE_MS)
    qtbot.waitUntil(lambda: fully_shown(status.estop_label, bar), timeout=DEADLINE_MS)
    assert fully_shown(console.arm_indicator, bar)
    assert console.ros.label.toolTip().startswith("ROS is commanding the robot")
    console.velocity_panel.sliders["neck"].setValue(0)
