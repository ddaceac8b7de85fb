"""`ocu-ros` runs the console's control core (ocu.core): its "ocu-control" thread, and a
safety rule only the core applies, read at the simulator.

The node runs as a child process (`python -m ocu.ros.node`) against a real roscore and the
robot simulator in this process, like tests/ros/test_node.py.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from ocu.profile import RobotProfile
from ocu.ros.master import RosMaster
from ocu.sim.simulator import RobotSimulator
from tests.ros.conftest import ROSPY_WARNINGS, NodeProcess, needs_ros, wait_for

pytestmark = [pytest.mark.slow, *ROSPY_WARNINGS]

TARGET_RAD = 2.5  # the waist at 0.5 rad/s: five seconds from 0
FREEZE_S = 1.0  # longer than the profile's alive timeout (0.5 s)


@pytest.fixture
def sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    needs_ros()
    simulator = RobotSimulator(profile, telemetry_hz=20.0, video_fps=0.0)
    simulator.start()
    yield simulator
    simulator.stop()


@pytest.fixture
def joint_goals(ros_client: None) -> Iterator[Any]:
    import rospy
    from sensor_msgs.msg import JointState

    publisher = rospy.Publisher("joint_goals", JointState, queue_size=10)
    yield publisher
    publisher.unregister()


def thread_names(pid: int) -> list[str]:
    """The OS's names of a process's threads."""
    names = []
    for comm in Path(f"/proc/{pid}/task").glob("*/comm"):
        with contextlib.suppress(OSError):  # the thread ended meanwhile
            names.append(comm.read_text().strip())
    return names


def test_the_node_runs_the_control_thread(
    ros_master: RosMaster, sim: RobotSimulator, joint_goals: Any, tmp_path: Path
) -> None:
    process = NodeProcess(tmp_path, sim.address)
    try:
        process.wait_connected(joint_goals)
        pid = process.process.pid
        assert wait_for(lambda: "ocu-control" in thread_names(pid), 10.0), thread_names(pid)
        assert "ocu-ros-bridge" in thread_names(pid)
    finally:
        assert process.stop() == 0, process.output()


def test_a_frozen_node_drops_its_joint_goal_instead_of_resuming_it(
    profile: RobotProfile,
    ros_master: RosMaster,
    sim: RobotSimulator,
    joint_goals: Any,
    tmp_path: Path,
) -> None:
    """The core's rule: a control thread silent past the alive timeout halts the model, and
    nothing resumes by itself (ocu/control/mux.md). The bridge's position controller used to
    carry its goal on after the freeze, to the target."""
    from sensor_msgs.msg import JointState

    process = NodeProcess(tmp_path, sim.address)
    pid = process.process.pid
    try:
        process.wait_connected(joint_goals)
        goal = JointState()
        goal.name = ["waist"]
        goal.position = [TARGET_RAD]
        joint_goals.publish(goal)
        assert sim.wait_until(lambda s: s.joints_rad["waist"] > 0.3, 10.0), process.output()
        # The whole node freezes (a swapped-out or stopped process): the robot, not the
        # node, measures how long.
        os.kill(pid, signal.SIGSTOP)
        try:
            frozen_at = sim.state().time_s
            assert sim.wait_until(lambda s: s.time_s > frozen_at + FREEZE_S, 5.0)
        finally:
            os.kill(pid, signal.SIGCONT)
        resumed_at = sim.state().time_s
        # Long enough for the old arrangement to reach the target at 0.5 rad/s.
        assert sim.wait_until(
            lambda s: s.velocities["waist"] == 0.0 and s.time_s > resumed_at + 1.0, 10.0
        )
        count = sim.state().rcp_count
        assert sim.wait_until(lambda s: s.rcp_count >= count + 20, 5.0)
        waist = profile.channels["waist"].axis
        after = [r for r in sim.received_commands() if r.time_s > resumed_at + 1.0]
        assert after
        assert all(r.packet.axes[waist] == 0 for r in after)
        angle = sim.state().joints_rad["waist"]
        assert angle < TARGET_RAD - math.radians(20.0), f"the goal went on to {angle:.2f} rad"
        assert wait_for(lambda: "ROS motion halted" in process.output(), 5.0), process.output()
    finally:
        code = process.stop()
    assert code == 0, process.output()
    # Whichever of the core's freeze rules saw it first after SIGCONT: the link's loop
    # ("link loop frozen"), the control thread's stall watch ("stalled") or the bridge
    # thread's watch ("silent") - each halts the model, and the goal was dropped (above).
    output = process.output()
    assert any(word in output for word in ("frozen", "stalled", "silent")), output
