"""The arm's ROS topics on the `ocu-ros` node, a real roscore and the simulator over a 50 ms
link: a pose goal reached within 5 mm, tool0 on arm/tool_pose and /tf, a stored pose by name,
and a streamed twist that stops 0.1 s after its last message (read from what the simulator
received)."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from ocu.kinematics.arm import ArmKinematics, ToolPose
from ocu.model.urdf import load_urdf
from ocu.profile import RobotProfile
from ocu.ros.convert import quaternion_xyzw, rotation_of
from ocu.ros.master import RosMaster
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator, SimState
from tests.ros.conftest import ROSPY_WARNINGS, Collector, NodeProcess, needs_ros

pytestmark = [pytest.mark.slow, *ROSPY_WARNINGS]

ARM = ("waist", "shoulder", "elbow", "neck")


@pytest.fixture(scope="module")
def kinematics(profile: RobotProfile) -> ArmKinematics:
    assert profile.arm is not None
    return ArmKinematics(load_urdf(meshes=False), profile.arm)


@pytest.fixture(scope="module")
def sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    needs_ros()
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


@pytest.fixture(scope="module")
def publishers(ros_client: None) -> Iterator[dict[str, Any]]:
    import rospy
    from geometry_msgs.msg import PoseStamped, TwistStamped
    from std_msgs.msg import String

    made = {
        "pose": rospy.Publisher("arm/pose_goal", PoseStamped, queue_size=10),
        "twist": rospy.Publisher("arm/twist_cmd", TwistStamped, queue_size=10),
        "named": rospy.Publisher("arm/named_pose", String, queue_size=10),
    }
    yield made
    for publisher in made.values():
        publisher.unregister()


@pytest.fixture(scope="module")
def node(
    ros_master: RosMaster,
    sim: RobotSimulator,
    publishers: dict[str, Any],
    tmp_path_factory: pytest.TempPathFactory,
) -> Iterator[NodeProcess]:
    folder = tmp_path_factory.mktemp("arm_node")
    process = NodeProcess(folder, sim.address, f"_arm_poses:={folder / 'arm_poses.toml'}")
    try:
        for publisher in publishers.values():
            process.wait_connected(publisher)
        yield process
    finally:
        code = process.stop()
        assert code == 0, process.output()


def truth(kinematics: ArmKinematics, state: SimState) -> ToolPose:
    return kinematics.tool_pose(kinematics.vector(state.joints_rad))


def arm_still(state: SimState) -> bool:
    return all(state.velocities[joint] == 0.0 for joint in ARM)


def test_pose_goal_reaches_and_tool_pose_and_tf_follow(
    sim: RobotSimulator,
    node: NodeProcess,
    publishers: dict[str, Any],
    kinematics: ArmKinematics,
) -> None:
    from geometry_msgs.msg import PoseStamped
    from tf2_msgs.msg import TFMessage

    tool_poses = Collector("arm/tool_pose", PoseStamped)
    transforms = Collector("/tf", TFMessage)
    try:
        tool_poses.wait_connected(node.name)
        tool_poses.wait(lambda m: True)  # the node has readings of the arm
        goal = PoseStamped()
        goal.header.frame_id = "base_link"
        goal.pose.position.x, goal.pose.position.y, goal.pose.position.z = 0.45, -0.3, 0.5
        # ROS's pitch about y is the negative of the arm's: x axis 30° below the horizontal,
        # pointing outward (toward the goal's azimuth).
        azimuth = math.atan2(-0.3, 0.45 + 0.12)
        rotation = rotation_of(0.0, 0.0, math.sin(azimuth / 2), math.cos(azimuth / 2)) @ (
            rotation_of(0.0, math.sin(math.radians(30) / 2), 0.0, math.cos(math.radians(30) / 2))
        )
        orientation = goal.pose.orientation
        orientation.x, orientation.y, orientation.z, orientation.w = quaternion_xyzw(rotation)
        publishers["pose"].publish(goal)
        assert sim.wait_until(lambda s: not arm_still(s), 5.0), node.output()
        assert sim.wait_until(arm_still, 20.0)
        time.sleep(0.2)  # the node confirms with a reading; the simulator is already still
        reached = truth(kinematics, sim.state())
        assert np.linalg.norm(reached.position - np.array([0.45, -0.3, 0.5])) < 0.005
        assert reached.pitch == pytest.approx(math.radians(-30.0), abs=math.radians(0.5))

        # tool0 as published agrees with the simulator's joints (a reading or two after the
        # arm came to rest: the node's last correction may still be on its way).
        def agrees(message: Any) -> bool:
            p = message.pose.position
            now = truth(kinematics, sim.state()).position
            return bool(np.linalg.norm(np.array([p.x, p.y, p.z]) - now) < 0.002)

        message = tool_poses.wait(agrees, after=tool_poses.count())
        assert message.header.frame_id == "base_link"
        tf = transforms.wait(
            lambda m: any(t.child_frame_id == "tool0" for t in m.transforms), after=0
        )
        assert tf.transforms[0].header.frame_id == "base_link"
    finally:
        tool_poses.close()
        transforms.close()


def test_named_pose_and_a_twist_that_stops_after_its_last_message(
    sim: RobotSimulator, node: NodeProcess, publishers: dict[str, Any], kinematics: ArmKinematics
) -> None:
    from geometry_msgs.msg import TwistStamped
    from std_msgs.msg import String

    assert sim.wait_until(arm_still, 20.0)
    publishers["named"].publish(String(data="look_forward"))
    assert sim.wait_until(lambda s: not arm_still(s), 5.0), node.output()
    look_forward = kinematics.vector(kinematics.settings.poses["look_forward"])

    def there(state: SimState) -> bool:
        # Still and at the pose: every joint can be still for a moment on the way - a late
        # control cycle lets the link end each command at its planned end (Command.until),
        # the next cycle goes on (a hog run saw the arm still half way).
        at = np.allclose(kinematics.vector(state.joints_rad), look_forward, atol=0.01)
        return arm_still(state) and bool(at)

    assert sim.wait_until(there, 20.0), (sim.state().joints_rad, node.output())

    start = truth(kinematics, sim.state())
    message = TwistStamped()
    message.header.frame_id = "base_link"
    message.twist.linear.y = 0.05
    last_sent = 0.0
    for _ in range(20):  # 1 s at 20 Hz
        message.header.stamp.secs = 0
        publishers["twist"].publish(message)
        last_sent = time.monotonic()
        time.sleep(0.05)
    assert sim.wait_until(arm_still, 2.0)
    received = sim.received_commands()
    moving = [r for r in received if any(r.packet.axes[sim.profile.channels[j].axis] for j in ARM)]
    assert moving, "the twist never moved the arm"
    last_motion = moving[-1].time_s
    # 0.1 s after the last twist the node stops; the zero then takes 50 ms to the robot.
    assert last_motion - last_sent < 0.1 + 0.05 + 0.1
    moved = truth(kinematics, sim.state()).position - start.position
    assert moved[1] > 0.03  # along +y
    assert abs(moved[0]) < 0.01
    assert abs(moved[2]) < 0.01
