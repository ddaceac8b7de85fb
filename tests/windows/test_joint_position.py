"""Joint-position window: targets reached in the simulator at 1 Hz telemetry, telemetry view."""

from __future__ import annotations

import math
from collections.abc import Iterator

import pytest
from PySide6.QtCore import Qt
from PySide6.QtTest import QTest
from pytestqt.qtbot import QtBot

from ocu.profile import RobotProfile
from ocu.sim.simulator import RobotSimulator
from ocu.windows.main_window import MainWindow
from tests.windows.console_fixtures import DEADLINE_MS, ConsoleFactory, drive_axis, wait_sim

TARGETS_DEG = {"waist": 25.0, "shoulder": 20.0, "elbow": -30.0, "neck": 15.0}
TOLERANCE_DEG = 1.0
REACH_DEADLINE_MS = 20_000
# What the event log says when a stalled GUI thread stopped every motion (by design).
# The halts a loaded machine may cause, each ending every target (README, "Safety
# behaviour"): the link zeroing for a silent control thread or a frozen loop, the control
# thread's own stall watch.
STALL_HALTS = ("control thread silent", "control thread stalled", "link loop frozen")
MAX_STALL_HALTS = 5


@pytest.fixture
def slow_sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """The simulator at the robot's documented telemetry rate: once per second."""
    simulator = RobotSimulator(profile, telemetry_hz=1.0, video_fps=0.0)
    simulator.start()
    yield simulator
    simulator.stop()


@pytest.fixture
def sim_near_limit(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """The simulator with the shoulder a few degrees below its upper limit (120°)."""
    simulator = RobotSimulator(
        profile, telemetry_hz=10.0, video_fps=0.0, initial_joints={"shoulder": math.radians(112)}
    )
    simulator.start()
    yield simulator
    simulator.stop()


def type_target(console: MainWindow, joint: str, text: str) -> None:
    box = console.joint_panel.boxes[joint]
    box.setFocus()
    box.selectAll()
    QTest.keyClick(box, Qt.Key.Key_Backspace)
    QTest.keyClicks(box, text)


def test_position_control_reaches_four_targets_at_1_hz_without_oscillating(
    make_console: ConsoleFactory, slow_sim: RobotSimulator, profile: RobotProfile, qtbot: QtBot
) -> None:
    console = make_console(slow_sim)
    for joint, angle in TARGETS_DEG.items():
        type_target(console, joint, f"{angle:g}".replace(".", ","))
    QTest.mouseClick(console.joint_panel.accept_button, Qt.MouseButton.LeftButton)
    assert set(console.model.targets) == set(TARGETS_DEG)
    assert console.joint_panel.status_labels["waist"].text() == "→ 25.0°"
    wait_sim(
        qtbot,
        slow_sim,
        lambda s: all(s.velocities[j] != 0 for j in TARGETS_DEG),
        "the four joints moving at once",
    )
    reached: set[str] = set()

    def event_log() -> list[str]:
        return [console.event_log.item(i).text() for i in range(console.event_log.count())]

    def every_end_logged() -> bool:
        # The model's targets are cleared on the control thread; the messages that say why
        # reach the Events dock through the GUI thread's inbox, after (each joint's, or a
        # halt's that ended them all).
        lines = event_log()
        halted = any(word in line for line in lines for word in STALL_HALTS)
        return halted or all(any(f"{j}: " in line for line in lines) for j in TARGETS_DEG)

    for _ in range(MAX_STALL_HALTS + 1):
        qtbot.waitUntil(lambda: not console.model.targets, timeout=REACH_DEADLINE_MS)
        qtbot.waitUntil(every_end_logged, timeout=DEADLINE_MS)
        log = event_log()
        reached = {j for j in TARGETS_DEG if any(f"{j}: reached" in line for line in log)}
        if reached == set(TARGETS_DEG):
            break
        # On a loaded machine the GUI thread may stall past the link's watchdog: every
        # motion then stops, targets included (the README's safety rules), and the operator
        # sends them again. Anything else that ends a target is a failure.
        assert any(word in line for line in log for word in STALL_HALTS), log
        wait_sim(qtbot, slow_sim, lambda s: s.all_stopped, "stopped by the stall")
        for joint in set(TARGETS_DEG) - reached:
            type_target(console, joint, f"{TARGETS_DEG[joint]:g}".replace(".", ","))
        QTest.mouseClick(console.joint_panel.accept_button, Qt.MouseButton.LeftButton)
    assert reached == set(TARGETS_DEG)
    state = wait_sim(qtbot, slow_sim, lambda s: s.all_stopped, "all stopped after reaching")
    for joint, angle in TARGETS_DEG.items():
        assert math.degrees(state.joints_rad[joint]) == pytest.approx(angle, abs=TOLERANCE_DEG)
    # No oscillation: each joint was only ever driven toward its target, never back.
    for joint, angle in TARGETS_DEG.items():
        signs = {
            math.copysign(1, drive_axis(profile, r, joint))
            for r in slow_sim.received_commands()
            if drive_axis(profile, r, joint) != 0
        }
        assert signs == {math.copysign(1, angle)}, joint
    assert console.model.velocities() == {}


def test_manual_command_takes_the_joint_back(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot
) -> None:
    type_target(console, "shoulder", "60")
    type_target(console, "elbow", "60")
    QTest.keyClick(console.joint_panel.boxes["elbow"], Qt.Key.Key_Return)
    wait_sim(qtbot, sim, lambda s: s.velocities["shoulder"] > 0, "shoulder moving to its target")
    console.activateWindow()
    console.velocity_panel.setFocus()
    QTest.keyPress(console, Qt.Key.Key_H)  # shoulder down: manual
    assert set(console.model.targets) == {"elbow"}
    wait_sim(qtbot, sim, lambda s: s.velocities["shoulder"] < 0, "shoulder following the key")
    QTest.keyRelease(console, Qt.Key.Key_H)
    wait_sim(
        qtbot,
        sim,
        lambda s: s.velocities["shoulder"] == 0 and s.velocities["elbow"] > 0,
        "elbow on",
    )
    QTest.mouseClick(console.joint_panel.cancel_button, Qt.MouseButton.LeftButton)
    wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped by Cancel")


def test_bad_targets_are_refused(console: MainWindow, sim: RobotSimulator) -> None:
    type_target(console, "waist", "20")
    type_target(console, "shoulder", "150")  # the shoulder's limit is 120°
    QTest.mouseClick(console.joint_panel.accept_button, Qt.MouseButton.LeftButton)
    message = console.joint_panel.message_label.text()
    assert "Not applied" in message
    assert "outside" in message
    assert console.model.targets == {}
    type_target(console, "shoulder", "1e")
    QTest.mouseClick(console.joint_panel.accept_button, Qt.MouseButton.LeftButton)
    assert "not a number" in console.joint_panel.message_label.text()


def test_every_motor_shown_in_the_table_and_the_plots(console: MainWindow, qtbot: QtBot) -> None:
    panel = console.joint_panel
    qtbot.waitUntil(lambda: panel.plots.sample_count("waist") >= 2, timeout=DEADLINE_MS)
    rows = {panel.table.cell_text(row, "joint") for row in range(panel.table.rowCount())}
    assert rows == set(console.profile.motors)
    assert panel.table.cell_text(0, "state") == "1"
    panel.plots.redraw(force=True)
    xs, _ys = panel.plots.curves[("position", "waist")].getData()
    assert xs is not None
    assert len(xs) >= 2
    assert xs[-1] == 0.0
    xs, _ = panel.plots.curves[("current", "left_track")].getData()
    assert xs is not None
    assert len(xs) >= 2
    assert ("position", "left_track") not in panel.plots.curves  # no position for tracks
    assert all(-console.model.robot.history_s <= x <= 0 for x in xs)


def test_the_limits_themselves_can_be_typed(
    make_console: ConsoleFactory,
    sim_near_limit: RobotSimulator,
    profile: RobotProfile,
    qtbot: QtBot,
) -> None:
    console = make_console(sim_near_limit)
    shoulder = profile.motors["shoulder"]
    assert shoulder.limits_deg == (-10.0, 120.0)
    assert shoulder.limits_rad is not None
    type_target(console, "shoulder", "120")  # radians(120) in degrees is 119.99999999999999
    QTest.keyClick(console.joint_panel.boxes["shoulder"], Qt.Key.Key_Return)
    message = console.joint_panel.message_label.text()
    assert console.model.targets == {"shoulder": shoulder.limits_rad[1]}, message
    state = wait_sim(
        qtbot,
        sim_near_limit,
        lambda s: abs(math.degrees(s.joints_rad["shoulder"]) - 120.0) < 0.5 and s.all_stopped,
        "the shoulder at 120°",
        timeout_ms=REACH_DEADLINE_MS,
    )
    assert math.degrees(state.joints_rad["shoulder"]) <= 120.0
    qtbot.waitUntil(lambda: not console.model.targets, timeout=DEADLINE_MS)
    type_target(console, "shoulder", "-10")
    QTest.keyClick(console.joint_panel.boxes["shoulder"], Qt.Key.Key_Return)
    # Stretched out at -10° the upper arm is in the chassis cameras (by the console's model):
    # refused with the reason, as the arm's own moves are (issue 19).
    message = console.joint_panel.message_label.text()
    assert console.model.targets == {}
    assert "Not applied — the path comes too close" in message
    assert "upper_arm and chassis_cameras" in message
    type_target(console, "shoulder", "")
    neck = profile.motors["neck"]
    assert neck.limits_rad is not None
    type_target(console, "neck", "-90")
    QTest.keyClick(console.joint_panel.boxes["neck"], Qt.Key.Key_Return)
    assert console.model.targets == {"neck": neck.limits_rad[0]}
    assert console.joint_panel.status_labels["neck"].text() == "→ -90.0°"
    QTest.mouseClick(console.joint_panel.cancel_button, Qt.MouseButton.LeftButton)
