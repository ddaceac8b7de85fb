"""`ocu-ros _profile:=ur5e` against a real roscore: the UR in ROS (issue 22, item 3).

The node runs as a child process (`python -m ocu.ros.node`). Without `_robot` the UR
simulator runs inside it: what the arm did is read from the node's own topics and its log
(the simulator reports the last command it received when it stops). With `_robot` the
simulator runs in this process and is read directly.
"""

from __future__ import annotations

import math
import socket
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from ocu.profile.ur import load_ur_profile
from ocu.ros.master import RosMaster
from ocu.sim.ur import UrSimulator
from tests.ros.conftest import ROSPY_WARNINGS, Collector, NodeProcess, needs_ros, wait_for

pytestmark = [pytest.mark.slow, *ROSPY_WARNINGS]

UR_JOINTS = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
]
#: An operator's stored pose for the UR (degrees), in the console's arm_poses.toml format.
STORED_POSE_DEG = {
    "shoulder_pan_joint": 10.0,
    "shoulder_lift_joint": -80.0,
    "elbow_joint": 80.0,
    "wrist_1_joint": -95.0,
    "wrist_2_joint": -85.0,
    "wrist_3_joint": 5.0,
}
#: At rest: tool0 moved less than this between two packets (50 Hz: 0.5 mm/s).
REST_STEP_M = 1e-5
#: The arm twist's timeout (the UR profile's arm.twist_timeout_s) and what may come on top:
#: the bridge's 50 Hz step, the control thread's 50 Hz cycle, the speedj's braking at the
#: controller's acceleration and the 50 Hz telemetry that shows it, on a loaded machine.
TWIST_TIMEOUT_S = 0.1
TWIST_STOP_MARGIN_S = 0.15


def ur_joint_state(message: Any) -> bool:
    return list(message.name) == UR_JOINTS


@pytest.fixture(scope="module")
def poses_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("ur_poses") / "arm_poses.toml"
    lines = ["[poses.ocu_test_pose]"] + [f"{j} = {v}" for j, v in STORED_POSE_DEG.items()]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def ur_node(
    ros_master: RosMaster,
    ros_client: None,
    poses_file: Path,
    tmp_path_factory: pytest.TempPathFactory,
) -> Iterator[NodeProcess]:
    """`ocu-ros _profile:=ur5e` with no `_robot`: the UR simulator in the node's process."""
    needs_ros()
    import rospy
    from sensor_msgs.msg import JointState

    node = NodeProcess(
        tmp_path_factory.mktemp("ur_node"),
        None,
        "_profile:=ur5e",
        f"_arm_poses:={poses_file}",
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
def joint_states(ur_node: NodeProcess) -> Iterator[Collector]:
    from sensor_msgs.msg import JointState

    collector = Collector("joint_states", JointState)
    collector.wait_connected(ur_node.name)
    collector.wait(ur_joint_state)
    yield collector
    collector.close()


@pytest.fixture(scope="module")
def tool_poses(ur_node: NodeProcess) -> Iterator[Collector]:
    from geometry_msgs.msg import PoseStamped

    collector = Collector("arm/tool_pose", PoseStamped)
    collector.wait_connected(ur_node.name)
    collector.wait(lambda m: True)
    yield collector
    collector.close()


def publisher(node: NodeProcess, topic: str, message_type: Any) -> Any:
    import rospy

    result = rospy.Publisher(topic, message_type, queue_size=10)
    node.wait_connected(result)
    return result


def at_rest(collector: Collector) -> Any:
    """The newest joint state once every joint stands still (the previous command done)."""
    start = collector.count()
    return collector.wait(
        lambda m: ur_joint_state(m) and all(abs(v) < 1e-9 for v in m.velocity),
        20.0,
        after=start,
    )


def positions(message: Any) -> dict[str, float]:
    return dict(zip(message.name, message.position, strict=True))


def test_joint_states_carry_the_ur_joint_names(joint_states: Collector) -> None:
    message = joint_states.wait(ur_joint_state)
    assert list(message.name) == UR_JOINTS
    assert len(message.position) == len(message.velocity) == len(message.effort) == 6
    assert all(math.isfinite(p) for p in message.position)
    # The simulator's start pose (ocu.sim.ur_arm.UrArm), read back over the realtime port.
    assert message.position[1] == pytest.approx(-1.57, abs=1e-3)
    assert abs(message.header.stamp.to_sec() - time.time()) < 5.0


def test_joint_goal_moves_the_ur_joint(ur_node: NodeProcess, joint_states: Collector) -> None:
    from sensor_msgs.msg import JointState

    goals = publisher(ur_node, "joint_goals", JointState)
    try:
        start = positions(at_rest(joint_states))["wrist_1_joint"]
        target = start + 0.3
        goal = JointState()
        goal.name = ["wrist_1_joint"]
        goal.position = [target]
        after = joint_states.count()
        goals.publish(goal)
        moving = joint_states.wait(
            lambda m: ur_joint_state(m) and abs(positions(m)["wrist_1_joint"] - start) > 0.05,
            10.0,
            after=after,
        )
        arrived = joint_states.wait(
            lambda m: (
                ur_joint_state(m)
                and abs(positions(m)["wrist_1_joint"] - target) < math.radians(0.5)
                and all(abs(v) < 1e-9 for v in m.velocity)
            ),
            20.0,
            after=joint_states.messages.index(moving),
        )
    finally:
        goals.unregister()
    # The other joints stayed where they were.
    assert positions(arrived)["elbow_joint"] == pytest.approx(
        positions(moving)["elbow_joint"], abs=1e-4
    )


def test_arm_twist_moves_tool0_and_stops_after_the_last_message(
    ur_node: NodeProcess, joint_states: Collector, tool_poses: Collector
) -> None:
    from geometry_msgs.msg import TwistStamped

    twists = publisher(ur_node, "arm/twist_cmd", TwistStamped)
    try:
        at_rest(joint_states)
        start = tool_poses.messages[-1].pose.position
        message = TwistStamped()
        message.header.frame_id = "base_link"
        message.twist.linear.z = 0.03
        first = tool_poses.count()
        deadline = time.monotonic() + 0.6
        while time.monotonic() < deadline:
            twists.publish(message)
            time.sleep(0.02)  # a 50 Hz publisher's pace, not a synchronisation
        last_sent = time.time()
        # Every tool pose until well after the arm must have stopped.
        tool_poses.wait(lambda m: m.header.stamp.to_sec() > last_sent + 0.8, 10.0, after=first)
    finally:
        twists.unregister()
    poses = list(tool_poses.messages[first:])
    z = [m.pose.position.z for m in poses]
    assert max(z) - start.z > 0.01, "tool0 did not move up"
    # When tool0 last moved: the stamp of the last packet that differs from the one before.
    moved_at = [
        poses[i].header.stamp.to_sec()
        for i in range(1, len(poses))
        if _distance(poses[i - 1].pose.position, poses[i].pose.position) > REST_STEP_M
    ]
    stopped_after_s = moved_at[-1] - last_sent
    assert stopped_after_s <= TWIST_TIMEOUT_S + TWIST_STOP_MARGIN_S, (
        f"tool0 still moved {stopped_after_s:.3f} s after the last twist"
    )
    print(f"tool0 at rest {stopped_after_s * 1e3:.0f} ms after the last twist")


def _distance(a: Any, b: Any) -> float:
    return math.dist((a.x, a.y, a.z), (b.x, b.y, b.z))


def test_pose_goal_moves_tool0_to_the_position(
    ur_node: NodeProcess, joint_states: Collector, tool_poses: Collector
) -> None:
    from geometry_msgs.msg import PoseStamped

    goals = publisher(ur_node, "arm/pose_goal", PoseStamped)
    try:
        at_rest(joint_states)
        now = tool_poses.messages[-1].pose
        target = (now.position.x + 0.04, now.position.y - 0.03, now.position.z - 0.02)
        goal = PoseStamped()
        goal.header.frame_id = "base_link"
        goal.pose.position.x, goal.pose.position.y, goal.pose.position.z = target
        goal.pose.orientation = now.orientation
        after = tool_poses.count()
        goals.publish(goal)
        tool_poses.wait(
            lambda m: (
                math.dist((m.pose.position.x, m.pose.position.y, m.pose.position.z), target) < 0.002
            ),
            20.0,
            after=after,
        )
    finally:
        goals.unregister()


def _quaternion_product(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, ...]:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _angle_between(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    dot = abs(sum(x * y for x, y in zip(a, b, strict=True)))
    return 2.0 * math.acos(min(1.0, dot))


def test_pose_goal_turns_tool0_to_the_whole_orientation(
    ur_node: NodeProcess, joint_states: Collector, tool_poses: Collector
) -> None:
    """Six joints: the goal's whole orientation, not only its pitch (a turn of tool0 about its
    own z axis, which leaves the pitch as it is)."""
    from geometry_msgs.msg import PoseStamped

    goals = publisher(ur_node, "arm/pose_goal", PoseStamped)
    try:
        at_rest(joint_states)
        now = tool_poses.messages[-1].pose
        o = now.orientation
        turn = math.radians(30.0)
        wanted = _quaternion_product(
            (o.x, o.y, o.z, o.w), (0.0, 0.0, math.sin(turn / 2), math.cos(turn / 2))
        )
        target = (now.position.x, now.position.y + 0.02, now.position.z)
        goal = PoseStamped()
        goal.header.frame_id = "base_link"
        goal.pose.position.x, goal.pose.position.y, goal.pose.position.z = target
        q = goal.pose.orientation
        q.x, q.y, q.z, q.w = wanted
        after = tool_poses.count()
        goals.publish(goal)

        def arrived(m: Any) -> bool:
            p, r = m.pose.position, m.pose.orientation
            return math.dist((p.x, p.y, p.z), target) < 0.002 and _angle_between(
                (r.x, r.y, r.z, r.w), wanted
            ) < math.radians(1.0)

        tool_poses.wait(arrived, 20.0, after=after)
    finally:
        goals.unregister()


def test_named_pose_moves_the_arm_to_the_stored_pose(
    ur_node: NodeProcess, joint_states: Collector
) -> None:
    from std_msgs.msg import String

    names = publisher(ur_node, "arm/named_pose", String)
    try:
        at_rest(joint_states)
        after = joint_states.count()
        names.publish(String(data="ocu_test_pose"))
        joint_states.wait(
            lambda m: (
                ur_joint_state(m)
                and all(
                    abs(math.degrees(positions(m)[j]) - deg) < 0.5
                    for j, deg in STORED_POSE_DEG.items()
                )
            ),
            30.0,
            after=after,
        )
    finally:
        names.unregister()


def test_tf_has_base_link_to_tool0(ur_node: NodeProcess, tool_poses: Collector) -> None:
    from tf2_msgs.msg import TFMessage

    tf = Collector("/tf", TFMessage)
    try:
        tf.wait_connected(ur_node.name)
        message = tf.wait(
            lambda m: any(
                t.header.frame_id == "base_link" and t.child_frame_id == "tool0"
                for t in m.transforms
            )
        )
    finally:
        tf.close()
    transform = next(t for t in message.transforms if t.child_frame_id == "tool0")
    # The same tool0 as arm/tool_pose publishes from the same packets.
    stamp = transform.header.stamp
    pose = tool_poses.wait(lambda m: m.header.stamp == stamp, 5.0).pose
    t = transform.transform.translation
    assert (t.x, t.y, t.z) == pytest.approx(
        (pose.position.x, pose.position.y, pose.position.z), abs=1e-9
    )
    # A UR5e's tool0 is within its reach (0.85 m) of base_link.
    assert 0.1 < math.dist((t.x, t.y, t.z), (0.0, 0.0, 0.0)) < 0.9


def test_diagnostics_show_the_robot_and_safety_modes(ur_node: NodeProcess) -> None:
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    diagnostics = Collector("/diagnostics", DiagnosticArray)
    try:
        diagnostics.wait_connected(ur_node.name)
        message = diagnostics.wait(
            lambda m: any(s.name == "ocu: robot controller" for s in m.status), 10.0
        )
    finally:
        diagnostics.close()
    controller = next(s for s in message.status if s.name == "ocu: robot controller")
    values = {kv.key: kv.value for kv in controller.values}
    assert values["robot mode"] == "RUNNING"
    assert values["safety mode"] == "NORMAL"
    assert values["protective stopped"] == values["emergency stopped"] == "false"
    assert controller.level == DiagnosticStatus.OK, controller.message
    assert [s.name for s in message.status][:2] == ["ocu: robot link", "ocu: ROS bridge"]


def test_cmd_vel_is_refused_with_a_diagnostic(
    ur_node: NodeProcess, joint_states: Collector
) -> None:
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Twist

    cmd_vel = publisher(ur_node, "cmd_vel", Twist)
    diagnostics = Collector("/diagnostics", DiagnosticArray)
    try:
        diagnostics.wait_connected(ur_node.name)
        at_rest(joint_states)
        twist = Twist()
        twist.linear.x = 0.3
        twist.angular.z = 0.5
        for _ in range(5):
            cmd_vel.publish(twist)

        def refused(message: Any) -> bool:
            bridge = next((s for s in message.status if s.name == "ocu: ROS bridge"), None)
            if bridge is None:
                return False
            values = {kv.key: kv.value for kv in bridge.values}
            return (
                values.get("cmd_vel", "").startswith("refused")
                and int(values["cmd_vel received"]) >= 1
                and int(values["rejected commands"]) >= 1
            )

        diagnostics.wait(refused, 10.0)
    finally:
        diagnostics.close()
        cmd_vel.unregister()
    assert ur_node.process.poll() is None, ur_node.output()
    # Nothing moved, and the node goes on publishing.
    after = joint_states.count()
    message = joint_states.wait(ur_joint_state, 5.0, after=after)
    assert all(abs(v) < 1e-9 for v in message.velocity)
    assert "cmd_vel rejected: this robot has no chassis" in ur_node.output()


def test_chassis_parameters_are_refused_for_a_ur(ros_master: RosMaster, tmp_path: Path) -> None:
    needs_ros()
    node = NodeProcess(tmp_path, None, "_profile:=ur5e", "_camera:=front", "_max_linear:=0.3")
    try:
        code = node.wait_exit()
    finally:
        node.stop()
    assert code == 2, node.output()
    assert "~max_linear, ~camera: not for a UR arm" in node.output()


def test_sigterm_stops_the_built_in_simulator_with_stopj_last(
    ros_master: RosMaster, ros_client: None, tmp_path: Path
) -> None:
    needs_ros()
    from sensor_msgs.msg import JointState

    node = NodeProcess(tmp_path, None, "_profile:=ur5e")
    goals = publisher(node, "joint_goals", JointState)
    states = Collector("joint_states", JointState)
    try:
        states.wait_connected(node.name)
        start = positions(states.wait(ur_joint_state))["shoulder_pan_joint"]
        goal = JointState(name=["shoulder_pan_joint"], position=[start + 2.0])
        goals.publish(goal)
        # Moving fast when the signal comes.
        states.wait(lambda m: ur_joint_state(m) and abs(m.velocity[0]) > 0.3, 10.0)
        code = node.stop()
    finally:
        states.close()
        goals.unregister()
        node.stop()
    output = node.output()
    assert code == 0, output
    assert "UR simulator stopping: its last command stopj, the arm at rest" in output
    assert output.index("SIGTERM: shutting down") < output.index("UR simulator stopping")


def controller_status(node: NodeProcess, safety_mode: str, level: int) -> None:
    """Wait for the node's /diagnostics to show the controller in this safety mode."""
    from diagnostic_msgs.msg import DiagnosticArray

    def shows(message: Any) -> bool:
        for status in message.status:
            if status.name == "ocu: robot controller":
                values = {kv.key: kv.value for kv in status.values}
                return bool(values["safety mode"] == safety_mode and status.level == level)
        return False

    diagnostics = Collector("/diagnostics", DiagnosticArray)
    try:
        diagnostics.wait_connected(node.name)
        diagnostics.wait(shows, 10.0)
    finally:
        diagnostics.close()


# ---- a UR controller given with _robot ----------------------------------------------------


@pytest.fixture
def controller() -> Iterator[UrSimulator]:
    """The UR simulator in this process on three consecutive free ports (HOST:PORT_BASE)."""
    arm = load_ur_profile("ur5e")
    for _ in range(20):
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            base = probe.getsockname()[1] - 1
        if base + 3 > 65535:
            continue
        simulator = UrSimulator(arm, host="127.0.0.1", ports=(base + 1, base + 2, base + 3))
        try:
            simulator.start()
        except OSError:
            continue
        try:
            yield simulator
        finally:
            simulator.stop()
        return
    pytest.fail("no three consecutive free ports on 127.0.0.1")


def test_ur_controller_with_robot_moves_and_stops_with_stopj(
    ros_master: RosMaster, ros_client: None, controller: UrSimulator, tmp_path: Path
) -> None:
    from diagnostic_msgs.msg import DiagnosticStatus
    from sensor_msgs.msg import JointState

    base = controller.ports["primary"] - 1
    node = NodeProcess(tmp_path, ("127.0.0.1", base), "_profile:=ur5e")
    goals = publisher(node, "joint_goals", JointState)
    try:
        assert wait_for(lambda: controller.snapshot().clients["realtime"] == 1, 20.0)
        start = controller.snapshot().q[2]
        goals.publish(JointState(name=["elbow_joint"], position=[start - 0.25]))
        assert wait_for(
            lambda: (
                abs(controller.snapshot().q[2] - (start - 0.25)) < math.radians(0.5)
                and max(abs(v) for v in controller.snapshot().qd) == 0.0
            ),
            20.0,
        ), controller.snapshot()
        # The controller's emergency stop on /diagnostics, and its release.
        controller.emergency_stop()
        controller_status(node, "ROBOT_EMERGENCY_STOP", DiagnosticStatus.ERROR)
        controller.emergency_stop(False)
        controller_status(node, "NORMAL", DiagnosticStatus.OK)
        # /diagnostics can show the controller's NORMAL before the UR link has acted on it
        # (it logs "ready, nothing resumed" then). A goal sent in between still met the stop
        # (a hog run: the goal came 15 ms before the link's "ready"), so wait for that line.
        assert wait_for(lambda: "safety NORMAL: ready" in node.output(), 10.0), node.output()
        # Moving again when the signal comes: stopj is the last thing the controller hears.
        goals.publish(JointState(name=["elbow_joint"], position=[start + 1.0]))
        assert wait_for(lambda: abs(controller.snapshot().qd[2]) > 0.2, 10.0), (
            f"{controller.snapshot()}\n{node.output()}"
        )
        code = node.stop()
    finally:
        goals.unregister()
        node.stop()
    assert code == 0, node.output()
    assert wait_for(lambda: controller.snapshot().clients["realtime"] == 0, 5.0)
    snapshot = controller.snapshot()
    assert snapshot.last_command == "stopj", snapshot
    assert wait_for(lambda: max(abs(v) for v in controller.snapshot().qd) == 0.0, 5.0)
