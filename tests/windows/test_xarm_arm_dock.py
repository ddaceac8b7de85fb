"""The Arm dock's pose goals and stored poses on the xArm 1S (issue 23, item 3).

Real widgets (offscreen), the real xArm simulator on a pseudo-terminal (in this process,
ocu.hardware.xarm.ConsoleLinks), the "xarm" plug-in over XarmLink. The dock's buttons are
clicked; what is checked is what the SIMULATOR ran: a typed pose goal is ONE move of the
four arm servos with the preview's duration and lands tool0 within 3 mm; a pose saved with
"Save here" is stored in the operator's file, shown with "Show" and gone back to with "Go" as
one move.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
from PySide6.QtCore import QSettings, Qt
from PySide6.QtTest import QTest
from pytestqt.qtbot import QtBot

from ocu.console.arm import ArmGoal
from ocu.hardware.xarm import ConsoleLinks
from ocu.kinematics.arm import ToolPose
from ocu.profile.xarm import XarmProfile
from ocu.protocol.xarm import ServoMove
from ocu.sim.xarm import XarmSimulator
from ocu.windows.arm import ArmPanel
from ocu.windows.main_window import MainWindow
from tests.windows.console_fixtures import DEADLINE_MS
from tests.windows.test_xarm_console import arm, links, xarm_console

__all__ = ["arm", "links", "xarm_console"]  # fixtures used below

ARM_JOINTS = ("base", "shoulder", "elbow", "wrist_pitch")
ARM_SERVOS = {6, 5, 4, 3}
FORWARD = ToolPose(0.20, 0.08, 0.10, math.radians(-30.0))
ASIDE = ToolPose(0.15, -0.12, 0.16, math.radians(-20.0))


def angles(arm_profile: XarmProfile, sim: XarmSimulator) -> np.ndarray:
    positions = sim.snapshot().positions
    return np.array(
        [
            arm_profile.angle_rad(arm_profile.joint(n), positions[arm_profile.joint(n).servo])
            for n in ARM_JOINTS
        ]
    )


def at_rest(sim: XarmSimulator) -> bool:
    """Every shaft still at its setpoint (seed 003's servos ring around it first)."""
    snapshot = sim.snapshot()
    return all(
        abs(snapshot.velocities[s]) < 0.5 and abs(snapshot.positions[s] - snapshot.setpoints[s]) < 1
        for s in snapshot.positions
    )


def click(button: object) -> None:
    QTest.mouseClick(button, Qt.MouseButton.LeftButton)  # type: ignore[call-overload]


def move_and_rest(
    window: MainWindow, sim: XarmSimulator, qtbot: QtBot, *buttons: object
) -> list[ServoMove]:
    """Click `buttons` (Preview and Accept, Go) and wait until the console says it arrived
    and the shafts rest; the moves the simulator ran from the (last) click on. A move the
    console stopped itself (a loaded machine's stale reading) is started again once the
    readings flow, as an operator would."""
    arm = window.model.arm
    assert arm is not None

    def fresh() -> bool:
        # Read each time: with the core in a process of its own the controller comes as a copy.
        position = arm.controller.position
        now = window.model.clock()
        return all(
            (at := position.predictors[j].last_received_at) is not None and now - at < 0.1
            for j in ARM_JOINTS
        )

    def lines(start: int) -> list[str]:
        return [window.event_log.item(i).text() for i in range(start, window.event_log.count())]

    def outcome(start: int) -> str:
        said = [line for line in lines(start) if "arm: reached" in line or "stopped" in line]
        return said[0] if said else ""

    since = 0.0
    for _ in range(4):
        qtbot.waitUntil(fresh, timeout=DEADLINE_MS)
        since, start = sim.snapshot().time, window.event_log.count()
        for button in buttons:
            click(button)
        qtbot.waitUntil(lambda: bool(outcome(start)), timeout=3 * DEADLINE_MS)  # noqa: B023
        if "arm: reached" in outcome(start):
            break
    assert "arm: reached" in outcome(start), lines(start)
    qtbot.waitUntil(lambda: at_rest(sim), timeout=3 * DEADLINE_MS)
    return [move for _, move in sim.board.moves_since(since)]


def pose_goal(window: MainWindow, sim: XarmSimulator, qtbot: QtBot, target: ToolPose) -> float:
    """Type a pose goal in the dock, Preview, Accept: the one move checked; tool0's error."""
    panel = window.arm_panel
    assert isinstance(panel, ArmPanel)
    arm = window.model.arm
    assert arm is not None
    panel.set_goal_boxes(target)
    goals: list[ArmGoal | None] = []
    arm.events.goal_changed.connect(goals.append, direct=True)
    try:
        moves = move_and_rest(window, sim, qtbot, panel.preview_button, panel.accept_button)
    finally:
        arm.events.goal_changed.disconnect(goals.append)
    # The preview showed the goal (a ghost, not accepted), Accept moved there.
    assert any(g is not None and not g.accepted for g in goals)
    duration = [g for g in goals if g is not None and g.accepted][-1].duration_s
    assert len(moves) == 1, moves
    assert {servo for servo, _ in moves[0].positions} == ARM_SERVOS
    assert abs(moves[0].duration_ms - duration * 1000) < 100
    reached = arm.kinematics.tool_pose(angles(sim_arm(window), sim))
    return float(np.linalg.norm(reached.position - np.array(target.position)))


def sim_arm(window: MainWindow) -> XarmProfile:
    from ocu.profile.xarm import load_xarm_profile

    return load_xarm_profile(window.profile.name)


def test_a_pose_goal_typed_in_the_arm_dock_is_one_move_of_the_board(
    xarm_console: MainWindow, links: ConsoleLinks, qtbot: QtBot
) -> None:
    window, sim = xarm_console, links.simulator
    assert sim is not None
    arm = window.model.arm
    assert arm is not None
    qtbot.waitUntil(lambda: arm.tool_pose() is not None, timeout=DEADLINE_MS)
    assert pose_goal(window, sim, qtbot, FORWARD) < 0.003
    panel = window.arm_panel
    assert isinstance(panel, ArmPanel)
    # Out of reach: refused with the reason, nothing sent.
    since = sim.snapshot().time
    panel.set_goal_boxes(ToolPose(0.60, 0.0, 0.10, 0.0))
    click(panel.preview_button)
    assert "out of reach" in panel.message_label.text()
    assert sim.board.moves_since(since) == []


def test_stored_poses_of_the_arm_dock_on_the_xarm(
    xarm_console: MainWindow, links: ConsoleLinks, settings: QSettings, qtbot: QtBot
) -> None:
    window, sim = xarm_console, links.simulator
    assert sim is not None
    arm = window.model.arm
    panel = window.arm_panel
    assert arm is not None
    assert isinstance(panel, ArmPanel)
    qtbot.waitUntil(lambda: arm.tool_pose() is not None, timeout=DEADLINE_MS)
    assert pose_goal(window, sim, qtbot, FORWARD) < 0.003
    saved_at = sim.snapshot().targets
    QTest.keyClicks(panel.name_box, "desk")
    click(panel.save_button)
    assert panel.pose_list.findItems("desk", Qt.MatchFlag.MatchExactly)
    stored = tomllib.loads(Path(arm.poses.path or "").read_text())
    assert "desk" in str(stored)
    assert pose_goal(window, sim, qtbot, ASIDE) < 0.003
    item = panel.pose_list.findItems("desk", Qt.MatchFlag.MatchExactly)[0]
    panel.pose_list.setCurrentItem(item)
    click(panel.show_button)
    assert arm.goal is not None
    assert arm.goal.label == "desk"
    assert not arm.goal.accepted
    moves = move_and_rest(window, sim, qtbot, panel.go_button)
    assert len(moves) == 1, moves
    assert {servo for servo, _ in moves[0].positions} == ARM_SERVOS
    # Back where it was saved: each servo's target within a unit of the one it held then
    # (the pose stores the estimate, which a move's target rounds to a whole unit).
    back = sim.snapshot().targets
    assert all(abs(back[servo] - saved_at[servo]) <= 1 for servo in ARM_SERVOS), (back, saved_at)
    assert str(Path(settings.fileName()).parent) in str(arm.poses.path)
