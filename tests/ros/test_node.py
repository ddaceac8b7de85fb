"""The `ocu-ros` node against a real roscore and the robot simulator in this process.

The node runs as a child process (`python -m ocu.ros.node`); this process publishes and
subscribes with rospy and reads what the simulator received.
"""

from __future__ import annotations

import importlib
import math
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from ocu.profile import RobotProfile
from ocu.ros.master import RosMaster
from ocu.sim.simulator import ReceivedRcp, RobotSimulator, SimState
from tests.ros.conftest import ROSPY_WARNINGS, Collector, NodeProcess, needs_ros, wait_for

pytestmark = [pytest.mark.slow, *ROSPY_WARNINGS]

INITIAL_JOINTS = {"waist": 0.3, "shoulder": 0.5, "elbow": -0.4, "neck": 0.2, "flippers": -0.1}
TICK_RAD = 1.0 / 10430.378  # one telemetry tick of the profile's joints


def twist(linear_x: float = 0.0, angular_z: float = 0.0) -> Any:
    from geometry_msgs.msg import Twist

    message = Twist()
    message.linear.x = linear_x
    message.angular.z = angular_z
    return message


def axis(profile: RobotProfile, rcp: ReceivedRcp, channel: str) -> int:
    return rcp.packet.axes[profile.channels[channel].axis]


def axis_for(profile: RobotProfile, channel: str, value: float) -> int:
    return round(value * profile.channels[channel].axis_per_unit)


def drive_stopped(state: SimState) -> bool:
    return (
        state.commanded_velocities["drive_linear"] == 0.0
        and state.commanded_velocities["drive_turn"] == 0.0
    )


@pytest.fixture(scope="module")
def sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    needs_ros()
    simulator = RobotSimulator(
        profile, telemetry_hz=20.0, video_fps=5.0, initial_joints=INITIAL_JOINTS
    )
    simulator.start()
    yield simulator
    simulator.stop()


@pytest.fixture(scope="module")
def cmd_vel(ros_client: None) -> Iterator[Any]:
    import rospy
    from geometry_msgs.msg import Twist

    publisher = rospy.Publisher("cmd_vel", Twist, queue_size=10)
    yield publisher
    publisher.unregister()


@pytest.fixture(scope="module")
def joint_goals(ros_client: None) -> Iterator[Any]:
    import rospy
    from sensor_msgs.msg import JointState

    publisher = rospy.Publisher("joint_goals", JointState, queue_size=10)
    yield publisher
    publisher.unregister()


@pytest.fixture(scope="module")
def node(
    ros_master: RosMaster,
    sim: RobotSimulator,
    cmd_vel: Any,
    joint_goals: Any,
    tmp_path_factory: pytest.TempPathFactory,
) -> Iterator[NodeProcess]:
    """One node shared by the tests that do not stop it."""
    process = NodeProcess(tmp_path_factory.mktemp("node"), sim.address, "_camera:=zoom")
    try:
        process.wait_connected(cmd_vel)
        process.wait_connected(joint_goals)
        yield process
    finally:
        code = process.stop()
        assert code == 0, process.output()


@pytest.fixture
def still(node: NodeProcess, sim: RobotSimulator) -> RobotSimulator:
    """The shared simulator once nothing moves (a previous test's command timed out)."""
    assert sim.wait_until(lambda s: s.all_stopped and drive_stopped(s), 5.0)
    return sim


def publish_and_wait(sim: RobotSimulator, cmd_vel: Any, message: Any) -> float:
    """Publish one cmd_vel and wait until the simulator's drive follows; returns publish time."""
    published_at = time.monotonic()
    cmd_vel.publish(message)
    assert sim.wait_until(lambda s: not drive_stopped(s), 5.0)
    return published_at


def last_drive_rcp(profile: RobotProfile, sim: RobotSimulator) -> ReceivedRcp:
    return next(
        r
        for r in reversed(sim.received_commands())
        if axis(profile, r, "drive_linear") or axis(profile, r, "drive_turn")
    )


class Planner:
    """A planner streaming one Twist at 20 Hz on its own thread until stop()."""

    PERIOD_S = 0.05

    def __init__(self, publisher: Any, message: Any) -> None:
        self.publisher = publisher
        self.message = message
        self.last_published_at = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="planner", daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            self.publisher.publish(self.message)
            self.last_published_at = time.monotonic()
            self._stop.wait(self.PERIOD_S)  # the planner's pace, not a synchronisation

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> float:
        """Stop publishing; returns when the last message was published."""
        self._stop.set()
        self._thread.join(5.0)
        return self.last_published_at


def status_values(message: Any, index: int) -> dict[str, str]:
    """The key/values of /diagnostics entry `index` (0: the link, 1: the bridge)."""
    return {kv.key: kv.value for kv in message.status[index].values}


def drive_axes(profile: RobotProfile, rcp: ReceivedRcp) -> tuple[int, int]:
    return axis(profile, rcp, "drive_linear"), axis(profile, rcp, "drive_turn")


# ---- cmd_vel ------------------------------------------------------------------------------


def test_small_speeds_are_raised_to_the_minimum(
    profile: RobotProfile, still: RobotSimulator, cmd_vel: Any
) -> None:
    publish_and_wait(still, cmd_vel, twist(0.1, -0.1))
    rcp = last_drive_rcp(profile, still)
    assert axis(profile, rcp, "drive_linear") == axis_for(profile, "drive_linear", 0.2)
    assert axis(profile, rcp, "drive_turn") == axis_for(profile, "drive_turn", -0.2)
    commanded = still.state().commanded_velocities
    assert commanded["drive_linear"] == pytest.approx(0.2, abs=1e-4)
    assert commanded["drive_turn"] == pytest.approx(-0.2, abs=1e-4)


def test_speeds_above_the_minimum_pass_unchanged(
    profile: RobotProfile, still: RobotSimulator, cmd_vel: Any
) -> None:
    publish_and_wait(still, cmd_vel, twist(0.25, 0.5))
    rcp = last_drive_rcp(profile, still)
    assert axis(profile, rcp, "drive_linear") == axis_for(profile, "drive_linear", 0.25)
    assert axis(profile, rcp, "drive_turn") == axis_for(profile, "drive_turn", 0.5)
    assert still.wait_until(lambda s: s.track_speeds_m_s[0] != s.track_speeds_m_s[1], 2.0)


def test_cmd_vel_timeout_stops_the_tracks(
    profile: RobotProfile, still: RobotSimulator, cmd_vel: Any
) -> None:
    published_at = publish_and_wait(still, cmd_vel, twist(0.3))
    assert still.wait_until(drive_stopped, 3.0)
    received = still.received_commands()
    moving = [i for i, r in enumerate(received) if axis(profile, r, "drive_linear")]
    zero = received[moving[-1] + 1]
    assert axis(profile, zero, "drive_linear") == 0
    # Default timeout 0.5 s, checked at the node's 50 Hz loop.
    assert 0.45 <= zero.time_s - published_at <= 0.8


def test_turn_radius_is_kept_when_lifted_to_the_minimum(
    profile: RobotProfile, still: RobotSimulator, cmd_vel: Any
) -> None:
    publish_and_wait(still, cmd_vel, twist(0.1, 0.05))
    rcp = last_drive_rcp(profile, still)
    # Both lifted by one factor (2): a 2 m arc stays a 2 m arc, not (0.2, 0.2), a 1 m one.
    assert drive_axes(profile, rcp) == (
        axis_for(profile, "drive_linear", 0.2),
        axis_for(profile, "drive_turn", 0.1),
    )
    commanded = still.state().commanded_velocities
    assert commanded["drive_linear"] / commanded["drive_turn"] == pytest.approx(2.0, rel=1e-3)


def test_link_loss_stops_ros_and_recovery_does_not_resume_it(
    profile: RobotProfile, still: RobotSimulator, cmd_vel: Any, node: NodeProcess
) -> None:
    from diagnostic_msgs.msg import DiagnosticArray

    diagnostics = Collector("/diagnostics", DiagnosticArray)
    planner = Planner(cmd_vel, twist(0.25, 0.0))
    try:
        diagnostics.wait_connected(node.name)
        planner.start()
        assert still.wait_until(lambda s: not drive_stopped(s), 5.0)
        still.cut_link()
        try:
            # LINK LOST after 3 s without packets; the planner streams on all along.
            diagnostics.wait(lambda m: status_values(m, 0)["state"] == "LINK LOST", 10.0)
            seen = diagnostics.count()
        finally:
            restored_at = time.monotonic()
            still.restore_link()
        diagnostics.wait(lambda m: status_values(m, 0)["state"] == "connected", 5.0, after=seen)
        # The planner still streams 0.25 m/s: the node's first RCPs after the cut (sent
        # while it still saw the link lost) and every one since it reconnected are zeros.
        assert still.wait_until(lambda s: s.time_s > restored_at + 1.5, 5.0)
        held = [r for r in still.received_commands() if r.time_s >= restored_at]
        assert len(held) >= 5
        assert [drive_axes(profile, r) for r in held] == [(0, 0)] * len(held)
        assert drive_stopped(still.state())
        # The diagnostics say why: refused while lost, and still while cmd_vel is not quiet.
        lost = next(m for m in diagnostics.messages if status_values(m, 0)["state"] == "LINK LOST")
        assert status_values(lost, 1)["link gate"] == "link lost"
        assert "LINK LOST" in lost.status[1].message
        recovering = diagnostics.wait(
            lambda m: (
                status_values(m, 0)["state"] == "connected"
                and status_values(m, 1)["link gate"] == "recovering"
            ),
            after=seen,
        )
        assert int(status_values(recovering, 1)["cmd_vel refused (link)"]) > 0
    finally:
        quiet_from = planner.stop()
        seen = diagnostics.count()
    try:
        # cmd_vel silent for the timeout (0.5 s): the next cmd_vel drives again.
        diagnostics.wait(lambda m: status_values(m, 1)["link gate"] == "open", 5.0, after=seen)
    finally:
        diagnostics.close()
    publish_and_wait(still, cmd_vel, twist(0.25, 0.0))
    moving = [
        r
        for r in still.received_commands()
        if r.time_s >= restored_at and any(drive_axes(profile, r))
    ]
    assert moving[0].time_s - quiet_from >= 0.5
    assert drive_axes(profile, moving[0]) == (axis_for(profile, "drive_linear", 0.25), 0)


# ---- joint states, goals, images, diagnostics ----------------------------------------------


def test_joint_states_carry_the_simulator_angles(still: RobotSimulator, ros_client: None) -> None:
    import rospy
    from sensor_msgs.msg import JointState

    message = rospy.wait_for_message("joint_states", JointState, timeout=10.0)
    truth = still.state().joints_rad
    assert list(message.name) == [
        "flippers",
        "waist",
        "shoulder",
        "elbow",
        "neck",
        "gripper",
        "gripper_roll",
        "head_pan",
    ]
    for name, position in zip(message.name, message.position, strict=True):
        assert position == pytest.approx(truth[name], abs=TICK_RAD)
    for name, angle in INITIAL_JOINTS.items():
        assert message.position[list(message.name).index(name)] == pytest.approx(angle, abs=1e-3)
    assert len(message.velocity) == len(message.effort) == len(message.name)
    assert all(effort > 0.0 for effort in message.effort)  # motor current, amperes
    assert abs(message.header.stamp.to_sec() - time.time()) < 5.0


def test_joint_goal_moves_the_joint_through_the_position_controller(
    still: RobotSimulator, joint_goals: Any
) -> None:
    from sensor_msgs.msg import JointState

    target = 0.9
    goal = JointState()
    goal.name = ["waist"]
    goal.position = [target]
    joint_goals.publish(goal)
    assert still.wait_until(
        lambda s: (
            abs(s.joints_rad["waist"] - target) < math.radians(0.5) and s.velocities["waist"] == 0.0
        ),
        10.0,
    ), still.state().joints_rad


def test_bad_joint_goal_is_rejected_with_the_reason(
    still: RobotSimulator, joint_goals: Any, node: NodeProcess
) -> None:
    from sensor_msgs.msg import JointState

    # rosgraph_msgs has no mypy override (no stubs); imported by name it stays Any.
    Log = importlib.import_module("rosgraph_msgs.msg").Log  # noqa: N806

    log = Collector("/rosout", Log)
    try:
        log.wait_connected(node.name)
        before = still.state().joints_rad
        goal = JointState()
        goal.name = ["shoulder", "nonsense"]
        goal.position = [0.2, 0.1]
        joint_goals.publish(goal)
        entry = log.wait(lambda m: m.name == f"/{node.name}" and "rejected" in m.msg)
    finally:
        log.close()
    assert entry.msg == ("joint goal rejected: nonsense: not a joint driven by a velocity channel")
    assert entry.level == Log.ERROR
    assert still.state().joints_rad["shoulder"] == before["shoulder"]


def test_camera_images_are_published_with_the_camera_name(
    node: NodeProcess, ros_client: None
) -> None:
    from sensor_msgs.msg import CompressedImage

    all_cameras = Collector("camera/compressed", CompressedImage)
    zoom = Collector("camera/zoom/image/compressed", CompressedImage)
    try:
        image = all_cameras.wait(lambda m: True)
        zoom_image = zoom.wait(lambda m: True)
    finally:
        all_cameras.close()
        zoom.close()
    assert image.format == zoom_image.format == "jpeg"
    assert image.header.frame_id == zoom_image.header.frame_id == "zoom"
    assert bytes(image.data[:2]) == b"\xff\xd8"


def test_diagnostics_report_the_link(node: NodeProcess, ros_client: None) -> None:
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    diagnostics = Collector("/diagnostics", DiagnosticArray)
    try:
        # "connected", or "connected, telemetry loss ..." when this machine is busy.
        message = diagnostics.wait(lambda m: m.status[0].message.startswith("connected"))
    finally:
        diagnostics.close()
    link, bridge = message.status
    values = {kv.key: kv.value for kv in link.values}
    assert link.name == "ocu: robot link"
    assert link.level in (DiagnosticStatus.OK, DiagnosticStatus.WARN), link.message
    assert int(values["telemetry packets"]) > 0
    assert {"malformed datagrams", "foreign datagrams", "telemetry loss"} <= set(values)
    assert values["emergency stop latched"] == "false"
    assert bridge.name == "ocu: ROS bridge"


# ---- nodes of their own: shutdown, TwistStamped, the protocol extension ---------------------


@pytest.fixture
def own_sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    needs_ros()
    simulator = RobotSimulator(profile, telemetry_hz=20.0, video_fps=0.0)
    simulator.start()
    yield simulator
    simulator.stop()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_signal_stops_the_node_with_zeros_last(
    profile: RobotProfile,
    own_sim: RobotSimulator,
    cmd_vel: Any,
    tmp_path: Path,
    sig: int,
) -> None:
    process = NodeProcess(tmp_path, own_sim.address)
    # A planner streaming: the robot is still moving when the signal comes.
    planner = Planner(cmd_vel, twist(0.3, 0.4))
    try:
        process.wait_connected(cmd_vel)
        planner.start()
        assert own_sim.wait_until(lambda s: not drive_stopped(s), 5.0)
    finally:
        code = process.stop(sig)
        planner.stop()
    assert code == 0, process.output()
    received = own_sim.received_commands()
    moving = [i for i, r in enumerate(received) if any(r.packet.axes)]
    assert moving, "the node never drove the robot"
    after = received[moving[-1] + 1 :]
    assert len(after) >= profile.link.estop_repeats
    assert all(not any(r.packet.axes) for r in after)
    assert own_sim.wait_until(lambda s: s.all_stopped, 1.0)
    assert "zeros sent last" in process.output()


def test_twist_stamped_option(
    profile: RobotProfile,
    own_sim: RobotSimulator,
    ros_client: None,
    tmp_path: Path,
) -> None:
    import rospy
    from geometry_msgs.msg import TwistStamped

    publisher = rospy.Publisher("cmd_vel_stamped", TwistStamped, queue_size=10)
    process = NodeProcess(
        tmp_path, own_sim.address, "_twist_stamped:=true", "cmd_vel:=cmd_vel_stamped"
    )
    try:
        process.wait_connected(publisher)
        message = TwistStamped()
        message.header.stamp = rospy.Time.now()
        message.twist.linear.x = -0.1
        publish_and_wait(own_sim, publisher, message)
        rcp = last_drive_rcp(profile, own_sim)
        assert axis(profile, rcp, "drive_linear") == axis_for(profile, "drive_linear", -0.2)
    finally:
        publisher.unregister()
        assert process.stop() == 0, process.output()


def test_extended_robot_gives_a_topic_per_camera(
    profile: RobotProfile, ros_master: RosMaster, ros_client: None, tmp_path: Path
) -> None:
    from sensor_msgs.msg import CompressedImage

    simulator = RobotSimulator(profile, telemetry_hz=5.0, video_fps=0.0, extended=True)
    simulator.start()
    rear = Collector("camera/rear/image/compressed", CompressedImage)
    process = NodeProcess(tmp_path, simulator.address, "_extension:=true")
    try:
        image = rear.wait(lambda m: True, 20.0)
    finally:
        rear.close()
        code = process.stop()
        simulator.stop()
    assert code == 0, process.output()
    assert image.header.frame_id == "rear"
    assert bytes(image.data[:2]) == b"\xff\xd8"


def test_command_line_parameters_hold_for_one_run_and_are_checked(
    own_sim: RobotSimulator, ros_client: None, tmp_path: Path
) -> None:
    import rospy

    name = "ocu_ros_params"
    private = f"/{name}"
    # Set by someone else: a launch file (~rate, ~min_linear) and another node (/other).
    rospy.set_param(f"{private}/rate", 40)
    rospy.set_param(f"{private}/min_linear", 0.15)
    rospy.set_param("/other/cmd_vel_timeout", 7.0)
    try:
        refused = NodeProcess(
            tmp_path, own_sim.address, "_cmd_vel_timeout:=86400", "_min_linear:=0.1", name=name
        )
        assert refused.wait_exit() == 2, refused.output()
        assert "~cmd_vel_timeout must be > 0 and at most 2 s, got 86400" in refused.output()
        # What the command line set is gone, what it replaced is back, the rest untouched.
        assert not rospy.has_param(f"{private}/cmd_vel_timeout")
        assert not rospy.has_param(f"{private}/robot")
        assert rospy.get_param(f"{private}/min_linear") == 0.15
        assert rospy.get_param(f"{private}/rate") == 40
        assert rospy.get_param("/other/cmd_vel_timeout") == 7.0

        # The next run without the argument has the default timeout, not the last run's.
        again = NodeProcess(tmp_path, own_sim.address, name=name)
        try:
            assert wait_for(lambda: "ROS bridge started" in again.output(), 20.0), again.output()
            started = next(
                line for line in again.output().splitlines() if "ROS bridge started" in line
            )
            assert "min 0.15 m/s" in started  # the launch file's value, restored
            assert "timeout 0.50 s" in started
            assert rospy.get_param(f"{private}/robot") == "{}:{}".format(*own_sim.address)
        finally:
            assert again.stop() == 0, again.output()
        assert not rospy.has_param(f"{private}/robot")
        assert rospy.get_param(f"{private}/rate") == 40
    finally:
        for param in (private, "/other"):
            if rospy.has_param(param):
                rospy.delete_param(param)
