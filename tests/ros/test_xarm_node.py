"""`ocu-ros _profile:=xarm1s` against a real roscore: the xArm in ROS (issue 23, item 3).

The xArm simulator runs in this process on a pseudo-terminal and the node opens it as its
serial device (`_robot:=/dev/pts/N`): what the servos received is read from the simulator;
the board's battery is on /diagnostics. The arm topics: /arm/twist_cmd streams jog moves
and the servos stop within the twist's timeout and a jog move's time; /arm/pose_goal and
/arm/named_pose are ONE move of the four arm servos (the hardware's timed moves), tool0
within 3 mm of the goal (the true tool0: the simulated shafts through the URDF).
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from ocu.profile.xarm import load_xarm_profile
from ocu.ros.master import RosMaster
from ocu.sim.xarm import XarmSimulator
from tests.ros.conftest import ROSPY_WARNINGS, Collector, NodeProcess, needs_ros, wait_for

pytestmark = [pytest.mark.slow, *ROSPY_WARNINGS]

XARM_JOINTS = ["base", "shoulder", "elbow", "wrist_pitch", "wrist_roll", "gripper"]
BASE = 6  # the base's servo
HALTED = "ROS motion halted"  # the node's log line when a safety stop took ROS's motion


@pytest.fixture
def board() -> Iterator[XarmSimulator]:
    simulator = XarmSimulator(load_xarm_profile("xarm1s"))
    simulator.start()
    yield simulator
    simulator.stop()


def battery_shown(message: Any) -> bool:
    """A /diagnostics message whose link status carries the board's battery (7.4 V)."""
    for status in message.status:
        if status.name == "ocu: robot link":
            return {kv.key: kv.value for kv in status.values}.get("battery") == "7.40 V"
    return False


def test_the_xarm_in_ros_moves_on_a_joint_goal_and_stops_last(
    ros_master: RosMaster, ros_client: None, board: XarmSimulator, tmp_path: Path
) -> None:
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState

    node = NodeProcess(tmp_path, None, "_profile:=xarm1s", f"_robot:={board.path}")
    goals: Any = None
    states = Collector("joint_states", JointState)
    diagnostics = Collector("/diagnostics", DiagnosticArray)
    try:
        import rospy

        goals = rospy.Publisher("joint_goals", JointState, queue_size=10)
        node.wait_connected(goals)
        states.wait_connected(node.name)
        message = states.wait(lambda m: list(m.name) == XARM_JOINTS)
        assert list(message.position) == pytest.approx([0.0] * 6, abs=1e-9)
        diagnostics.wait_connected(node.name)
        diagnostics.wait(battery_shown, 10.0)
        arm = load_xarm_profile("xarm1s")
        target_units = arm.raw_units(arm.joint("base"), math.radians(20.0))

        def arrived() -> bool:
            snapshot = board.snapshot()
            return (
                abs(snapshot.positions[BASE] - target_units) < 3.0
                and abs(snapshot.velocities[BASE]) < 1.0
            )

        # The node halts ROS's motion when a reading or its link loop comes too late (a
        # machine loaded past its limits: "link loop frozen"); a client that sees the halt
        # sends its goal again. Each halt is a safety action, not a failure.
        for _ in range(3):
            halts = node.output().count(HALTED)

            def arrived_or_halted(before: int = halts) -> bool:
                return arrived() or node.output().count(HALTED) > before

            goals.publish(JointState(name=["base"], position=[math.radians(20.0)]))
            wait_for(arrived_or_halted, 30.0)
            if arrived():
                break
        assert arrived(), (board.snapshot(), node.output())
        # The other servos were not told to move.
        assert all(board.snapshot().targets[s] == 500 for s in (1, 2, 3, 4, 5))
        code = node.stop()
    finally:
        if goals is not None:
            goals.unregister()
        states.close()
        diagnostics.close()
        node.stop()
    assert code == 0, node.output()
    assert "link shut down, the stop move sent last" in node.output()


def test_chassis_parameters_are_refused_for_the_xarm(ros_master: RosMaster, tmp_path: Path) -> None:
    needs_ros()
    node = NodeProcess(tmp_path, None, "_profile:=xarm1s", "_max_linear:=0.3")
    try:
        code = node.wait_exit()
    finally:
        node.stop()
    assert code == 2, node.output()
    assert "~max_linear: not for an xArm" in node.output()


# ---- the arm topics on the xArm: /arm/twist_cmd, /arm/pose_goal, /arm/named_pose -----------

ARM_JOINTS = ("base", "shoulder", "elbow", "wrist_pitch")
#: A bent start (URDF angles, degrees), away from the straight-up singularity.
START_DEG = {"base": 0.0, "shoulder": 30.0, "elbow": 60.0, "wrist_pitch": 40.0}
#: An operator's stored pose (degrees), in the console's arm_poses.toml format.
STORED_POSE_DEG = {"base": 15.0, "shoulder": 20.0, "elbow": 70.0, "wrist_pitch": 30.0}


@pytest.fixture(scope="module")
def bent_board() -> Iterator[XarmSimulator]:
    arm = load_xarm_profile("xarm1s")
    initial = {
        arm.joint(n).servo: arm.raw_units(arm.joint(n), math.radians(d))
        for n, d in START_DEG.items()
    }
    simulator = XarmSimulator(arm, initial=initial, seed=3)
    simulator.start()
    yield simulator
    simulator.stop()


@pytest.fixture(scope="module")
def xarm_node(
    ros_master: RosMaster,
    ros_client: None,
    bent_board: XarmSimulator,
    tmp_path_factory: pytest.TempPathFactory,
) -> Iterator[NodeProcess]:
    needs_ros()
    import rospy
    from sensor_msgs.msg import JointState

    work = tmp_path_factory.mktemp("xarm_node")
    poses = work / "arm_poses.toml"
    lines = ["[poses.ocu_test_pose]"] + [f"{j} = {v}" for j, v in STORED_POSE_DEG.items()]
    poses.write_text("\n".join(lines) + "\n", encoding="utf-8")
    node = NodeProcess(
        work, None, "_profile:=xarm1s", f"_robot:={bent_board.path}", f"_arm_poses:={poses}"
    )
    probe = rospy.Publisher("joint_goals", JointState, queue_size=1)
    try:
        node.wait_connected(probe)
        yield node
    finally:
        probe.unregister()
        code = node.stop()
        assert code == 0, node.output()


@pytest.fixture(scope="module")
def tool_poses(xarm_node: NodeProcess) -> Iterator[Collector]:
    from geometry_msgs.msg import PoseStamped

    collector = Collector("arm/tool_pose", PoseStamped)
    collector.wait_connected(xarm_node.name)
    collector.wait(lambda m: True)
    yield collector
    collector.close()


def publisher(node: NodeProcess, topic: str, message_type: Any) -> Any:
    import rospy

    result = rospy.Publisher(topic, message_type, queue_size=10)
    node.wait_connected(result)
    return result


def board_at_rest(board: XarmSimulator) -> bool:
    """Every shaft still at its setpoint (seed 003's servos ring around it first)."""
    snapshot = board.snapshot()
    return all(
        abs(snapshot.velocities[s]) < 0.5 and abs(snapshot.positions[s] - snapshot.setpoints[s]) < 1
        for s in snapshot.positions
    )


def board_angles(board: XarmSimulator) -> dict[str, float]:
    arm = load_xarm_profile("xarm1s")
    positions = board.snapshot().positions
    return {n: arm.angle_rad(arm.joint(n), positions[arm.joint(n).servo]) for n in ARM_JOINTS}


def true_tool(board: XarmSimulator) -> tuple[float, float, float]:
    """tool0 from the simulated shafts through the xArm's URDF (the console's kinematics)."""
    import numpy as np

    from ocu.kinematics.arm import ArmKinematics
    from ocu.model.urdf import load_urdf
    from ocu.profile.xarm_robot import xarm_robot_profile

    profile = xarm_robot_profile(load_xarm_profile("xarm1s"))
    assert profile.arm is not None
    kinematics = ArmKinematics(load_urdf(profile.urdf, meshes=False), profile.arm)
    angles = board_angles(board)
    pose = kinematics.tool_pose(np.array([angles[n] for n in ARM_JOINTS]))
    return (pose.x, pose.y, pose.z)


def test_arm_twist_on_the_xarm_moves_tool0_and_the_servos_stop_after_the_last(
    xarm_node: NodeProcess, bent_board: XarmSimulator, tool_poses: Collector
) -> None:
    from geometry_msgs.msg import TwistStamped

    twists = publisher(xarm_node, "arm/twist_cmd", TwistStamped)
    try:
        assert wait_for(lambda: board_at_rest(bent_board), 20.0)
        start = true_tool(bent_board)
        message = TwistStamped()
        message.header.frame_id = "base_link"
        message.twist.linear.z = 0.03
        deadline = time.monotonic() + 0.6
        while time.monotonic() < deadline:
            twists.publish(message)
            time.sleep(0.02)  # a 50 Hz publisher's pace, not a synchronisation
        last_sent = time.monotonic()
        assert wait_for(lambda: board_at_rest(bent_board), 20.0)
    finally:
        twists.unregister()
    assert true_tool(bent_board)[2] - start[2] > 0.008, "tool0 did not move up"
    # The last move the board received that goes anywhere: within the twist's timeout
    # (0.1 s) of the last twist; its 150 ms is all the servos run on after it.
    moves = [(t, m) for t, m in bent_board.board.moves_since(last_sent - 1.0) if m.duration_ms]
    assert moves
    last_at, last = moves[-1]
    # (0.4 s of margin: the node, another process, hears the twists late on a loaded machine.)
    assert last_at - last_sent < 0.1 + 0.4, f"a move {last_at - last_sent:.3f} s after"
    assert last.duration_ms == 150


def test_pose_goal_on_the_xarm_moves_tool0_there(
    xarm_node: NodeProcess, bent_board: XarmSimulator, tool_poses: Collector
) -> None:
    from geometry_msgs.msg import PoseStamped

    goals = publisher(xarm_node, "arm/pose_goal", PoseStamped)
    try:
        assert wait_for(lambda: board_at_rest(bent_board), 20.0)
        now = tool_poses.messages[-1].pose
        target = (now.position.x - 0.02, now.position.y - 0.03, now.position.z + 0.03)
        goal = PoseStamped()
        goal.header.frame_id = "base_link"
        goal.pose.position.x, goal.pose.position.y, goal.pose.position.z = target
        goal.pose.orientation = now.orientation  # the same pitch
        since = bent_board.snapshot().time
        goals.publish(goal)
        assert wait_for(lambda: bool(bent_board.board.moves_since(since)), 10.0), xarm_node.output()
        assert wait_for(
            lambda: board_at_rest(bent_board) and math.dist(true_tool(bent_board), target) < 0.003,
            30.0,
        ), (true_tool(bent_board), target)
    finally:
        goals.unregister()
    # ONE move of the four arm servos (the hardware's timed moves), nothing streamed.
    moves = [m for _, m in bent_board.board.moves_since(since)]
    assert len(moves) == 1, moves
    assert {servo for servo, _ in moves[0].positions} == {6, 5, 4, 3}
    off_mm = math.dist(true_tool(bent_board), target) * 1e3
    print(f"pose goal: one move of {moves[0].duration_ms} ms, tool0 {off_mm:.2f} mm off")


def test_named_pose_moves_the_xarm_to_the_stored_pose(
    xarm_node: NodeProcess, bent_board: XarmSimulator
) -> None:
    from std_msgs.msg import String

    names = publisher(xarm_node, "arm/named_pose", String)
    unit_deg = 240.0 / 1000.0
    try:
        assert wait_for(lambda: board_at_rest(bent_board), 20.0)
        since = bent_board.snapshot().time
        names.publish(String(data="ocu_test_pose"))
        assert wait_for(
            lambda: (
                board_at_rest(bent_board)
                and all(
                    abs(math.degrees(board_angles(bent_board)[j]) - deg) <= 1.5 * unit_deg
                    for j, deg in STORED_POSE_DEG.items()
                )
            ),
            30.0,
        ), board_angles(bent_board)
    finally:
        names.unregister()
    moves = [m for _, m in bent_board.board.moves_since(since)]
    assert len(moves) == 1, moves
