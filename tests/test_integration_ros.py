"""The console's ROS control toggle: ROS drives while it is on, the operator overrides at once.

rospy allows one node per process, and tests/ros owns this process's node (and shuts it down
when its tests end). The console scenario therefore runs in a pytest child process of its
own: the child collects only the `ros_scenario_*` functions below (`-o python_functions`),
so the main run never collects them, and the parent test fails with the child's output.
The ROS tests start a private `roscore` on a free port, like tests/ros does; they are skipped
(with the packages to install) only when Debian's ROS 1 is absent, and OCU_REQUIRE_ROS=1
turns that skip into a failure.
"""

from __future__ import annotations

import gc
import os
import subprocess
import sys
import time
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from PySide6.QtCore import QSettings, Qt, QTimer
from PySide6.QtTest import QTest
from pytestqt.qtbot import QtBot

from ocu.console.model import ConsoleModel
from ocu.profile import RobotProfile
from ocu.ros.diagnostics import BridgeState
from ocu.ros.environment import missing_ros
from ocu.ros.master import RosMaster, free_port
from ocu.sim.simulator import ReceivedRcp, RobotSimulator
from ocu.windows.main_window import MainWindow
from tests.windows.console_fixtures import (
    DEADLINE_MS,
    ConsoleFactory,
    drive_axis,
    make_console,
    settings,
    sim,
    wait_sim,
)

__all__ = ["make_console", "settings", "sim"]  # fixtures used below

REPO_ROOT = Path(__file__).resolve().parents[1]
ROS_MISSING = missing_ros()
CHILD_FUNCTIONS = "ros_scenario_*"
CHILD_TIMEOUT_S = 100
ROS_DEADLINE_MS = 15_000
PUBLISH_PERIOD_MS = 50  # a planner streaming cmd_vel at 20 Hz
PROMPT_S = 0.3  # the operator's command reaches the robot this soon (loopback)
RCPS_AFTER_OVERRIDE = 6  # ROS keeps publishing meanwhile: none of its commands may follow


def needs_ros() -> None:
    """Skip with the reason when ROS 1 is absent; fail instead with OCU_REQUIRE_ROS=1."""
    if ROS_MISSING is None:
        return
    if os.environ.get("OCU_REQUIRE_ROS") == "1":
        pytest.fail(ROS_MISSING)
    pytest.skip(ROS_MISSING)


# ---- in this process --------------------------------------------------------------------


def test_operator_acted_comes_before_every_operator_input(profile: RobotProfile) -> None:
    model = ConsoleModel(profile)
    seen: list[dict[str, float]] = []
    model.events.operator_acted.connect(lambda: seen.append(model.velocities()))
    model.hotkey_down("W", "drive_linear", 1)
    assert seen == [{}]  # emitted before the key's command exists: ROS lets go first
    model.hotkey_up("W")
    model.set_velocity("waist", 0.1)
    model.set_velocities({"elbow": 0.1})
    model.set_switch("flippers", 1)
    model.set_target("shoulder", 0.2)
    model.emergency_stop("Space")
    assert len(seen) == 6
    model.halt("focus lost")  # stops are not operator input: they override nothing
    model.set_torch(True)
    model.update()
    assert len(seen) == 6


def test_the_console_imports_rospy_only_when_ros_control_starts() -> None:
    code = (
        "import sys, ocu.app, ocu.windows.main_window, ocu.windows.ros_control\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in "
        "('rospy', 'rosgraph', 'geometry_msgs', 'sensor_msgs')))"
    )
    result = subprocess.run(
        [sys.executable, "-c", code],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"


def test_ros_toggle_is_disabled_without_a_master(
    make_console: ConsoleFactory,
    sim: RobotSimulator,
    qtbot: QtBot,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    uri = f"http://127.0.0.1:{free_port()}"
    monkeypatch.setenv("ROS_MASTER_URI", uri)
    console = make_console(sim)
    action = console.ros.action
    reason = "ROS 1 not found" if ROS_MISSING is not None else f"no ROS master at {uri}"
    qtbot.waitUntil(lambda: reason in action.toolTip(), timeout=DEADLINE_MS)
    assert not action.isEnabled()
    assert not action.isChecked()
    action.trigger()  # a disabled action does nothing
    assert console.ros.bridge is None
    assert not console.ros.label.isVisible()
    assert action in console.view_menu.actions()


def test_ros_control_from_the_console(tmp_path: Path) -> None:
    needs_ros()
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-p",
            "no:cacheprovider",
            "-q",
            "-o",
            f"python_functions={CHILD_FUNCTIONS}",
            "--basetemp",
            str(tmp_path / "child"),
            str(Path(__file__).relative_to(REPO_ROOT)),
        ],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=CHILD_TIMEOUT_S,
        check=False,
    )
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    assert "2 passed" in result.stdout, output


# ---- in the child process ---------------------------------------------------------------


@pytest.fixture(scope="module")
def ros_master(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RosMaster]:
    """A private roscore; this process's environment points at it; rospy shut down after."""
    needs_ros()
    master = RosMaster(tmp_path_factory.mktemp("ros"))
    saved = {key: os.environ.get(key) for key in master.env}
    os.environ.update(master.env)
    try:
        yield master
    finally:
        if "rospy" in sys.modules:
            import rospy

            rospy.signal_shutdown("tests finished")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ResourceWarning)
                gc.collect()
        master.stop()
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def turning(profile: RobotProfile, rcp: ReceivedRcp) -> bool:
    return drive_axis(profile, rcp, "drive_turn") != 0


def assert_overridden_at_once(
    console: MainWindow, sim: RobotSimulator, profile: RobotProfile, qtbot: QtBot, since: float
) -> None:
    """The operator's first command arrived promptly and no ROS command came after it."""
    assert console.ros.state is BridgeState.OVERRIDDEN  # synchronous, before anything is sent
    count = sim.state().rcp_count
    wait_sim(qtbot, sim, lambda s: s.rcp_count >= count + RCPS_AFTER_OVERRIDE, "more RCPs")
    after = [r for r in sim.received_commands() if r.time_s >= since]
    first = next(k for k, r in enumerate(after) if not turning(profile, r))
    assert after[first].time_s - since < PROMPT_S
    assert not [r for r in after[first:] if turning(profile, r)], "ROS commanded after"
    qtbot.waitUntil(lambda: not console.ros.action.isChecked(), timeout=DEADLINE_MS)
    assert console.ros.label.text() == "ROS overridden"
    bridge = console.ros.bridge
    assert bridge is not None
    rejected = bridge.core.status().rejected_count
    qtbot.waitUntil(
        lambda: bridge.core.status().rejected_count > rejected + 2, timeout=DEADLINE_MS
    )  # ROS went on publishing all along


# Debian's rospy (Noetic) warns from its own threads and leaves sockets to the collector.
@pytest.mark.filterwarnings("ignore::DeprecationWarning:rospy")
@pytest.mark.filterwarnings("ignore::DeprecationWarning:rosgraph")
@pytest.mark.filterwarnings("ignore::ResourceWarning")
def ros_scenario_toggle_drives_and_the_operator_overrides(
    ros_master: RosMaster,
    make_console: ConsoleFactory,
    sim: RobotSimulator,
    qtbot: QtBot,
    profile: RobotProfile,
) -> None:
    console = make_console(sim)
    ros = console.ros
    action = ros.action

    def state() -> BridgeState:
        return ros.state

    qtbot.waitUntil(action.isEnabled, timeout=ROS_DEADLINE_MS)
    action.trigger()
    assert action.isChecked()
    assert state() is BridgeState.LISTENING
    qtbot.waitUntil(lambda: ros.label.text() == "ROS on · waiting", timeout=DEADLINE_MS)

    import rospy
    from geometry_msgs.msg import Twist
    from sensor_msgs.msg import JointState

    joint_states: list[Any] = []
    subscriber = rospy.Subscriber("joint_states", JointState, joint_states.append)
    publisher = rospy.Publisher("cmd_vel", Twist, queue_size=1)
    twist = Twist()
    twist.angular.z = 0.6
    planner = QTimer()
    planner.setInterval(PUBLISH_PERIOD_MS)
    planner.timeout.connect(lambda: publisher.publish(twist))
    try:
        qtbot.waitUntil(lambda: publisher.get_num_connections() > 0, timeout=ROS_DEADLINE_MS)
        planner.start()
        wait_sim(qtbot, sim, lambda s: s.velocities["drive_turn"] > 0, "ROS turning the robot")
        qtbot.waitUntil(
            lambda: ros.label.text() == "ROS is commanding the robot", timeout=DEADLINE_MS
        )
        assert ros.label.isVisible()
        qtbot.waitUntil(lambda: bool(joint_states), timeout=ROS_DEADLINE_MS)  # the link's

        # The torch is no motion command: it goes out and ROS keeps driving.
        console.velocity_panel.torch_box.setChecked(True)
        wait_sim(qtbot, sim, lambda s: s.torch, "torch on")
        assert state() is BridgeState.COMMANDING
        since = time.monotonic()
        count = sim.state().rcp_count
        wait_sim(qtbot, sim, lambda s: s.rcp_count >= count + 3, "more RCPs")
        assert all(turning(profile, r) for r in sim.received_commands() if r.time_s > since)

        # A key: ROS loses control at once, the key's command goes out instead.
        since = time.monotonic()
        QTest.keyPress(console, Qt.Key.Key_W)
        assert_overridden_at_once(console, sim, profile, qtbot, since)
        wait_sim(qtbot, sim, lambda s: s.velocities["drive_linear"] > 0, "the key drives")
        QTest.keyRelease(console, Qt.Key.Key_W)
        wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped after the release")

        # On again: ROS drives again; Space overrides it with the e-stop.
        action.trigger()
        assert state() is BridgeState.LISTENING
        wait_sim(qtbot, sim, lambda s: s.velocities["drive_turn"] > 0, "ROS turning again")
        since = time.monotonic()
        QTest.keyPress(console, Qt.Key.Key_Space)
        QTest.keyRelease(console, Qt.Key.Key_Space)
        assert console.model.estopped
        assert_overridden_at_once(console, sim, profile, qtbot, since)
        wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped by the e-stop")

        # On, then off by the operator: ROS stops what it moved and lets go.
        action.trigger()
        wait_sim(qtbot, sim, lambda s: s.velocities["drive_turn"] > 0, "ROS turning once more")
        action.trigger()
        assert not action.isChecked()
        assert state() is BridgeState.OFF
        wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped when ROS control went off")
        qtbot.waitUntil(lambda: not ros.label.isVisible(), timeout=DEADLINE_MS)
    finally:
        planner.stop()
        publisher.unregister()
        subscriber.unregister()
        console.shutdown()
    assert state() is BridgeState.OFF


@pytest.mark.filterwarnings("ignore::DeprecationWarning:rospy")
@pytest.mark.filterwarnings("ignore::DeprecationWarning:rosgraph")
@pytest.mark.filterwarnings("ignore::ResourceWarning")
def ros_scenario_an_xarm_pose_goal_through_the_console_is_one_move(
    ros_master: RosMaster, qtbot: QtBot, settings: QSettings
) -> None:
    """The console's ROS control on the xArm (its simulator on a pty, bent): /arm/pose_goal
    goes to the board as ONE move of the four arm servos (the hardware's timed moves, which
    the console's sink passes on), tool0 within 3 mm of the goal."""
    import math

    import numpy as np

    from ocu.hardware.xarm import XARM_CAPABILITIES, ConsoleLinks
    from ocu.hotkeys import load_key_map
    from ocu.profile.xarm import load_xarm_profile
    from ocu.profile.xarm_robot import xarm_robot_profile
    from ocu.records import LinkState
    from ocu.sim.xarm import XarmSimulator

    arm = load_xarm_profile("xarm1s")
    profile = xarm_robot_profile(arm)
    bent = {"shoulder": 30.0, "elbow": 60.0, "wrist_pitch": 40.0}
    initial = {
        arm.joint(n).servo: arm.raw_units(arm.joint(n), math.radians(d)) for n, d in bent.items()
    }
    board = XarmSimulator(arm, initial=initial, seed=2)
    links = ConsoleLinks(arm, profile, board.start())
    console = MainWindow(
        profile,
        links.make_link,
        links.where,
        settings,
        load_key_map(profile),
        hardware_for=links.hardware_for,
        capabilities=XARM_CAPABILITIES,
    )
    qtbot.addWidget(console)
    console.show()

    import rospy
    from geometry_msgs.msg import PoseStamped

    poses: list[Any] = []
    subscriber = rospy.Subscriber("arm/tool_pose", PoseStamped, poses.append)
    goals = rospy.Publisher("arm/pose_goal", PoseStamped, queue_size=1)

    def at_rest() -> bool:
        snapshot = board.snapshot()
        return all(
            abs(snapshot.velocities[s]) < 0.5
            and abs(snapshot.positions[s] - snapshot.setpoints[s]) < 1
            for s in snapshot.positions
        )

    def tool() -> tuple[float, float, float]:
        assert console.model.arm is not None
        positions = board.snapshot().positions
        q = [
            arm.angle_rad(arm.joint(n), positions[arm.joint(n).servo])
            for n in ("base", "shoulder", "elbow", "wrist_pitch")
        ]
        pose = console.model.arm.kinematics.tool_pose(np.array(q))
        return (pose.x, pose.y, pose.z)

    try:
        qtbot.waitUntil(
            lambda: console.link_status.state == LinkState.CONNECTED, timeout=ROS_DEADLINE_MS
        )
        qtbot.waitUntil(console.ros.action.isEnabled, timeout=ROS_DEADLINE_MS)
        console.ros.action.trigger()
        qtbot.waitUntil(lambda: goals.get_num_connections() > 0, timeout=ROS_DEADLINE_MS)
        qtbot.waitUntil(lambda: bool(poses), timeout=ROS_DEADLINE_MS)
        now = poses[-1].pose
        target = (now.position.x - 0.02, now.position.y - 0.03, now.position.z + 0.03)
        goal = PoseStamped()
        goal.header.frame_id = "base_link"
        goal.pose.position.x, goal.pose.position.y, goal.pose.position.z = target
        goal.pose.orientation = now.orientation
        since = board.snapshot().time
        goals.publish(goal)
        qtbot.waitUntil(lambda: bool(board.board.moves_since(since)), timeout=ROS_DEADLINE_MS)
        qtbot.waitUntil(
            lambda: at_rest() and math.dist(tool(), target) < 0.003, timeout=2 * ROS_DEADLINE_MS
        )
        moves = [move for _, move in board.board.moves_since(since)]
        assert len(moves) == 1, moves
        assert {servo for servo, _ in moves[0].positions} == {6, 5, 4, 3}
    finally:
        goals.unregister()
        subscriber.unregister()
        console.shutdown()
        links.close()
        board.stop()
