"""`ocu-ros _profile:=xarm1s` against a real roscore: the xArm in ROS (issue 23, item 3).

The xArm simulator runs in this process on a pseudo-terminal and the node opens it as its
serial device (`_robot:=/dev/pts/N`): what the servos received is read from the simulator;
the board's battery is on /diagnostics.
"""

from __future__ import annotations

import math
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
        goals.publish(JointState(name=["base"], position=[math.radians(20.0)]))
        arm = load_xarm_profile("xarm1s")
        target_units = arm.raw_units(arm.joint("base"), math.radians(20.0))
        assert wait_for(
            lambda: (
                abs(board.snapshot().positions[BASE] - target_units) < 3.0
                and abs(board.snapshot().velocities[BASE]) < 1.0
            ),
            30.0,
        ), board.snapshot()
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
