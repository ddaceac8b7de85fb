"""The arm in the whole console over a 50 ms link: stored poses from F-keys, Cartesian jogs from
held keys, and every automatic arm motion stopped by Space, a lost link and the operator — each
judged by the datagrams the simulator received. Also the Arm dock and the 3D view's helpers.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
from PySide6.QtCore import QPoint, Qt
from PySide6.QtTest import QTest
from pytestqt.qtbot import QtBot

from ocu.console.model import Source
from ocu.profile import RobotProfile
from ocu.records import LinkState
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import ReceivedRcp, RobotSimulator, SimState
from ocu.windows.main_window import MainWindow
from tests.windows.console_fixtures import (
    DEADLINE_MS,
    ConsoleFactory,
    make_console,
    settings,
    wait_sim,
)

__all__ = ["make_console", "settings"]  # fixtures used below

PROMPT_S = 0.35  # a zero must reach the robot this soon (50 ms each way, plus the GUI)
ARM = ("waist", "shoulder", "elbow", "neck")


@pytest.fixture
def slow_sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """The simulator behind 50 ms each way, telemetry at 10 Hz."""
    simulator = RobotSimulator(
        profile, telemetry_hz=10.0, video_fps=0.0, faults=FaultConfig(latency_ms=50.0)
    )
    simulator.start()
    yield simulator
    simulator.stop()


@pytest.fixture
def ready_sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """The same, with the arm in its ready pose."""
    assert profile.arm is not None
    simulator = RobotSimulator(
        profile,
        telemetry_hz=10.0,
        video_fps=0.0,
        faults=FaultConfig(latency_ms=50.0),
        initial_joints=profile.arm.poses["ready"],
    )
    simulator.start()
    yield simulator
    simulator.stop()


def arm_axes(profile: RobotProfile, rcp: ReceivedRcp) -> list[int]:
    return [rcp.packet.axes[profile.channels[name].axis] for name in ARM]


def arm_moving(state: SimState) -> bool:
    return any(state.velocities[name] != 0.0 for name in ARM)


def assert_arm_stopped(
    profile: RobotProfile, sim: RobotSimulator, qtbot: QtBot, since: float, why: str
) -> None:
    """A command with the arm at zero reached the robot promptly, and no arm motion after."""
    wait_sim(qtbot, sim, lambda s: not arm_moving(s), f"arm stopped: {why}")
    received = [r for r in sim.received_commands() if r.time_s >= since]
    zeros = [r for r in received if not any(arm_axes(profile, r))]
    assert zeros, f"no arm-zero command after: {why}"
    assert zeros[0].time_s - since < PROMPT_S, f"zeros late after: {why}"
    QTest.qWait(400)
    later = [r for r in sim.received_commands() if r.time_s > zeros[0].time_s]
    assert not any(any(arm_axes(profile, r)) for r in later), f"the arm moved again after: {why}"


def start_pose(console: MainWindow, sim: RobotSimulator, qtbot: QtBot, key: Qt.Key) -> None:
    QTest.keyClick(console, key)
    wait_sim(qtbot, sim, arm_moving, "the arm moving to a stored pose")
    assert console.model.channel("shoulder").source is Source.ARM


def test_arm_moves_yield_to_space_the_link_and_the_operator(
    make_console: ConsoleFactory, slow_sim: RobotSimulator, profile: RobotProfile, qtbot: QtBot
) -> None:
    sim = slow_sim
    console = make_console(sim, link_lost_after_s=1.0)
    qtbot.waitUntil(lambda: console.model.arm.tool_pose() is not None, timeout=DEADLINE_MS)  # type: ignore[union-attr]
    # Space.
    start_pose(console, sim, qtbot, Qt.Key.Key_F4)
    since = time.monotonic()
    QTest.keyClick(console, Qt.Key.Key_Space)
    assert_arm_stopped(profile, sim, qtbot, since, "Space")
    assert console.model.estopped
    # Another operator input: the gripper key.
    start_pose(console, sim, qtbot, Qt.Key.Key_F3)
    since = time.monotonic()
    QTest.keyPress(console, Qt.Key.Key_T)
    assert_arm_stopped(profile, sim, qtbot, since, "the gripper key")
    wait_sim(qtbot, sim, lambda s: s.velocities["gripper"] > 0.0, "the gripper opening")
    QTest.keyRelease(console, Qt.Key.Key_T)
    # The link lost: the robot's watchdog stops it, the console stops commanding, and after
    # the link comes back nothing resumes.
    start_pose(console, sim, qtbot, Qt.Key.Key_F4)
    sim.cut_link()
    qtbot.waitUntil(lambda: console.link_status.state == LinkState.LOST, timeout=DEADLINE_MS)
    assert console.model.velocities() == {}
    assert console.model.arm.goal is None  # type: ignore[union-attr]
    restored = time.monotonic()
    sim.restore_link()
    qtbot.waitUntil(lambda: console.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS)
    mark = sim.state().rcp_count
    wait_sim(qtbot, sim, lambda s: s.rcp_count >= mark + 3, "RCPs after the link came back")
    assert not any(
        any(arm_axes(profile, r)) for r in sim.received_commands() if r.time_s >= restored
    )


def test_cartesian_jog_from_held_keys_and_release(
    make_console: ConsoleFactory, ready_sim: RobotSimulator, profile: RobotProfile, qtbot: QtBot
) -> None:
    sim = ready_sim
    console = make_console(sim)
    arm = console.model.arm
    assert arm is not None
    qtbot.waitUntil(lambda: arm.tool_pose() is not None, timeout=DEADLINE_MS)
    QTest.keyClick(console, Qt.Key.Key_C)
    assert arm.cartesian
    assert console.arm_indicator.text() == "CARTESIAN · base"
    QTest.keyPress(console, Qt.Key.Key_A)  # left: the waist turns, the chassis does not
    wait_sim(qtbot, sim, lambda s: s.velocities["waist"] > 0.0, "the waist turning")
    assert sim.state().velocities["drive_turn"] == 0.0
    assert console.model_view.overlays()[-1].mesh == "arrow"
    since = time.monotonic()
    QTest.keyRelease(console, Qt.Key.Key_A)
    assert_arm_stopped(profile, sim, qtbot, since, "the key released")
    assert console.arm_panel is not None
    console.arm_panel.refresh()
    assert console.arm_panel.pose_label.text().startswith("tool0: x ")


def test_pose_goal_from_the_dock_and_a_pick_in_the_3d_view(
    make_console: ConsoleFactory, ready_sim: RobotSimulator, qtbot: QtBot
) -> None:
    console = make_console(ready_sim)
    panel, arm = console.arm_panel, console.model.arm
    assert panel is not None
    assert arm is not None
    qtbot.waitUntil(lambda: arm.tool_pose() is not None, timeout=DEADLINE_MS)
    for name, value in (("x", "600"), ("y", "100"), ("z", "500"), ("pitch", "-30")):
        panel.goal_boxes[name].setText(value)
    panel.preview()
    assert arm.goal is not None
    assert not arm.goal.accepted
    assert console.model_view.ghost_targets  # the ghost shows the solution before Accept
    assert "goal" in [o.mesh for o in console.model_view.overlays()]
    panel.goal_boxes["x"].setText("2500")
    panel.preview()
    assert "outside" in panel.message_label.text()
    panel.goal_boxes["x"].setText("1400")
    panel.preview()
    assert "out of reach" in panel.message_label.text()
    # Ctrl+click in the 3D view: x, y at the typed height, previewed at once.
    view = console.model_view
    panel.goal_boxes["z"].setText("400")
    view.pick_height_m = panel.pick_height_m()
    target = view.camera.project([[0.55, -0.2, 0.4]], view.width(), view.height())[0]
    point = QPoint(round(float(target[0])), round(float(target[1])))
    QTest.mouseClick(view, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.ControlModifier, point)
    assert float(panel.goal_boxes["x"].text()) == pytest.approx(550, abs=8)
    assert float(panel.goal_boxes["y"].text()) == pytest.approx(-200, abs=8)
    assert arm.goal is not None
    panel.accept()
    assert arm.goal is not None
    assert arm.goal.accepted
    qtbot.waitUntil(lambda: not arm.controller.active, timeout=15000)
    pose = arm.tool_pose()
    assert pose is not None
    assert pose.x == pytest.approx(0.55, abs=0.01)
    # The workspace from its key.
    QTest.keyClick(console, Qt.Key.Key_I)
    assert view.workspace_visible
    assert "workspace" in [o.mesh for o in view.overlays()]


def test_a_stored_pose_is_refused_while_driving_with_the_reason_in_the_events_dock(
    make_console: ConsoleFactory, ready_sim: RobotSimulator, profile: RobotProfile, qtbot: QtBot
) -> None:
    """The robot does not turn the waist while the chassis moves (issue 19): look back from
    an F-key while W drives is refused, the reason in the Events dock, and no arm motion
    reaches the simulator; stopped, the same key moves the arm."""
    sim = ready_sim
    console = make_console(sim)
    qtbot.waitUntil(lambda: console.model.arm.tool_pose() is not None, timeout=DEADLINE_MS)  # type: ignore[union-attr]
    QTest.keyPress(console, Qt.Key.Key_W)
    wait_sim(qtbot, sim, lambda s: s.velocities["drive_linear"] > 0.0, "the chassis driving")
    since = time.monotonic()
    QTest.keyClick(console, Qt.Key.Key_F5)

    def events() -> list[str]:
        return [console.event_log.item(i).text() for i in range(console.event_log.count())]

    qtbot.waitUntil(
        lambda: any("the chassis is driving" in line and "waist" in line for line in events()),
        timeout=DEADLINE_MS,
    )
    mark = sim.state().rcp_count
    wait_sim(qtbot, sim, lambda s: s.rcp_count >= mark + 3, "RCPs while driving")
    received = [r for r in sim.received_commands() if r.time_s >= since]
    assert received
    assert not any(any(arm_axes(profile, r)) for r in received)
    assert not sim.state().waist_suppressed
    QTest.keyRelease(console, Qt.Key.Key_W)
    wait_sim(qtbot, sim, lambda s: s.velocities["drive_linear"] == 0.0, "the chassis stopped")
    start_pose(console, sim, qtbot, Qt.Key.Key_F5)
    wait_sim(qtbot, sim, lambda s: s.velocities["waist"] != 0.0, "the waist turning")
